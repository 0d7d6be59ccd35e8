"""A scenario's world compiled once at load time: what the simulator and the environments run on.

By concept: ``compiled`` (:func:`crowdnav.worlds.compiled.load_world`, the scenario loaded and its
geometry compiled: :class:`crowdnav.worlds.compiled.CompiledWorld`), ``obstacles`` (the static
obstacles) and the placement of starts and goals: ``placement`` (a scenario's candidate sets),
``placement_regions`` (one region's lattice and the draw at each reset), ``placement_checks`` (the
load-time proofs that every reset succeeds) and ``placement_team`` (room for several robots).

Nothing is imported here: import the modules. :mod:`crowdnav.legacy_paths` keeps the module paths
these had at the package root (``crowdnav.world``, ``crowdnav.obstacles``, ...) importable.
"""
