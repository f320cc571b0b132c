"""Physics core: the chain's equations of motion, its reels and the orbit (numpy + numba).

Public API::

    from tether_gym.physics import TetherChain, transition, Scales, STATE, PARAMS

:class:`TetherChain` evaluates the equations at given states, :func:`transition`
advances states with the reels in the loop (the step the environments take),
:class:`Scales` converts to and from SI units, and ``STATE`` / ``PARAMS`` declare
the rows they exchange.
"""

from .dynamics import TetherChain, Transition, transition
from .integrators import make_rk4
from .scales import Scales
from .state import PARAMS, STATE

__all__ = ["TetherChain", "Transition", "transition", "Scales", "STATE", "PARAMS", "make_rk4"]
