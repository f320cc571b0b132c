"""Physics core: orbit, equations of motion, reels and the integrator (numpy + numba).

Public API::

    from tether_gym.physics import TetherChain, ReelActuator, orbit, make_rk4
"""

from . import orbit
from .dynamics import TetherChain
from .integrators import make_rk4, rk4_integrate
from .reel import ReelActuator, lengths_within

__all__ = ["TetherChain", "ReelActuator", "lengths_within", "make_rk4", "rk4_integrate", "orbit"]
