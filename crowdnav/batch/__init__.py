"""Many worlds of one scenario as one batch: the stacked state the sensors read and the batched simulator.

The native vector env (:class:`crowdnav.envs.vector.env.CrowdNavVectorEnv`) is built on it.
"""

from crowdnav.batch.state import BatchState

__all__ = ["BatchState"]
