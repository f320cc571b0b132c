"""tether_gym: a Gymnasium benchmark for tethered multi-satellites in elliptic orbits.

Importing the package registers ``tether_gym/TetherLibration-v0``. Heavy modules
(numba kernels, environments) load only when used.
"""

from gymnasium.envs.registration import register

__version__ = "0.2.0"
__all__ = ["__version__", "ENV_ID", "DEFAULT_MAX_EPISODE_STEPS"]

ENV_ID = "tether_gym/TetherLibration-v0"

# ceil(orbits_per_episode * 2 pi / control_step) for the defaults (3 orbits, 0.025 rad);
# tests/envs check it against EnvConfig().max_episode_steps.
DEFAULT_MAX_EPISODE_STEPS = 754

register(
    id=ENV_ID,
    entry_point="tether_gym.envs.tether_libration:TetherLibrationEnv",
    vector_entry_point="tether_gym.envs.vector:TetherLibrationVectorEnv",
    max_episode_steps=DEFAULT_MAX_EPISODE_STEPS,
)
