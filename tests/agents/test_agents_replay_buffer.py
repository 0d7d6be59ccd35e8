"""crowdnav's replay buffer: n-step returns on hand-built transitions with known answers."""

from __future__ import annotations

import numpy as np
import pytest
from crowdnav.agents.sb3.replay_buffer import PackedGridReplayBuffer
from gymnasium import spaces

GAMMA = 0.9
SPACE = spaces.Dict({"goal": spaces.Box(-100.0, 100.0, shape=(1,), dtype=np.float32)})
ACTIONS = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)


def filled_buffer(n_steps: int, transitions: list[tuple[float, bool, bool]], size: int = 32) -> PackedGridReplayBuffer:
    """A buffer holding ``transitions`` (reward, terminated, truncated); row i observes i and then i + 1."""
    buffer = PackedGridReplayBuffer(size, SPACE, ACTIONS, device="cpu", n_steps=n_steps, gamma=GAMMA)
    for row, (reward, terminated, truncated) in enumerate(transitions):
        buffer.add({"goal": np.array([[row]], np.float32)}, {"goal": np.array([[row + 1]], np.float32)}, np.zeros((1, 2)),
                   np.array([reward]), np.array([terminated or truncated]), [{"TimeLimit.truncated": truncated and not terminated}])
    return buffer


def sample(buffer: PackedGridReplayBuffer, rows: list[int]):
    samples = buffer._get_samples(np.array(rows))
    return (samples.rewards.numpy().ravel(), None if samples.discounts is None else samples.discounts.numpy().ravel(),
            samples.dones.numpy().ravel(), samples.next_observations["goal"].numpy().ravel())


# episode A: rows 0-3, terminated at row 3; episode B: rows 4-6, truncated at row 6; episode C: rows 7-9, still running
EPISODES = [(1.0, False, False), (2.0, False, False), (3.0, False, False), (-50.0, True, False),
            (1.0, False, False), (1.0, False, False), (1.0, False, True),
            (4.0, False, False), (5.0, False, False), (6.0, False, False)]


def test_one_step_samples_are_the_stored_transitions_without_a_discount():
    rewards, discounts, dones, next_goal = sample(filled_buffer(1, EPISODES), [0, 3, 6])
    np.testing.assert_allclose(rewards, [1.0, -50.0, 1.0])
    assert discounts is None  # SB3 then uses its own gamma
    np.testing.assert_array_equal(dones, [0, 1, 0])  # a truncation is not a terminal state
    np.testing.assert_array_equal(next_goal, [1, 4, 7])


def test_n_step_return_sums_discounted_rewards_and_bootstraps_with_gamma_to_the_n():
    rewards, discounts, dones, next_goal = sample(filled_buffer(3, EPISODES), [0, 7])
    np.testing.assert_allclose(rewards, [1 + GAMMA * 2 + GAMMA**2 * 3, 4 + GAMMA * 5 + GAMMA**2 * 6], rtol=1e-6)
    np.testing.assert_allclose(discounts, [GAMMA**3, GAMMA**3], rtol=1e-6)
    np.testing.assert_array_equal(dones, [0, 0])
    np.testing.assert_array_equal(next_goal, [3, 10])


def test_n_step_window_stops_at_a_terminal_state_without_bootstrapping():
    rewards, discounts, dones, next_goal = sample(filled_buffer(5, EPISODES), [1, 3])
    np.testing.assert_allclose(rewards, [2 + GAMMA * 3 + GAMMA**2 * -50, -50.0], rtol=1e-6)
    np.testing.assert_allclose(discounts, [GAMMA**3, GAMMA], rtol=1e-6)
    np.testing.assert_array_equal(dones, [1, 1])
    np.testing.assert_array_equal(next_goal, [4, 4])


