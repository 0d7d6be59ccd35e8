"""The simulation: one world's crowd and robots stepped in time, and the parts a step is made of.

By concept: ``simulator`` (:class:`crowdnav.sim.simulator.Simulator`, the step), ``state`` (the
episode state and its crowd-size constants), ``geometry`` (what a step measures from the state),
``contacts`` (overlaps, collisions and goals after the move), ``neighbours`` and ``crowd_grid``
(the geometry of large crowds), ``events`` (what a step reports), ``groups`` (the crowd's groups
at their goals), ``robots`` and ``robot_view`` (several robots, and the world seen from one),
``episode_draw`` (an episode's first state), and the kernels the crowd models run on: ``forces``
(the social-force kernels; the model is :mod:`crowdnav.crowd.social_force`) and ``orca_solver``
(ORCA through pyrvo; the model is :mod:`crowdnav.crowd.orca`). A scenario's world, compiled
before it is simulated, is :mod:`crowdnav.worlds`.

Nothing is imported here: import the modules. :mod:`crowdnav.legacy_paths` keeps the module paths
these had at the package root (``crowdnav.simulator``, ``crowdnav.social_force``, ...) importable.
"""
