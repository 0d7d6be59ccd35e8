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


DENSE_LIMIT = 4_000_000
"""Most (row x human x cell) tests :func:`disc_cells` makes densely; bigger grids (the oracle's) are rasterised per human."""


def disc_cells(centres: np.ndarray, reach: np.ndarray, origin: np.ndarray, spacing: float, shape: tuple[int, int]) -> np.ndarray:
    """The cells humans block: those within ``reach`` of each centre (touching counts).

    ``centres``: (..., n) complex positions; ``reach``: broadcastable to ``centres``, the contact
    distance (a negative reach blocks nothing: an absent human); ``origin``: (...,) complex position
    of cell (0, 0) per leading index. Returns a bool mask (..., W * H). A small grid (a planner's
    local window) is tested densely, the squared distance separable in x and y; a large one (the
    oracle's room) only around each human whose disc meets it. No loop over humans or cells.
    """
    w, h = shape
    lead = centres.shape[:-1]
    rows = int(np.prod(lead, dtype=np.int64))
    reach = np.broadcast_to(reach, centres.shape).reshape(rows, -1)
    rel = (centres - origin[..., None]).reshape(rows, -1) / spacing  # in cells
    r = reach / spacing
    if rel.size * w * h <= DENSE_LIMIT:
        dx = (np.arange(w) - rel.real[..., None]) ** 2  # (rows, n, W)
        dy = (np.arange(h) - rel.imag[..., None]) ** 2  # (rows, n, H)
        inside = dx[..., :, None] + dy[..., None, :] <= np.where(r >= 0, r * r, -1.0)[..., None, None]
        dense: np.ndarray = inside.any(1).reshape(lead + (w * h,))
        return dense
    blocked = np.zeros((rows, w * h), dtype=bool)
    meets = (r >= 0) & (rel.real >= -r) & (rel.real <= w - 1 + r) & (rel.imag >= -r) & (rel.imag <= h - 1 + r)
    row, human = np.nonzero(meets)
    if len(row):
        x, y, r = rel.real[row, human], rel.imag[row, human], r[row, human]
        radius = int(np.ceil(r.max())) + 1
        span = np.arange(-radius, radius + 1)
        si, sj = np.meshgrid(span, span, indexing="ij")
        keep = si * si + sj * sj <= (radius + 1) ** 2  # the stencil's disc: its corners are never within reach
        si, sj = si[keep], sj[keep]
        ci = np.rint(x).astype(np.int64)[:, None] + si
        cj = np.rint(y).astype(np.int64)[:, None] + sj
        dx, dy = ci - x[:, None], cj - y[:, None]
        hit = (dx * dx + dy * dy <= (r * r)[:, None]) & (ci >= 0) & (ci < w) & (cj >= 0) & (cj < h)
        blocked[np.broadcast_to(row[:, None], hit.shape)[hit], (ci * h + cj)[hit]] = True
    return blocked.reshape(lead + (w * h,))
