"""The people tracker's episode keys are numpy's SeedSequence words (the stream docs/sensors.md names), for seeds of any width."""

from __future__ import annotations

import numpy as np
import pytest

from crowdnav.sensors.tracker_draws import TRACKER_STREAM, episode_key

ENTROPIES = [0, 1, 7, 2**32 - 1, 2**32, 2**64 + 5, 2**96 - 3, 2**128 - 1, 2**128, 2**200 + 12345,
             *np.random.default_rng(0).integers(0, 2**63, 6).tolist(), 0x1F2E3D4C5B6A79881726354453627180]
EPISODES = [0, 1, 2, 3, 99, 1000, 2**31, 2**32 - 1, 2**32, 2**40 + 7]


@pytest.mark.parametrize("entropy", ENTROPIES)
def test_episode_keys_are_the_seed_sequence_words(entropy):
    for episode in EPISODES:
        expected = np.random.SeedSequence(entropy, spawn_key=(TRACKER_STREAM, episode)).generate_state(1, dtype=np.uint64)[0]
        key = episode_key(entropy, episode)
        assert isinstance(key, np.uint64) and key == expected, (entropy, episode)


def test_fresh_entropy_keys_and_negative_seeds():
    for _ in range(20):
        entropy = np.random.SeedSequence().entropy
        assert episode_key(entropy, 3) == np.random.SeedSequence(entropy, spawn_key=(TRACKER_STREAM, 3)).generate_state(1, np.uint64)[0]
    with pytest.raises(ValueError, match="non-negative"):
        episode_key(-1, 0)
