"""The engines: what holds a vector env's worlds, behind one protocol, and a world's state as data.

``protocol`` declares :class:`~crowdnav.envs.engines.protocol.WorldEngine` (what the native vector env asks of its
worlds: reset by seed, step, judge, observe, shield, snapshot and load a world) and
:class:`~crowdnav.envs.engines.protocol.RobotsEngine` (the same for the robots-only env, every robot driven by the
caller). Their backends: the worlds stacked in one :class:`crowdnav.batch.simulator.BatchSimulator` (``stacked``,
``stacked_team`` for a ``robots:`` scenario, ``stacked_robots`` for the robots-only engine) and one env per world
(``per_world``; ``robots``, which also chooses the robots-only backend). ``world_state`` is a world as data (what
``snapshot`` gives and ``load`` takes; ``robots_state`` the robots-only engines' form of it) and
``world_state_codec`` stores it as arrays and JSON, without pickle. These modules may import the simulation
(``sim``, ``worlds``, ``crowd``, ``batch``), ``sensors``, ``planning`` and the env core beside them
(``crowdnav.envs.core``, ``reward``; ``single`` and ``parallel``, of which the per-world backends are made), never the
vector env (:mod:`crowdnav.envs.vector`), which sits above them and reads them through the protocol only
(tests/project/test_layers.py). Nothing is imported here: import the modules. The flat module paths they had
(``crowdnav.envs.engine``, ``crowdnav.envs.vector_stacked``, ``crowdnav.envs.world_state``, ...) still import, as these
modules (:mod:`crowdnav.legacy_paths`).
"""
