"""The learning-algorithm seam: what crowdnav asks of an algorithm, for Stable-Baselines3's and the others alike.

An algorithm is registered by name with :func:`crowdnav.registry.register_algorithm` and an
:class:`~crowdnav.registry.AlgorithmSpec` whose ``builder`` (:func:`builder_of`) is a class (or factory) with

* ``builder(env, config) -> Algorithm``: a new agent for the run's env and its
  :class:`~crowdnav.agents.training.config.TrainConfig` (``seed``, ``gamma``, ``learning_rate``, ``algo_kwargs``, ...). The env is
  the one collection stack of every algorithm and world count, :func:`crowdnav.agents.sb3.factory.make_vec_env`:
  ``num_envs`` worlds (``config.num_envs``, 1 included) behind Stable-Baselines3's ``VecEnv`` API (``observation_space``
  the single world's Dict, as the modalities give it, normalised if the config says so; actions ``(num_envs, 2)`` in
  [-1, 1]; ``env.get_attr("scenario")[0]`` the scenario). At one world it plays the single env's episodes, bit for bit;
* ``builder.load(folder) -> Algorithm``: the agent :meth:`Algorithm.save` wrote to ``folder``, with everything a
  resumed run continues from (weights, optimiser state, random streams).

Every algorithm goes through the same three places, which read only its builder:

* ``crowdnav train`` (:func:`crowdnav.agents.training.run.trainer_of`): crowdnav's episode loop around
  :meth:`Algorithm.learn` (:mod:`crowdnav.agents.training.episode_loop`: episodes counted, logged in ``episodes.csv`` and
  seeded, checkpoints, snapshots, ``--resume``), unless the builder is a :class:`RunTrainer`, which runs the whole
  run itself;
* ``crowdnav evaluate RUN``, ``crowdnav render`` and the experiment runner (:func:`crowdnav.agents.load_policy`, which
  calls :func:`load_agent`): ``builder.load(checkpoint / "algorithm")``, or a :class:`RunTrainer`'s
  ``load_checkpoint``;
* ``crowdnav export`` (:mod:`crowdnav.agents.runs.onnx_export`): the agent's :meth:`Exportable.export_module`; an agent
  without one is refused in one line.

A checkpoint holds no pickle: :meth:`Algorithm.save` writes arrays (``.npz`` read with ``allow_pickle=False``, or
safetensors) and JSON.

The Stable-Baselines3 algorithms (``sac``, ``td3``, ``ddpg``, ``a2c``, ``ppo``, and any spec with an ``sb3_class``) have
the builder :data:`crowdnav.registry.SB3_BUILDER` (:class:`crowdnav.agents.sb3.algorithm.SB3Builder`): its agents are
:class:`crowdnav.agents.sb3.algorithm.SB3Algorithm` (``learn``, ``save``, ``predict``, ``export_module``), and it is the
one :class:`RunTrainer`: ``crowdnav train`` runs their :class:`crowdnav.agents.sb3.session.TrainingSession`
(a strategy of the one run loop, :class:`crowdnav.agents.training.run_loop.RunLoop`, as crowdnav's episode loop is:
SB3's own loop with crowdnav's callbacks, collecting from the same :func:`~crowdnav.agents.sb3.factory.make_vec_env`
worlds, replay buffers and rollouts restored
mid-episode for an exact resume), which a loop that sees the agent only between episodes could not give, and
their checkpoints are SB3's ``model.zip`` at the checkpoint's top, read back as tensors only.
``agents: robots`` (one shared policy for every robot) is trained by the ``robots_trainer`` of the algorithm's registry
entry (PPO's: :func:`crowdnav.agents.marl.robots.train_robots`); an algorithm without one is refused with it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from importlib import import_module
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from stable_baselines3.common.vec_env import VecEnv
    from torch import nn

ALGORITHM_FOLDER = "algorithm"
"""Where :meth:`Algorithm.save` writes inside a checkpoint folder of crowdnav's episode loop (not a :class:`RunTrainer`'s)."""


AgentState = Any
"""What an agent carries from one step to the next (a recurrent network's hidden state: SB3's tuple of arrays, one row
per world); ``None`` for an agent without memory, which is what every agent but a recurrent one returns."""


@runtime_checkable
class Predictor(Protocol):
    """What a trained agent does in evaluation, rendering and experiments (:class:`crowdnav.agents.runs.checkpoint.AgentPolicy`).

    Stable-Baselines3's own signature, so an SB3 model is one as it is: the caller keeps the returned state and gives
    it back at the next step, with ``episode_start`` True for the worlds whose episode has just begun (the agent forgets
    their memory). A batch always holds the same worlds in the same rows while a state is carried.
    """

    def predict(self, observation: Mapping[str, np.ndarray], state: AgentState = None, episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, AgentState]:
        """(actions, next state): for one observation float (2,), for a batch stacked per key float (N, 2)."""


@runtime_checkable
class Algorithm(Predictor, Protocol):
    """A learning agent crowdnav can train, checkpoint, resume and evaluate (module docstring: how it is registered)."""

    def learn(self, env: VecEnv, keep_going: Callable[[], bool]) -> None:
        """Train on the worlds of ``env`` (``reset()`` once, then ``step(actions)`` for all worlds at once) until ``keep_going()`` returns False.

        ``env`` follows SB3's ``VecEnv`` conventions (:class:`crowdnav.agents.sb3.vec_env.CrowdNavSB3VecEnv`): ``step`` returns
        ``(observations, rewards, dones, infos)`` with a leading world axis; a world whose episode ended is reset in the
        same step, its last observation in ``infos[i]["terminal_observation"]`` and ``infos[i]["TimeLimit.truncated"]``
        set when the time limit (not an event) ended it. Act on all worlds in one batched call (``predict`` takes
        batches). Call ``keep_going()`` once for every episode that ended, in the order they ended (several in one
        step: in world order), once what that episode taught is in the agent's state: crowdnav logs that episode
        there, stops on the budget (episodes, or env steps of all worlds) and may call :meth:`save` from inside it
        for a checkpoint (the other worlds then mid-episode: a resume starts new episodes in every world, see
        :mod:`crowdnav.agents.training.episode_loop`). crowdnav seeds every training episode itself; do not reset mid-run.
        """

    def save(self, folder: Path) -> None:
        """Write the agent into the empty ``folder``: arrays and JSON, no pickle; ``builder.load(folder)`` gives it back."""


@runtime_checkable
class Continuing(Protocol):
    """Optional: an agent whose behaviour depends on the run's settings (e.g. a schedule over the budget) is told them again on a resume."""

    def continue_with(self, config: Any) -> None:
        """Called on the agent :func:`load_algorithm` gave back, with the resumed run's config (its budget may be larger)."""


