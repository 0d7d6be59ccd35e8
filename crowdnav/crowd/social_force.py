"""The social-force crowd model (``model: social_force``, the default): Helbing's forces as velocity commands.

The forces are kernels of :mod:`crowdnav.sim.forces` that both simulators sum on the geometry a
step measures (the pair and obstacle repulsion are part of that geometry, which the contacts use
too), so the model reads the summed command from the view: one world's, or K worlds' at once
(the kernels take a leading world axis, so the batch needs no loop over worlds).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from crowdnav.crowd.base import CrowdModel, CrowdView


class SocialForceModel(CrowdModel):
    """Every human's social-force command (docs/simulator.md gives the formulas)."""

    name = "social_force"

    def commands(self, view: CrowdView) -> np.ndarray:
        return view.social_force()

    def commands_batch(self, view: CrowdView, worlds: Sequence[CrowdModel]) -> np.ndarray:
        return view.social_force()
