"""The array calls of the SARL lookahead's maths that numpy and torch spell differently, behind one small interface.

:mod:`~crowdnav.agents.sarl.lookahead` writes the per-state maths once (decode, features, the one-step lookahead,
the value ceiling) on arrays of either library: arithmetic, comparisons, ``&``, ``|``, ``~``, indexing and
``reshape`` read alike in both, and every other call goes through an :class:`Ops` passed as ``xp``. :data:`NUMPY`
(float64 maths, float32 features and commands) acts in training, evaluation and the published runs;
:class:`crowdnav.agents.sarl.export.TorchOps` runs the same maths in torch for the ONNX export. Axis arguments are
the last axis unless a call takes one.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

import numpy as np

if TYPE_CHECKING:
    import torch

Array = TypeVar("Array", np.ndarray, "torch.Tensor")
"""An array of the backend at hand: ``np.ndarray`` (:data:`NUMPY`) or ``torch.Tensor`` (the export's ops)."""


class Ops(Protocol):
    """What the lookahead's maths asks of an array library besides operators and indexing."""

    def float64(self, x: Any) -> Any: ...  # a cast (observations, masks)
    def float32(self, x: Any) -> Any: ...  # the network's input and the env's commands
    def int64(self, x: Any) -> Any: ...  # indices
    def norm(self, vectors: Any) -> Any: ...  # length of vectors (..., 2)
    def stack(self, arrays: Sequence[Any]) -> Any: ...  # along a new last axis
    def concatenate(self, arrays: Sequence[Any]) -> Any: ...  # along the last axis
    def sum(self, x: Any, axis: int) -> Any: ...
    def any(self, x: Any) -> Any: ...  # booleans, along the last axis
    def where(self, condition: Any, a: Any, b: Any) -> Any: ...  # a and b: float64 arrays or floats
    def clip(self, x: Any, low: float, high: float) -> Any: ...
    def maximum(self, x: Any, low: float) -> Any: ...
    def minimum(self, x: Any, high: float) -> Any: ...
    def exp(self, x: Any) -> Any: ...
    def floor(self, x: Any) -> Any: ...
    def ceil(self, x: Any) -> Any: ...
    def power(self, base: float, exponent: Any) -> Any: ...
    def take(self, x: Any, index: Any) -> Any: ...  # numpy's take_along_axis on the last axis
    def broadcast_to(self, x: Any, shape: Sequence[Any]) -> Any: ...  # a view, never written to
    def zeros_like(self, x: Any) -> Any: ...
    def zeros(self, shape: Sequence[int]) -> Any: ...  # float64
    def copy(self, x: Any) -> Any: ...
    def size(self, n: Any) -> int: ...  # a length read from a shape, as a Python int (fixed in a traced graph)
    # the backup's picking (the lookahead's depth 2), on (B, M, ...) arrays
    def keep(self, done: Any) -> Any: ...  # not done, as a factor of values
    def best(self, scores: Any, width: int) -> Any: ...  # (B, width) indices of the best scores, the lower index first on a tie
    def rows(self, x: Any, index: Any) -> Any: ...  # x (B, M, ...) at index (B, w) -> (B * w, ...)
    def row_max(self, x: Any) -> Any: ...  # the maximum along axis 1
    def spread(self, scores: Any, index: Any, values: Any) -> Any: ...  # -inf like scores, values at index


class NumpyOps:
    """:class:`Ops` in numpy: the calls the lookahead made before it was shared, so acting stays bit for bit."""

    def float64(self, x: Any) -> Any:
        return np.asarray(x, dtype=np.float64)

    def float32(self, x: Any) -> Any:
        return x.astype(np.float32)

    def int64(self, x: Any) -> Any:
        return x.astype(np.int64)

    def norm(self, vectors: Any) -> Any:
        return np.hypot(vectors[..., 0], vectors[..., 1])

    def stack(self, arrays: Sequence[Any]) -> Any:
        return np.stack(arrays, axis=-1)

    def concatenate(self, arrays: Sequence[Any]) -> Any:
        return np.concatenate(arrays, axis=-1)

    def sum(self, x: Any, axis: int) -> Any:
        return np.sum(x, axis=axis)

    def any(self, x: Any) -> Any:
        return np.any(x, axis=-1)

    def where(self, condition: Any, a: Any, b: Any) -> Any:
        return np.where(condition, a, b)

    def clip(self, x: Any, low: float, high: float) -> Any:
        return np.clip(x, low, high)

    def maximum(self, x: Any, low: float) -> Any:
        return np.maximum(x, low)

    def minimum(self, x: Any, high: float) -> Any:
        return np.minimum(x, high)

    def exp(self, x: Any) -> Any:
        return np.exp(x)

    def floor(self, x: Any) -> Any:
        return np.floor(x)

    def ceil(self, x: Any) -> Any:
        return np.ceil(x)

    def power(self, base: float, exponent: Any) -> Any:
        return base ** exponent

    def take(self, x: Any, index: Any) -> Any:
        return np.take_along_axis(x, index, axis=-1)

    def broadcast_to(self, x: Any, shape: Sequence[Any]) -> Any:
        return np.broadcast_to(x, tuple(shape))

    def zeros_like(self, x: Any) -> Any:
        return np.zeros_like(x)

    def zeros(self, shape: Sequence[int]) -> Any:
        return np.zeros(tuple(shape))

    def copy(self, x: Any) -> Any:
        return x.copy()

    def size(self, n: Any) -> int:
        return int(n)

    def keep(self, done: Any) -> Any:
        return ~done

    def best(self, scores: Any, width: int) -> Any:
        return np.argsort(-scores, axis=1, kind="stable")[:, :width]

    def rows(self, x: Any, index: Any) -> Any:  # numpy's arrays may be empty (no static shapes): no -1 in the shape
        return x[np.arange(x.shape[0])[:, None], index].reshape(index.size, *x.shape[2:])

    def row_max(self, x: Any) -> Any:
        return x.max(axis=1)

    def spread(self, scores: Any, index: Any, values: Any) -> Any:
        spread = np.full_like(scores, -np.inf)
        spread[np.arange(scores.shape[0])[:, None], index] = values
        return spread


NUMPY: Ops = NumpyOps()
"""The backend that acts (training, evaluation, the published runs)."""
