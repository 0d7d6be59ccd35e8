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
seeded takes fresh entropy once (``SeedSequence()``), as the simulator does. :func:`episode_key` computes
that word with SeedSequence's own hash in Python integers (numpy's ``bit_generator.pyx``, pool of 4
words), the seed's part mixed once and kept: about 3 us a key instead of a SeedSequence's 9 or more
(``tests/core/test_tracker_keys.py`` holds it to numpy's, word for word).
"""

from __future__ import annotations

import functools

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
    """The 64-bit key of episode ``episode`` (0: the seeded reset itself) after a reset with seed ``entropy``:
    ``SeedSequence(entropy, spawn_key=(TRACKER_STREAM, episode)).generate_state(1, dtype=np.uint64)[0]``."""
    pool, hash_const = _seeded_pool(entropy)
    mixer = list(pool)
    for word in _words(episode):  # the spawn key's last entry, each word mixed into each pool word
        for dst in range(_POOL):
            value, hash_const = _hashmix(word, hash_const)
            mixer[dst] = _mix(mixer[dst], value)
    hash_const, words = _INIT_B, []
    for value in mixer[:2]:  # generate_state(1, uint64): 2 uint32 words, the low one first
        value ^= hash_const
        hash_const = hash_const * _MULT_B & _M32
        value = value * hash_const & _M32
        words.append(value ^ value >> 16)
    key: np.uint64 = np.uint64(words[0] | words[1] << 32)
    return key


# SeedSequence's hash (numpy/random/bit_generator.pyx: pool of 4 words), on Python integers
_POOL, _M32 = 4, 0xFFFFFFFF
_INIT_A, _MULT_A, _INIT_B, _MULT_B = 0x43B0D7E5, 0x931E8875, 0x8B51F9DD, 0x58F38DED
_MIX_L, _MIX_R = 0xCA01F9DD, 0x4973F715


def _words(value: int) -> list[int]:
    """``value`` as SeedSequence reads an integer: 32-bit words, lowest first (0: one word)."""
    if value < 0:
        raise ValueError("expected non-negative integer")
    words = [value & _M32]
    value >>= 32
    while value:
        words.append(value & _M32)
        value >>= 32
    return words


def _hashmix(value: int, hash_const: int) -> tuple[int, int]:
    """The hashed value, and the hash constant advanced."""
    value ^= hash_const
    hash_const = hash_const * _MULT_A & _M32
    value = value * hash_const & _M32
    return value ^ value >> 16, hash_const


def _mix(x: int, y: int) -> int:
    result = (_MIX_L * x - _MIX_R * y) & _M32
    return result ^ result >> 16


@functools.lru_cache(maxsize=1024)
def _seeded_pool(entropy: int) -> tuple[tuple[int, ...], int]:
    """The pool, and the hash constant, once the seed and the tracker's stream are mixed in (the spawn key but its last
    entry): the same for every episode of the seed."""
    run = _words(entropy)
    run += [0] * (_POOL - len(run))  # a spawn key given: the seed's words padded to the pool size
    words = run + _words(TRACKER_STREAM)
    hash_const = _INIT_A
    mixer = []
    for word in words[:_POOL]:
        value, hash_const = _hashmix(word, hash_const)
        mixer.append(value)
    for src in range(_POOL):  # every pool word into every other
        for dst in range(_POOL):
            if src != dst:
                value, hash_const = _hashmix(mixer[src], hash_const)
                mixer[dst] = _mix(mixer[dst], value)
    for word in words[_POOL:]:
        for dst in range(_POOL):
            value, hash_const = _hashmix(word, hash_const)
            mixer[dst] = _mix(mixer[dst], value)
    return tuple(mixer), hash_const


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
