"""Pairs of points closer than a cut-off, found with a grid of cells (for large crowds).

All pairs of ``n`` points cost ``n^2`` distances; a crowd of 1,000 pays a million per step to
find the few thousand pairs near enough to push each other. Here the points are binned into
square cells of the cut-off's size, sorted by cell, and each point is paired with the points of
its own cell and of four neighbouring cells (half of the 3 x 3 block, so each unordered pair
comes once). Everything is a fixed number of array operations: no Python loop over points or
cells, only over the five cell offsets.
"""

from __future__ import annotations

import numpy as np

_HALF_BLOCK = ((0, 0), (1, 0), (-1, 1), (0, 1), (1, 1))
"""Cell offsets (dx, dy) that meet every neighbouring cell pair exactly once."""
_TABLE_CELLS = 1 << 20
"""Grids of up to this many cells (8 MB of counts) use a lookup table; larger ones a binary search."""


def close_pairs(points: np.ndarray, cutoff: float) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``(i, j)`` with ``i < j`` of every pair of ``points`` (complex) closer than ``cutoff``.

    The order of the pairs is deterministic (a function of the points only).
    """
    n = len(points)
    if n < 2 or cutoff <= 0:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty
    cx = np.floor(points.real / cutoff).astype(np.int64)
    cy = np.floor(points.imag / cutoff).astype(np.int64)
    cx -= cx.min() - 1  # a free column and row on every side: neighbour keys never wrap around
    cy -= cy.min() - 1
    width = int(cx.max()) + 2
    key = cy * width + cx
    order = np.argsort(key, kind="stable")
    cells = width * (int(cy.max()) + 2)
    if cells <= _TABLE_CELLS:  # each cell's run in the sorted order, read off a table
        per_cell = np.bincount(key, minlength=cells)
        cell_start = np.cumsum(per_cell) - per_cell
    else:  # a few points spread over a huge area: binary search instead of a table
        sorted_key = key[order]
    first, second = [], []
    for dx, dy in _HALF_BLOCK:
        target = key + (dy * width + dx)
        if cells <= _TABLE_CELLS:
            start, count = cell_start[target], per_cell[target]
        else:
            start = np.searchsorted(sorted_key, target, side="left")
            count = np.searchsorted(sorted_key, target, side="right") - start
        total = int(count.sum())
        if total == 0:
            continue
        owner = np.repeat(np.arange(n), count)
        # position of each candidate within its owner's run of the sorted order
        within = np.arange(total) - np.repeat(np.cumsum(count) - count, count)
        other = order[np.repeat(start, count) + within]
        if dx == 0 and dy == 0:  # the own cell: each pair once, not a point with itself
            keep = owner < other
            owner, other = owner[keep], other[keep]
        first.append(owner)
        second.append(other)
    if not first:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty
    i, j = np.concatenate(first), np.concatenate(second)
    near = np.abs(points[j] - points[i]) < cutoff
    i, j = i[near], j[near]
    swap = i > j
    i, j = np.where(swap, j, i), np.where(swap, i, j)
    return i, j
