"""Shared-parameter PPO for every robot of a multi-robot scenario (``agents: robots``): the robots as one env and one
``VecEnv`` (a row per robot per world), how each robot reads the shared actions, per-kind networks, exact resume, and
the training and loading of the shared policy (:mod:`crowdnav.agents.marl.robots`)."""
