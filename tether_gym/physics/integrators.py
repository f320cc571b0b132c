"""Generic fixed-step Runge-Kutta 4 that knows nothing of tethers.

The contract follows scipy.integrate: a right-hand side ``fun(t, y, args, dydt)``
that writes dy/dt into ``dydt`` (a compiled numba function, so the integrator can be
compiled with it). :func:`make_rk4` returns a compiled stepper specialised for that
right-hand side; each right-hand side gets its own cached compilation.
"""

from __future__ import annotations

from numba import njit

from .jit import LOOP

__all__ = ["make_rk4"]


def make_rk4(fun, compiled=True):
    """Build a classic RK4 stepper for ``fun(t, y, args, dydt)``.

    Parameters
    ----------
    fun : function
        Right-hand side; writes dy/dt at (t, y) into its last argument. A
        numba-compiled function when ``compiled`` is True, any Python callable
        otherwise.
    compiled : bool
        Return the numba-compiled stepper (default) or the same code as plain Python.
        The compiled stepper runs without numba's reference counting
        (:data:`tether_gym.physics.jit.LOOP`), so a compiled ``fun`` inlined into it
        must not allocate arrays.

    Returns
    -------
    step : function
        ``step(t, y, h, args, k1, work, out)``: one RK4 step of size ``h`` from
        (t, y), where ``k1 = fun(t, y)`` was already evaluated by the caller (so a
        caller that needs f at the step's start pays for it once). ``work`` is a
        tuple of four scratch arrays shaped like y, (k2, k3, k4, tmp); ``out``
        receives y(t + h) and may not alias y. The compiled stepper is inlined into
        its compiled callers (``inline="always"``).
    """

    @njit(inline="always", **LOOP)
    def step(t, y, h, args, k1, work, out):  # pragma: no cover - compiled
        m = y.shape[0]
        tmp = work[3]
        half = 0.5 * h
        # stages 2-4 as a loop over (k2, k3, k4) = work[0:3], so that an inlined ``fun``
        # appears once in the compiled code (a third of the compile time of three calls)
        prev = k1
        for stage in range(3):
            a = h if stage == 2 else half
            for i in range(m):
                tmp[i] = y[i] + a * prev[i]
            k = work[stage]
            fun(t + a, tmp, args, k)
            prev = k
        k2, k3, k4 = work[0], work[1], work[2]
        sixth = h / 6.0
        for i in range(m):
            out[i] = y[i] + sixth * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i])

    return step if compiled else step.py_func

