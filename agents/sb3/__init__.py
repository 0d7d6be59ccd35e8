"""Stable-Baselines3 under crowdnav: the config-to-model factory, crowdnav's faster SAC/TD3/DDPG, the episode-counting
callback, the packed replay buffer, the ``VecEnv`` over the native vector env, one SB3 training run as a session, SB3
behind the algorithm seam, ``model.zip`` read as parameters only, and the list of SB3 internals crowdnav relies on."""
