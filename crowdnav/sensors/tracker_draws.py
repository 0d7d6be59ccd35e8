"""The people tracker's random numbers: a counter-based stream per episode, apart from the simulator's generator.

The tracker must not draw from the simulator's generator: that would shift the crowd's own draws,
and a noisy tracker would then change the episode it observes. Its numbers are instead a pure
function of the episode's key, the step, the person and the draw (a counter-based generator:
SplitMix64's mixing function over those four, as Philox or Threefry do with a cipher). So world k
of K stacked worlds draws exactly what one world alone draws, with no generator object per world
and no Python loop, and the same episode gets the same numbers, bit for bit. Persons are numbered below 2^16 and steps below 2^40.

**Episode keys.** ``reset(seed=s)`` starts episode 0 of seed ``s``; each ``reset()`` without a seed
after it starts the next episode of that seed (1, 2, ...), as the simulator continues its own
generator. Episode ``e`` of seed ``s`` has the key ``SeedSequence(s, spawn_key=(TRACKER_STREAM, e))``
(one 64-bit word), a stream of its own beside the simulator's ``SeedSequence(s)``. A world never
seeded takes fresh entropy once (``SeedSequence()``), as the simulator does.
"""

from __future__ import annotations

import numpy as np

TRACKER_STREAM = 0x747261636B6572
"""The spawn key that sets the tracker's streams apart from the simulator's (``b"tracker"`` as an integer)."""
DRAWS = 4
"""Numbers per person and step: detection, track drop, and two for the position noise (Box-Muller)."""

_GAMMA = np.uint64(0x9E3779B97F4A7C15)  # SplitMix64's increment: counter c maps to key + c * gamma, then the mix
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_STEP_GAMMA = np.uint64((0x9E3779B97F4A7C15 << 24) % 2**64)  # counter = step << 24 | person << 8 | draw: (step << 24) * gamma
_30, _27, _31, _11 = (np.uint64(bits) for bits in (30, 27, 31, 11))
_TAILS: dict[int, np.ndarray] = {}


def fresh_entropy() -> int:
    """Entropy for a world reset without a seed before any seeded reset (the OS's, as the simulator's first draw)."""
    entropy: int = np.random.SeedSequence().entropy  # type: ignore[assignment]  # an int when drawn fresh
    return entropy


def episode_key(entropy: int, episode: int) -> np.uint64:
    """The 64-bit key of episode ``episode`` (0: the seeded reset itself) after a reset with seed ``entropy``."""
    sequence = np.random.SeedSequence(entropy, spawn_key=(TRACKER_STREAM, episode))
    key: np.uint64 = sequence.generate_state(1, dtype=np.uint64)[0]
    return key


def _tail(persons: int) -> np.ndarray:
    """(persons, DRAWS) uint64: ``(person << 8 | draw) * gamma``, the part of a counter's offset that does not change."""
    tail = _TAILS.get(persons)
    if tail is None:
        counter = (np.arange(persons, dtype=np.uint64)[:, None] << np.uint64(8)) | np.arange(DRAWS, dtype=np.uint64)
        tail = _TAILS[persons] = counter * _GAMMA
    return tail


def uniforms(keys: np.ndarray, steps: np.ndarray, persons: int) -> np.ndarray:
    """(K, persons, DRAWS) float64 in [0, 1): world k's draws at step ``steps[k]`` for persons 0..persons-1.

    ``keys``: (K,) uint64 episode keys; ``steps``: (K,) int64 steps since the episode's reset. Entry
    (k, person, draw) is SplitMix64's output at ``keys[k] + counter * gamma`` (counter = step << 24 |
    person << 8 | draw): it depends on its key, step, person and draw alone. uint64 arithmetic wraps.
    """
    base = keys + steps.astype(np.uint64) * _STEP_GAMMA  # (step << 24) * gamma, modulo 2^64
    z = base[:, None] + _tail(persons).reshape(-1)  # (K, persons DRAWS): a long last axis for the broadcast
    shifted = z >> _30  # the mix in place, one scratch array
    z ^= shifted
    z *= _MIX1
    np.right_shift(z, _27, out=shifted)
    z ^= shifted
    z *= _MIX2
    np.right_shift(z, _31, out=shifted)
    z ^= shifted
    np.right_shift(z, _11, out=z)
    draws: np.ndarray = np.multiply(z, 2.0**-53)  # the top 53 bits, exactly a double: every double of [0, 1) on a 2^-53 grid
    return draws.reshape(len(keys), persons, DRAWS)


def normal_pair(u1: np.ndarray, u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two independent standard normals from two uniforms of [0, 1) (Box-Muller)."""
    radius = np.sqrt(-2.0 * np.log1p(-u1))  # log(1 - u1): u1 < 1, so finite
    angle = (2.0 * np.pi) * u2
    return radius * np.cos(angle), radius * np.sin(angle)
