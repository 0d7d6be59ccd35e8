"""The SARL-style agent collects from the one vector stack (``make_vec_env``) at any ``num_envs``: at one world its run
is the single env's episode loop it had before, bit for bit; with several worlds each world's teacher reads that
world's simulator and a resume starts new episodes in every world."""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

torch = pytest.importorskip("torch")

from crowdnav.agents.sarl.agent import SarlAgent  # noqa: E402
from crowdnav.agents.sarl.imitation import make_teacher  # noqa: E402

from tests.agents.test_sarl import config as sarl_config  # noqa: E402
from tests.agents.test_sarl import rows  # noqa: E402

KWARGS = {"batch_size": 16, "updates_per_episode": 3, "target_update_every": 2, "width": 16, "imitation_episodes": 2,
          "imitation_epochs": 2}

PUBLISHED_LOOP = [("truncated", 12.4743, 20), ("truncated", 11.4763, 20), ("truncated", 0.7106, 20), ("truncated", 8.2792, 20),
                  ("truncated", 11.7982, 20), ("truncated", 8.5672, 20), ("truncated", 11.4635, 20), ("truncated", 5.6143, 20)]
"""(outcome, return, length) of :func:`config`'s 8 episodes as crowdnav trained them on one gym env (commit 4c1b7e2,
before the vector stack): 2 of the predictive teacher, then V-learning."""


def config(out, **fields):
    """tests/agents/test_sarl.py's run, 8 episodes, the first 2 the teacher's."""
    return sarl_config(out, **{"episodes": 8, "algo_kwargs": dict(KWARGS), **fields})


def outcomes(run):
    return [(row["outcome"], float(row["return"]), int(row["length"])) for row in rows(run)]


def single_env_loop(document):
    """SarlAgent's training before the vector stack (4c1b7e2), written out: one gym env (make_env), an episode at a time."""
    from crowdnav.agents.sb3.factory import make_env, make_vec_env
    from crowdnav.agents.training.config import config_from_mapping

    cfg = config_from_mapping(document)
    agent = SarlAgent(make_vec_env(cfg, reward_dtype=np.float64), cfg)
    env, imitation, played = make_env(cfg), KWARGS["imitation_episodes"], []
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        for _ in range(cfg.episodes):
            demonstrating = agent.episodes < imitation
            teacher = make_teacher("predictive")
            observation, _ = env.reset()
            state = agent._observed(observation)
            shown, done = ([], []), False
            while not done:
                action = teacher(env.unwrapped.simulator) if demonstrating else agent.act(observation, deterministic=False)
                observation, reward, terminated, truncated, info = env.step(action)
                following = agent._observed(observation)
                agent.memory.add(state, float(reward), following, bool(terminated))
                for items, item in zip(shown, (state, float(reward)), strict=True):
                    items.append(item)
                state, done = following, terminated or truncated
            if demonstrating:
                agent.demonstrations.add_episode(*shown, agent.discount)
            if not demonstrating:
                agent._train()
            elif agent.episodes + 1 == imitation:
                agent._imitate()
                agent.target.load_state_dict(agent.network.state_dict())
            agent.episodes += 1
            if agent.episodes % KWARGS["target_update_every"] == 0:
                agent.target.load_state_dict(agent.network.state_dict())
            played.append((info["outcome"], round(float(info["episode"]["r"]), 4), int(info["episode"]["l"])))
    finally:
        torch.set_num_threads(threads)
    return agent, played


def test_one_world_trains_the_single_env_loop_bit_for_bit_and_the_published_runs_episodes(tmp_path):
    from crowdnav.agents import train

    result = train(config(tmp_path / "run"))
    reference, played = single_env_loop(config(tmp_path / "unused"))
    assert outcomes(tmp_path / "run") == played == PUBLISHED_LOOP
    for mine, theirs in zip(result.model.network.state_dict().values(), reference.network.state_dict().values(), strict=True):
        torch.testing.assert_close(mine, theirs, rtol=0, atol=0)
    assert result.model.rng.bit_generator.state == reference.rng.bit_generator.state
    memory, theirs = result.model.memory, reference.memory
    assert memory.size == theirs.size and np.array_equal(memory.reward, theirs.reward) and np.array_equal(memory.humans, theirs.humans)


def teacher_episode(document, seed):
    """(outcome, return, length) of the predictive teacher driving one single env from ``seed``, by hand."""
    from crowdnav.agents.sb3.factory import env_options
    from crowdnav.agents.training.config import config_from_mapping

    from crowdnav.envs import CrowdNavEnv

    env, teacher = CrowdNavEnv(**env_options(config_from_mapping(document))), make_teacher("predictive")
    env.reset(seed=seed)
    total, length, done = 0.0, 0, False
    while not done:
        _, reward, terminated, truncated, info = env.step(teacher(env.simulator))
        total, length, done = total + float(reward), length + 1, terminated or truncated
    return info["outcome"], round(total, 4), length


def test_three_stacked_worlds_each_taught_from_its_own_simulator_and_a_resume_starts_new_episodes(tmp_path):
    import json

    from crowdnav.agents import train
    from crowdnav.agents.training.seeding import train_seed

    document = config(tmp_path / "run", num_envs=3, episodes=5, overrides={"humans.count": 3, "max_steps": 30})
    result = train(document)
    logged = {int(row["seed"]): (row["outcome"], float(row["return"]), int(row["length"])) for row in rows(tmp_path / "run")}
    assert len(logged) == 5 and result.model.demonstrations.episodes == 2
    for episode in range(2):  # the first two episodes to start (worlds 0 and 1) were the teacher's, each in its own world
        assert logged[train_seed(0, episode)] == teacher_episode(document, train_seed(0, episode))
    started = json.loads((tmp_path / "run" / "checkpoint" / "policy.json").read_text(encoding="utf-8"))["next_episode"]
    resumed = train({**document, "episodes": 8}, resume=True)
    seeds = [int(row["seed"]) for row in rows(tmp_path / "run")]
    assert resumed.episodes == 8 and len(set(seeds)) == 8  # none played twice
    assert set(seeds[5:]) <= {train_seed(0, episode) for episode in range(started, started + 8)}
