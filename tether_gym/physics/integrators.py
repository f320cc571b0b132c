"""Generic fixed-step Runge-Kutta 4 that knows nothing of tethers.

The contract follows scipy.integrate: a right-hand side ``fun(t, y, args, dydt, node)``
that writes dy/dt into ``dydt`` (a compiled numba function, so the integrator can be
compiled with it). ``node`` is True at the grid nodes (t0 + i h, y_i), where a
right-hand side may also record quantities that are wanted only there (the chain
records its tensions). :func:`make_rk4` returns a compiled integrator specialised for
that right-hand side; each right-hand side gets its own cached compilation.
"""

from __future__ import annotations

from numba import njit

from .jit import LOOP

__all__ = ["make_rk4"]


def make_rk4(fun, compiled=True):
    """Build a classic RK4 integrator for ``fun(t, y, args, dydt, node)``.

    Parameters
    ----------
    fun : function
        Right-hand side; writes dy/dt at (t, y) into ``dydt``. A numba-compiled
        function when ``compiled`` is True, any Python callable otherwise.
    compiled : bool
        Return the numba-compiled integrator (default) or the same code as plain
        Python. The compiled integrator runs without numba's reference counting
        (:data:`tether_gym.physics.jit.LOOP`), so a compiled ``fun`` inlined into it
        must not allocate arrays.

    Returns
    -------
    integrate : function
        ``integrate(t0, y, h, n_steps, args, work, deriv) -> t``: ``n_steps`` RK4
        steps of size ``h`` from (t0, y), y updated in place; returns the final t.
        ``work`` is a tuple of five arrays shaped like y, (k1, k2, k3, k4, tmp);
        ``deriv`` receives dy/dt at the final state. ``fun`` is called with
        ``node=True`` at every grid node, the start of each step and the end
        (n_steps + 1 calls, the derivative there serving as the next step's first
        stage), and with ``node=False`` at the three inner stages. All evaluations go
        through one call site, so a compiled ``fun`` is compiled into it once. The
        compiled integrator is inlined into its compiled callers.
    """

    def integrate(t0, y, h, n_steps, args, work, deriv):  # pragma: no cover - compiled
        k1, k2, k3, k4, tmp = work
        m = y.shape[0]
        half = 0.5 * h
        sixth = h / 6.0
        t = t0
        for e in range(4 * n_steps + 1):
            i = e // 4
            stage = e - 4 * i
            if stage == 0:  # a grid node: the start of step i, or the end
                x = y
                at_t = t
                dy = k1 if i < n_steps else deriv
            else:  # stages 2-4 from k1, k2, k3
                a = h if stage == 3 else half
                prev = k1 if stage == 1 else (k2 if stage == 2 else k3)
                for j in range(m):
                    tmp[j] = y[j] + a * prev[j]
                x = tmp
                at_t = t + a
                dy = k2 if stage == 1 else (k3 if stage == 2 else k4)
            fun(at_t, x, args, dy, stage == 0)
            if stage == 3:
                for j in range(m):
                    y[j] = y[j] + sixth * (k1[j] + 2.0 * (k2[j] + k3[j]) + k4[j])
                t = t0 + (i + 1) * h
        return t

    if not compiled:
        return integrate
    return njit(inline="always", **LOOP)(integrate)