def test_n_step_window_stops_at_a_truncation_and_bootstraps_from_its_next_observation():
    rewards, discounts, dones, next_goal = sample(filled_buffer(5, EPISODES), [4])
    np.testing.assert_allclose(rewards, [1 + GAMMA + GAMMA**2], rtol=1e-6)
    np.testing.assert_allclose(discounts, [GAMMA**3], rtol=1e-6)
    np.testing.assert_array_equal(dones, [0])
    np.testing.assert_array_equal(next_goal, [7])


def test_n_step_window_stops_at_the_newest_row_of_an_unfinished_episode():
    rewards, discounts, dones, next_goal = sample(filled_buffer(5, EPISODES), [8])
    np.testing.assert_allclose(rewards, [5 + GAMMA * 6], rtol=1e-6)
    np.testing.assert_allclose(discounts, [GAMMA**2], rtol=1e-6)
    np.testing.assert_array_equal(dones, [0])
    np.testing.assert_array_equal(next_goal, [10])


def test_n_step_window_does_not_cross_into_older_rows_after_the_buffer_wraps():
    # 12 rows in a buffer of 10: rows 10 and 11 overwrite 0 and 1, so the newest row is index 1
    transitions = [(float(i), False, False) for i in range(12)]
    buffer = filled_buffer(4, transitions, size=10)
    rewards, discounts, _, next_goal = sample(buffer, [0])  # holds transition 10; index 1 holds 11, index 2 holds 2
    np.testing.assert_allclose(rewards, [10 + GAMMA * 11], rtol=1e-6)
    np.testing.assert_allclose(discounts, [GAMMA**2], rtol=1e-6)
    np.testing.assert_array_equal(next_goal, [12])
    rewards, _, _, next_goal = sample(buffer, [8])  # 8, 9 then 10, 11 across the wrap
    np.testing.assert_allclose(rewards, [8 + GAMMA * 9 + GAMMA**2 * 10 + GAMMA**3 * 11], rtol=1e-6)
    np.testing.assert_array_equal(next_goal, [12])


def test_n_steps_below_one_is_refused():
    with pytest.raises(ValueError, match="n_steps must be >= 1"):
        PackedGridReplayBuffer(8, SPACE, ACTIONS, device="cpu", n_steps=0)


@pytest.mark.parametrize("n_steps", [1, 3])
@pytest.mark.parametrize("packed", [True, False])
def test_fast_sampling_gives_the_batch_sb3s_indexing_gives(n_steps, packed):
    import torch

    space = spaces.Dict({"goal": spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32),
                         "lidar": spaces.Box(0.0, 1.0, shape=(40,), dtype=np.float32),
                         "leog": spaces.Box(0, 255, shape=(1, 6, 6), dtype=np.uint8)})
    rng = np.random.default_rng(0)

    def observation():
        return {"goal": rng.uniform(-1, 1, (2, 3)).astype(np.float32), "lidar": rng.uniform(0, 1, (2, 40)).astype(np.float32),
                "leog": ((rng.uniform(size=(2, 1, 6, 6)) > 0.6) * 255).astype(np.uint8)}

    buffer = PackedGridReplayBuffer(50, space, ACTIONS, device="cpu", n_envs=2, n_steps=n_steps, gamma=GAMMA,
                                    packed_keys=["leog"] if packed else [])
    for _ in range(70):  # wraps around
        done = rng.uniform(size=2) < 0.1
        buffer.add(observation(), observation(), rng.uniform(-1, 1, (2, 2)), rng.normal(size=2), done,
                   [{"TimeLimit.truncated": bool(d and rng.uniform() < 0.5)} for d in done])
    batches = []
    for fast in (True, False):
        buffer.fast_sampling = fast
        np.random.seed(3)
        batches.append(buffer.sample(64))
    for name in batches[0]._fields:
        a, b = getattr(batches[0], name), getattr(batches[1], name)
        pairs = [(a[key], b[key]) for key in b] if isinstance(b, dict) else [(a, b)]
        if isinstance(b, dict):
            assert list(a) == list(b)
        for x, y in pairs:
            if y is None:
                assert x is None
            else:
                assert x.dtype == y.dtype and x.shape == y.shape and torch.equal(x, y), name