@runtime_checkable
class Exportable(Protocol):
    """An agent ``crowdnav export`` can write to ONNX (optional: an :class:`Algorithm` without it is refused in one line)."""

    def export_module(self, keys: Sequence[str]) -> nn.Module:
        """:meth:`Predictor.predict` with ``deterministic=True`` as a torch module the TorchScript ONNX exporter traces.

        ``forward`` takes one tensor per observation key, in ``keys`` order, each with a leading batch axis and
        holding what ``predict`` receives for that key (crowdnav puts the checkpoint's observation normalisation, and
        a frozen LEOG encoder, before it in the graph), and returns the actions, float32 ``(batch, 2)``. It may ignore
        keys it does not read.
        """


class SB3Predictor:
    """A Stable-Baselines3 model seen as a :class:`Predictor`: SB3's ``predict``, its recurrent state passed through."""

    def __init__(self, model: Any):
        self.model = model

    @property
    def recurrent(self) -> bool:
        """Whether the policy carries a state between steps (:func:`has_lstm_policy`)."""
        return has_lstm_policy(self.model)

    def predict(self, observation: Mapping[str, np.ndarray], state: AgentState = None, episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, AgentState]:
        action, state = self.model.predict(observation, state, episode_start, deterministic)
        return np.asarray(action), state


def has_lstm_policy(model: Any) -> bool:
    """Whether an SB3 model's policy is one of sb3-contrib's LSTM policies (``RecurrentActorCriticPolicy``)."""
    return hasattr(model.policy, "lstm_hidden_state_shape")


