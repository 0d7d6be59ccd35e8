"""Pre-training the LEOG encoder as the encoder half of a convolutional autoencoder.

The autoencoder (:class:`crowdnav.agents.networks.encoders.LeogAutoencoder`) reconstructs each binary grid
from its latent, trained with binary cross-entropy on the cell logits. A held-out fraction of
the grids measures the reconstruction loss before training and after every epoch.

Output folder: ``encoder.pt`` (``torch.load``-able dict: ``format``, ``architecture``,
``encoder`` and ``decoder`` state dicts, ``metadata`` with the ``decoder_width``), ``encoder.json`` (the same
architecture and metadata, with the per-epoch losses, readable without torch) and
``loss.png`` (train and held-out loss per epoch).
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from crowdnav.agents.networks.dataset import GridDataset
from crowdnav.agents.networks.encoders import LeogAutoencoder, LeogEncoder, leog_architecture
from torch import nn

from crowdnav.files import atomic_write_text, replacing

ENCODER_FORMAT = "crowdnav-leog-encoder/1"
ENCODER_FILE = "encoder.pt"


@dataclass
class PretrainResult:
    """What a pre-training run produced."""

    encoder_path: Path | None
    """The saved ``encoder.pt`` (None when no output folder was given)."""
    architecture: dict[str, Any]
    train_loss: list[float]
    """Mean training BCE per epoch."""
    val_loss: list[float]
    """Held-out BCE before training (index 0) and after each epoch."""
    seconds: float
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def initial_val_loss(self) -> float:
        return self.val_loss[0]

    @property
    def final_val_loss(self) -> float:
        return self.val_loss[-1]


def pretrain_encoder(
    dataset: GridDataset | np.ndarray,
    out: str | Path | None = None,
    *,
    channels: Sequence[int] = (8, 16, 16),
    kernels: Sequence[int] = (4, 3, 3),
    strides: Sequence[int] = (4, 2, 1),
    latent: int = 64,
    decoder_width: int = 2,
    epochs: int = 30,
    batch_size: int = 32,
    learning_rate: float = 3e-3,
    val_fraction: float = 0.1,
    seed: int = 0,
    progress: bool = False,
) -> PretrainResult:
    """Train an autoencoder on ``dataset`` and save its encoder to ``out`` (if given).

    ``decoder_width`` multiplies the decoder's channels (it is dropped after pre-training, so
    its size costs the agent nothing). The default architecture is :class:`crowdnav.agents.training.config.ExtractorConfig`'s, so the result plugs
    into an agent with default settings (``encoder.mode: frozen`` or ``finetune``).
    """
    if isinstance(dataset, np.ndarray):
        dataset = GridDataset(dataset)
    if epochs < 1 or batch_size < 1 or not 0.0 < val_fraction < 1.0 or len(dataset) < 2:
        raise ValueError(f"expected epochs >= 1, batch_size >= 1, 0 < val_fraction < 1 and >= 2 grids; got "
                         f"{epochs}, {batch_size}, {val_fraction}, {len(dataset)} grids")
    started = time.perf_counter()
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    grids = torch.as_tensor(dataset.grids > 0, dtype=torch.float32)
    order = torch.as_tensor(rng.permutation(len(grids)))
    n_val = max(1, round(val_fraction * len(grids)))
    val, train = grids[order[:n_val]], grids[order[n_val:]]
    architecture = leog_architecture(dataset.grid_shape, channels, kernels, strides, latent)
    model = LeogAutoencoder(architecture, decoder_width)
    optimizer = torch.optim.Adam(model.parameters(), lr=learning_rate)
    loss_fn = nn.BCEWithLogitsLoss()
    val_loss = [_evaluate(model, val, loss_fn)]
    train_loss: list[float] = []
    epochs_iter: Iterable[int] = range(epochs)
    bar = None  # tqdm's bar over the epochs, when progress is shown
    if progress:
        from tqdm import tqdm

        epochs_iter = bar = tqdm(epochs_iter, desc="pretrain", unit="epoch")
    for _ in epochs_iter:
        model.train()
        total, seen = 0.0, 0
        for index in torch.as_tensor(rng.permutation(len(train))).split(batch_size):
            batch = train[index]
            loss = loss_fn(model(batch), batch)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            total += float(loss.detach()) * len(batch)
            seen += len(batch)
        train_loss.append(total / seen)
        val_loss.append(_evaluate(model, val, loss_fn))
        if bar is not None:
            bar.set_postfix(train=f"{train_loss[-1]:.4f}", held_out=f"{val_loss[-1]:.4f}")
    metadata = {
        "dataset": dataset.metadata, "grids": len(dataset), "held_out": n_val, "epochs": epochs, "batch_size": batch_size,
        "learning_rate": learning_rate, "seed": seed, "decoder_width": decoder_width, "occupied_fraction": float(grids.mean()),
        "held_out_cell_accuracy": _accuracy(model, val),
    }
    result = PretrainResult(None, architecture, train_loss, val_loss, time.perf_counter() - started, metadata)
    if out is not None:
        result.encoder_path = save_encoder(model, out, result)
    return result


def _evaluate(model: LeogAutoencoder, grids: torch.Tensor, loss_fn: nn.Module, batch_size: int = 512) -> float:
    model.eval()
    with torch.no_grad():
        total = sum(float(loss_fn(model(batch), batch)) * len(batch) for batch in grids.split(batch_size))
    return total / len(grids)


def _accuracy(model: LeogAutoencoder, grids: torch.Tensor) -> float:
    model.eval()
    with torch.no_grad():
        correct = sum(float(((model(batch) > 0).float() == batch).float().sum()) for batch in grids.split(512))
    return correct / grids.numel()


def save_encoder(model: LeogAutoencoder, out: str | Path, result: PretrainResult) -> Path:
    """Write ``encoder.pt``, ``encoder.json`` and ``loss.png`` into the folder ``out``; returns the .pt path."""
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / ENCODER_FILE
    with replacing(path) as temporary:  # renamed over the destination: a link there is replaced, never written through
        torch.save({"format": ENCODER_FORMAT, "architecture": result.architecture, "encoder": model.encoder.state_dict(),
                    "decoder": model.decoder.state_dict(), "metadata": result.metadata}, temporary)
    summary = {"format": ENCODER_FORMAT, **{k: v for k, v in asdict(result).items() if k != "encoder_path"}}
    atomic_write_text(folder / "encoder.json", json.dumps(summary, indent=2) + "\n")
    plot_losses(result.train_loss, result.val_loss, folder / "loss.png")
    return path


def plot_losses(train_loss: Sequence[float], val_loss: Sequence[float], path: str | Path) -> None:
    """Loss curves (log scale) as a PNG, with matplotlib's non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    figure, axes = plt.subplots(figsize=(6, 4))
    axes.plot(range(1, len(train_loss) + 1), train_loss, label="train")
    axes.plot(range(len(val_loss)), val_loss, marker="o", markersize=3, label="held-out")
    axes.set_xlabel("epoch")
    axes.set_ylabel("binary cross-entropy")
    axes.set_yscale("log")
    axes.set_title("LEOG autoencoder pre-training")
    axes.legend()
    axes.grid(True, alpha=0.3)
    figure.tight_layout()
    with replacing(path, suffix=".png") as temporary:  # the suffix tells matplotlib the format
        figure.savefig(temporary, dpi=100)
    plt.close(figure)


def load_encoder(path: str | Path) -> tuple[LeogEncoder, dict[str, Any]]:
    """The pre-trained encoder (in eval mode) and its saved dict, from ``encoder.pt`` or its folder."""
    path = Path(path)
    if path.is_dir():
        path = path / ENCODER_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no pre-trained encoder file (create one with `crowdnav pretrain-encoder`)")
    saved = torch.load(path, map_location="cpu", weights_only=True)
    if not isinstance(saved, dict) or saved.get("format") != ENCODER_FORMAT:
        raise ValueError(f"{path}: not a crowdnav LEOG encoder file (expected format {ENCODER_FORMAT!r})")
    encoder = LeogEncoder(saved["architecture"])
    encoder.load_state_dict(saved["encoder"])
    encoder.eval()
    return encoder, saved
