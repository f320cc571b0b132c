"""tether_gym: a Gymnasium benchmark for tethered multi-satellites in elliptic orbits.

Importing the package registers ``tether_gym/TetherLibration-v2`` (:data:`ENV_ID`) and
``tether_gym/TetherLibration-v1`` (v2 without the cost entries of ``info``). Heavy modules
(numba kernels, environments) load only when used.
"""

from gymnasium.envs.registration import register

__version__ = "0.7.0"
__all__ = ["__version__", "ENV_ID", "ENV_ID_V1", "DEFAULT_MAX_EPISODE_STEPS"]

ENV_ID = "tether_gym/TetherLibration-v2"
ENV_ID_V1 = "tether_gym/TetherLibration-v1"

DEFAULT_MAX_EPISODE_STEPS = 754
"""Control steps of an episode with the default arguments (3 orbits of 0.025 rad steps).

Informational: the env truncates itself after ``orbits_per_episode`` orbits of true
anomaly, whatever its configuration, so no step limit is registered (a registered one
would cut lengthened episodes, e.g. ``orbits_per_episode=6`` or ``control_step=0.01``).
"""

register(
    id=ENV_ID,
    entry_point="tether_gym.envs.tether_libration:TetherLibrationEnv",
    vector_entry_point="tether_gym.envs.vector:TetherLibrationVectorEnv",
)
register(
    id=ENV_ID_V1,
    entry_point="tether_gym.envs.legacy:TetherLibrationEnvV1",
    vector_entry_point="tether_gym.envs.legacy:TetherLibrationVectorEnvV1",
)
