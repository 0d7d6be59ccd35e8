"""Run-length expansion: the vectorized replacement for "for each item, for each index in its range".

The LIDAR pairs each obstacle with the run of beams it can hit, the occupancy grid pairs each
obstacle with the run of grid rows it crosses; both then do exact per-pair math on the flat
list of pairs, whose length follows the work actually needed rather than items x indices.
Per-item data reaches the pairs with ``data.repeat(count)``.
"""

from __future__ import annotations

import numpy as np


def expand_runs(first: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Expand runs ``first[i], first[i] + 1, ..., first[i] + count[i] - 1`` into one array.

    ``first`` and ``count`` are (R,) integer arrays (``count >= 0``). Returns the concatenated
    runs and ``ends``, the cumulative counts: run ``i`` fills ``[ends[i] - count[i], ends[i])``.
    """
    ends = count.cumsum()
    index = np.arange(int(ends[-1]) if len(ends) else 0)
    # Entry j of run i sits at position ends[i] - count[i] + j and must become first[i] + j.
    index += (first - (ends - count)).repeat(count)
    return index, ends
