"""The space-time lattice both planners search: positions on a grid, one move per time step.

A robot that moves at most ``step = max_speed * dt`` per step lives, for planning, on a square
lattice of spacing ``step / cells_per_step`` anchored at its own position: every lattice move of
at most ``cells_per_step`` cells is one action it can take exactly (a holonomic robot's velocity
is its action). The search keeps, per time step, the boolean grid of the cells the robot can be
in without touching a human or an obstacle at that step, and which move first reached each one:
a breadth-first search in time, one numpy operation per move and step (no loop over cells).

Everything here has a leading world axis ``K``: the oracle searches one world (K = 1), the
predictive planner of a native vector env K worlds at once, with the same code.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Lattice:
    """The moves of one time step on a lattice of ``cells_per_step`` cells per full-speed step."""

    cells_per_step: int
    """Lattice cells per full-speed step: 2 gives a 0.1 m lattice for 1 m/s and 0.2 s, and 13 moves."""
    spacing: float
    """Metres between neighbouring cells: ``max_speed * dt / cells_per_step``."""

    @property
    def moves(self) -> np.ndarray:
        """(M, 2) int cell offsets of one step, every offset within ``cells_per_step`` cells; standing still last."""
        m = self.cells_per_step
        offsets = [(di, dj) for di in range(-m, m + 1) for dj in range(-m, m + 1) if 0 < di * di + dj * dj <= m * m]
        return np.array(offsets + [(0, 0)], dtype=np.int64)

    @property
    def displacements(self) -> np.ndarray:
        """(M,) complex: each move in metres (world frame)."""
        moves = self.moves
        return (moves[:, 0] + 1j * moves[:, 1]) * self.spacing


def shifted(grid: np.ndarray, di: int, dj: int) -> np.ndarray:
    """``grid`` (K, W, H) moved by (di, dj) cells, cells shifted in from outside False."""
    out = np.zeros_like(grid)
    w, h = grid.shape[1:]
    src_i = slice(max(0, -di), w - max(0, di))
    dst_i = slice(max(0, di), w - max(0, -di))
    src_j = slice(max(0, -dj), h - max(0, dj))
    dst_j = slice(max(0, dj), h - max(0, -dj))
    out[:, dst_i, dst_j] = grid[:, src_i, src_j]
    return out


@dataclass
class SearchLayers:
    """What :func:`search` found: the reachable cells and the move that reached each, per step."""

    reached: list[np.ndarray]
    """Per step t = 0..T: (K, W, H) bool, the cells the robot can occupy after t steps."""
    parent: list[np.ndarray]
    """Per step t = 1..T (index t - 1): (K, W, H) int8, the index of the move into the cell (-1: not reached)."""

    def path(self, world: int, t: int, cell: tuple[int, int], moves: np.ndarray) -> list[int]:
        """The moves (indices, first first) from the start to ``cell`` at step ``t`` in ``world``."""
        i, j = cell
        out = []
        for layer in range(t, 0, -1):
            k = int(self.parent[layer - 1][world, i, j])
            out.append(k)
            i, j = i - int(moves[k, 0]), j - int(moves[k, 1])
        return out[::-1]


def search(start: np.ndarray, free: np.ndarray, moves: np.ndarray, stop: np.ndarray | None = None) -> SearchLayers:
    """Breadth-first search in time over ``free`` cells.

    ``start``: (K, W, H) bool, the cells at step 0; ``free``: (T, K, W, H) bool, the cells that
    touch nothing at step t + 1 (static obstacles, world bounds and the humans at that step);
    ``moves``: (M, 2) int offsets. ``stop``: optional (K, W, H) bool goal cells: the search ends
    after the first step at which every world has reached one (or has nothing left).
    """
    reached = [start.copy()]
    parent: list[np.ndarray] = []
    for t in range(len(free)):
        before = reached[-1]
        now = np.zeros_like(before)
        into = np.full(before.shape, -1, dtype=np.int8)
        for k, (di, dj) in enumerate(moves.tolist()):
            new = shifted(before, di, dj) & free[t] & ~now
            into[new] = k
            now |= new
        reached.append(now)
        parent.append(into)
        alive = now.reshape(len(now), -1).any(1)
        if not alive.any():
            break
        if stop is not None and ((now & stop).reshape(len(now), -1).any(1) | ~alive).all():
            break
    return SearchLayers(reached, parent)


def disc_cells(centres: np.ndarray, reach: np.ndarray, origin: np.ndarray, spacing: float, shape: tuple[int, int]) -> np.ndarray:
    """Flat cell indices within ``reach`` of each centre: the cells a human at ``centres`` blocks.

    ``centres``: (..., n) complex positions; ``reach``: (n,) or broadcastable contact distance
    (touching counts: a cell at exactly ``reach`` is blocked); ``origin``: (...,) complex position
    of cell (0, 0) per leading index. Returns a bool mask (..., W * H) of blocked cells.
    """
    w, h = shape
    radius = int(np.ceil(float(np.max(reach, initial=0.0)) / spacing)) + 1
    span = np.arange(-radius, radius + 1)
    si, sj = np.meshgrid(span, span, indexing="ij")
    si, sj = si.ravel(), sj.ravel()
    rel = (centres - origin[..., None]) / spacing  # in cells
    ci = np.rint(rel.real).astype(np.int64)[..., None] + si
    cj = np.rint(rel.imag).astype(np.int64)[..., None] + sj
    gap = np.abs((ci + 1j * cj) * spacing - (centres - origin[..., None])[..., None])
    hit = (gap <= np.broadcast_to(reach, centres.shape)[..., None]) & (ci >= 0) & (ci < w) & (cj >= 0) & (cj < h)
    lead = centres.shape[:-1]
    blocked = np.zeros((int(np.prod(lead, dtype=np.int64)), w * h), dtype=bool)
    rows = np.broadcast_to(np.arange(blocked.shape[0]).reshape(lead + (1, 1)), hit.shape)
    blocked[rows[hit], (ci * h + cj)[hit]] = True
    return blocked.reshape(lead + (w * h,))
