"""What an action means: the normalised reel-rate command u it sets, in either action mode.

The one copy of the command update. The compiled step
(:func:`tether_gym.envs.step_kernel.step_rows`) inlines :func:`next_command` for each
tether of each row; code outside the env that must know the command an action sets (a
hybrid policy handing control back to an agent trained on increments,
``tether_gym_agents.hybrids``) calls the same compiled function with numpy arrays.
:func:`require_rate_mode` is the one check that an env's actions are the commands.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..physics.jit import INLINE

__all__ = ["RATE", "INCREMENT", "next_command", "require_rate_mode"]

RATE = "rate"
"""``action_mode`` whose action is the command: u = clip(a, -1, 1)."""
INCREMENT = "increment"
"""``action_mode`` whose action changes the command: u <- clip(u + gain a, -1, 1)."""


@njit(**INLINE)
def next_command(command, action, incremental, gain):
    """The normalised reel-rate command u [-] that an action sets.

    Parameters
    ----------
    command : float or ndarray
        The command u in force before the action [-], in [-1, 1] (read only with
        ``incremental``).
    action : float or ndarray
        The action a [-], finite; clipped to [-1, 1] first, as the env does.
    incremental : bool
        True for ``action_mode="increment"``: u <- clip(u + gain * clip(a, -1, 1), -1, 1);
        False for ``"rate"``: u = clip(a, -1, 1).
    gain : float
        The increment gain [-] (``increment_gain``, (0, 2]).

    Returns
    -------
    float or ndarray
        The new command in [-1, 1] [-], of the inputs' (broadcast) shape: scalars in
        the compiled step, float64 arrays for Python callers. l'_cmd = u * max_reel_rate.
    """
    a = np.minimum(np.maximum(action, -1.0), 1.0)
    if incremental:
        return np.minimum(np.maximum(command + gain * a, -1.0), 1.0)
    return a


def require_rate_mode(action_mode: str, who: str) -> None:
    """Raise ValueError unless ``action_mode`` makes the action the command (``"rate"``).

    Parameters
    ----------
    action_mode : str
        An env's ``action_mode`` (``EnvConfig.action_mode``).
    who : str
        What needs reel-rate actions, named in the message.
    """
    if action_mode != RATE:
        raise ValueError(f"{who} commands reel rates, but the env has action_mode="
                         f"{action_mode!r}: make it with gym.make(..., action_mode={RATE!r})")