def is_recurrent(agent: Any) -> bool:
    """Whether ``agent`` (a :class:`Predictor`, or a policy holding one) carries a state: its callers must keep it per world."""
    return bool(getattr(agent, "recurrent", False))


def as_predictor(model: Any) -> Predictor:
    """``model`` as a :class:`Predictor`: a registered algorithm's agent as it is, an SB3 model through :class:`SB3Predictor`."""
    from stable_baselines3.common.base_class import BaseAlgorithm

    if isinstance(model, BaseAlgorithm):
        return SB3Predictor(model)
    if not isinstance(model, Predictor):
        raise TypeError(f"{type(model).__name__} is neither an SB3 model nor a Predictor (predict)")
    return model


@runtime_checkable
class RunTrainer(Protocol):
    """A builder that trains whole runs with a loop of its own and reads the checkpoints that loop writes.

    The Stable-Baselines3 builder (:class:`crowdnav.agents.sb3.algorithm.SB3Builder`) is one: an exact resume needs
    SB3's buffers, rollouts and worlds restored mid-episode, which :meth:`Algorithm.learn` between episodes cannot
    give. Other builders leave both to crowdnav (:mod:`crowdnav.agents.training.episode_loop`, :func:`load_algorithm`).
    """

    def train_run(self, config: Any, resume: bool, on_checkpoint: Callable[[int], None] | None, trust_pickle: bool) -> Any:
        """Train ``config`` (a TrainConfig) in ``config.out`` (``resume``: from its checkpoint); the run's TrainResult."""

    def load_checkpoint(self, folder: Path, info: Mapping[str, Any], *, encoder: Any, device: str, trusted: bool,
                        config: Any) -> Algorithm:
        """The agent of the checkpoint ``folder`` (``info``: its policy.json) to act with; see :func:`crowdnav.agents.load_policy`."""


def import_reference(reference: str) -> Any:
    """The object a ``"module:attribute"`` text names (a spec's ``builder`` or ``sb3_class``), imported now."""
    module, _, attribute = reference.partition(":")
    try:
        return getattr(import_module(module), attribute)
    except (ImportError, AttributeError) as error:
        raise ValueError(f"{reference}: cannot import it ({error})") from None


def builder_of(algo: str) -> Any:
    """The ``builder`` of the registered algorithm ``algo``, imported if its spec names it (ValueError for an unknown name)."""
    from crowdnav.registry import algorithm_spec

    builder = algorithm_spec(algo).builder
    if builder is None:
        raise ValueError(f"algorithm {algo!r} has no builder: it cannot be trained or loaded")
    return import_reference(builder) if isinstance(builder, str) else builder


def load_algorithm(folder: Path, algo: str) -> Algorithm:
    """The agent a checkpoint of crowdnav's episode loop holds in ``folder/algorithm/`` (``builder.load``)."""
    return _checked(algo, builder_of(algo).load(folder / ALGORITHM_FOLDER))


def load_agent(folder: Path, info: Mapping[str, Any], *, encoder: Any = None, device: str = "cpu", trusted: bool = False,
               config: Any = None) -> Algorithm:
    """The agent of the checkpoint ``folder`` whose policy.json is ``info``, by its algorithm's builder, whatever the algorithm.

    A :class:`RunTrainer` reads its own checkpoints (``encoder``, ``device``, ``trusted``, ``config``: see
    :func:`crowdnav.agents.load_policy`); any other builder's agent is ``builder.load(folder / "algorithm")``.
    """
    builder = builder_of(info["algo"])
    if isinstance(builder, RunTrainer):
        return _checked(info["algo"], builder.load_checkpoint(folder, info, encoder=encoder, device=device, trusted=trusted, config=config))
    return load_algorithm(folder, info["algo"])


def _checked(algo: str, agent: Any) -> Algorithm:
    if not isinstance(agent, Algorithm):
        raise TypeError(f"{algo}: load() returned {type(agent).__name__}, not an Algorithm (learn, predict, save)")
    return agent
