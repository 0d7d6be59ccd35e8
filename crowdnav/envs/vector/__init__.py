"""The native vector env: B worlds of one scenario behind Gymnasium's ``VectorEnv``, and its action and info pipeline.

``env`` is :class:`~crowdnav.envs.vector.env.CrowdNavVectorEnv` (Gymnasium's conventions only: autoreset modes,
seeding, reset masks, the residual plan, snapshots with Gymnasium's flags) and :func:`~crowdnav.envs.vector.env.stacks`,
which chooses its engine; ``actions`` checks a step's actions and adds the plan and the shield (a resume's replay
too); ``infos`` lays the infos out in Gymnasium's vector convention. These modules may import the engines
(:mod:`crowdnav.envs.engines`, read through their protocol, never by their type), the env core and everything below
the envs; in the core only :mod:`crowdnav.envs.registration` imports them (Gymnasium's vector entry point, on first
use). The public names of ``env`` are exported here too, imported on first use (PEP 562): ``crowdnav.envs.vector`` was
that module before it became this package, and user code, older docs and any pickle name
``crowdnav.envs.vector.CrowdNavVectorEnv``. The flat paths of the other two (``crowdnav.envs.vector_actions``,
``crowdnav.envs.vector_infos``) still import, as these modules (:mod:`crowdnav.legacy_paths`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from crowdnav.lazy_exports import lazy_exports

if TYPE_CHECKING:
    from crowdnav.envs.vector.env import MAX_AGENTS, MAX_WORLDS, CrowdNavVectorEnv, EngineFactory, stacks

__all__ = ["MAX_AGENTS", "MAX_WORLDS", "CrowdNavVectorEnv", "EngineFactory", "stacks"]

_EXPORTS = dict.fromkeys(__all__, "crowdnav.envs.vector.env")

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
