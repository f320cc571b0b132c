"""Tests of the reel actuators (the reel law inside tether_gym.physics.transition).

The acceleration limit is checked in physical units along integrated trajectories
under aggressive commands (both from the integrator's l'' and from finite
differences of the physical reel rate); the unlimited reel against the closed-form
first-order lag; the speed limit and the saturation law by their defining properties.
"""

from __future__ import annotations

import numpy as np
import pytest
from chain_helpers import advance
from kepler import time_from_true_anomaly

from tether_gym.params import OrbitParams
from tether_gym.physics import STATE, Scales, TetherChain, transition

L0 = 2.0e4  # [m]
A_MAX = 0.01  # [m/s^2], paper Sec. 4.3


def _reel_ddlength(par, nu, dl, cmd):
    """l'' the reels produce at (nu, l') under the command (transition with 0 substeps)."""
    dl = np.atleast_2d(dl)
    n = dl.shape[1]
    y = np.zeros((dl.shape[0], STATE.size(n)))
    y[:, STATE.slices(n)["length"]] = 0.5
    y[:, STATE.slices(n)["dlength"]] = dl
    nu = np.broadcast_to(nu, dl.shape[:1])
    out = transition(nu, y, np.broadcast_to(cmd, dl.shape), par, 0.0, 0)
    return out.derivative[:, STATE.slices(n)["dlength"]]


def _random_command_run(par, rng, batch=4, n=2, h=1e-3, n_steps=3000, hold=50):
    """Integrate a chain under piecewise-constant random commands (held ``hold`` steps).

    Returns
    -------
    nu : ndarray, shape (S+1, B)
        True anomaly at the start and after every RK4 step.
    dl : ndarray, shape (S+1, B, n)
        Reel rates l' at the same points.
    ddl : ndarray, shape (S, B, n)
        l'' after every step under the command in force (``deriv_end``).
    cmds : ndarray, shape (S, B, n)
        The command in force during each step.
    """
    y = np.zeros((batch, 4 * n))
    y[:, :n] = rng.uniform(-0.2, 0.2, (batch, n))
    y[:, 2 * n:3 * n] = 0.5
    nu = rng.uniform(0.0, 2.0 * np.pi, batch)
    rec_nu, rec_dl, rec_ddl, rec_cmd = [nu.copy()], [y[:, 3 * n:].copy()], [], []
    cmd = np.zeros((batch, n))
    for i in range(n_steps):
        if i % hold == 0:
            cmd = rng.uniform(-1.0, 1.0, (batch, n)) * rng.choice([0.05, 0.5, 2.0], (batch, 1))
        _, deriv, _ = advance(nu, y, cmd, par, h, 1)
        rec_nu.append(nu.copy())
        rec_dl.append(y[:, 3 * n:].copy())
        rec_ddl.append(deriv[:, 3 * n:].copy())
        rec_cmd.append(cmd.copy())
    return (np.array(rec_nu), np.array(rec_dl), np.array(rec_ddl), np.array(rec_cmd))


def test_acceleration_limit_holds_in_physical_units():
    """|L_ddot| <= 0.01 m/s^2 along trajectories under aggressive random commands.

    Table 1 chain, e = 0.2, L0 = 20 km (a_bound ~ 0.776), tau = 0.005, commands up
    to |l'_cmd| = 2 switched every 0.05 rad, RK4 h = 0.001 over 3 rad, 4 runs.
    Checked three ways: the integrator's l'' at every step (<= a_max (1 + 1e-12));
    the reel law alone at every command switch; and finite differences of the
    physical reel rate L_dot = L0 n k^2 l' between consecutive steps, against the
    elapsed time from the Kepler map (<= a_max (1 + 1e-6)). The limit must be active
    in a large share of the steps, and without it the same commands exceed it.
    """
    op = OrbitParams()
    e, n_rate = op.eccentricity, op.rate_scale
    scales = Scales(op, L0)
    chain = TetherChain((1.0, 2.0), e)
    par = chain.param_row(accel_bound=scales.accel_bound(A_MAX), time_constant=0.005)[None]

    nu, dl, ddl, cmds = _random_command_run(par, np.random.default_rng(0))
    accel = scales.reel_accel_si(nu[1:, :, None], e, dl[1:], ddl)
    assert np.max(np.abs(accel)) <= A_MAX * (1.0 + 1e-12)
    assert np.mean(np.abs(accel) >= A_MAX * (1.0 - 1e-9)) > 0.3  # saturated often

    # the reel law alone at the state where each new command starts
    starts = np.arange(0, cmds.shape[0], 50)
    start_ddl = np.stack([_reel_ddlength(par, nu[i], dl[i], cmds[i]) for i in starts])
    assert np.max(np.abs(scales.reel_accel_si(nu[starts, :, None], e, dl[starts],
                                              start_ddl))) <= A_MAX * (1.0 + 1e-12)
    np.testing.assert_array_equal(_reel_ddlength(par, nu[1:].ravel(), dl[1:].reshape(-1, 2),
                                                 cmds.reshape(-1, 2)),
                                  ddl.reshape(-1, 2))

    t = time_from_true_anomaly(nu, e, n_rate)
    rate = scales.reel_rate_si(nu[:, :, None], e, dl)
    fd = np.diff(rate, axis=0) / np.diff(t, axis=0)[:, :, None]
    assert np.max(np.abs(fd)) <= A_MAX * (1.0 + 1e-6)

    free = chain.param_row(time_constant=0.005)[None]
    nu, dl, _, _ = _random_command_run(free, np.random.default_rng(0))
    rate = scales.reel_rate_si(nu[:, :, None], e, dl)
    t = time_from_true_anomaly(nu, e, n_rate)
    assert np.max(np.abs(np.diff(rate, axis=0) / np.diff(t, axis=0)[:, :, None])) > 10 * A_MAX


@pytest.mark.parametrize("e", [0.0, 0.2, 0.7])
def test_unlimited_reel_is_first_order_lag(e):
    """Without limits l' = c (1 - exp(-nu/tau)) and l = l0 + c (nu - tau (1 - exp(-nu/tau))).

    From l'(0) = 0 at nu = 0, constant commands c, tau = 0.05, RK4 h = 0.001 over
    10 tau (lengths move, so the chain swings); agreement to 2e-9 relative to |c| (the
    RK4 error: per step z^5/120 with z = h/tau = 0.02, ~5e-10 in total). The reel
    rate also equals RK4's exact discrete solution c (1 - R(-z)^m),
    R(x) = 1 + x + x^2/2 + x^3/6 + x^4/24, to 1e-13. The reel reaches the command to
    within exp(-10).
    """
    tau = 0.05
    n = 3
    chain = TetherChain((1.0, 2.0, 1.5), e)
    par = chain.param_row(time_constant=tau)[None]
    c = np.array([[0.08, -0.05, 0.03]])
    l0 = np.array([0.4, 0.3, 0.3])
    y = np.concatenate([[0.1, -0.1, 0.05], np.zeros(n), l0, np.zeros(n)])[None]
    nu = np.zeros(1)
    z = -1e-3 / tau
    growth = 1.0 + z + z**2 / 2 + z**3 / 6 + z**4 / 24
    worst = 0.0
    for i in range(50):
        _, deriv, _ = advance(nu, y, c, par, 1e-3, 10)
        np.testing.assert_allclose(y[0, 3 * n:], c[0] * (1.0 - growth ** (10 * (i + 1))),
                                   rtol=1e-13, atol=0.0)
        decay = np.exp(-nu[0] / tau)
        dl_ref = c[0] * (1.0 - decay)
        l_ref = l0 + c[0] * (nu[0] - tau * (1.0 - decay))
        worst = max(worst, np.max(np.abs(y[0, 3 * n:] - dl_ref) / np.abs(c[0])),
                    np.max(np.abs(y[0, 2 * n:3 * n] - l_ref) / np.abs(c[0])))
        np.testing.assert_allclose(deriv[0, 3 * n:], (c[0] - y[0, 3 * n:]) / tau, rtol=1e-14,
                                   atol=1e-15)
    assert nu[0] == pytest.approx(10 * tau, abs=1e-12)
    assert worst <= 2e-9
    assert np.all(np.abs(y[0, 3 * n:] - c[0]) <= np.exp(-10.0) * np.abs(c[0]) * (1 + 1e-6))


@pytest.mark.parametrize("e", [0.0, 0.2, 0.7])
def test_saturation_law_properties(e):
    """The reel law: the physical |L_ddot| <= a_max; unsaturated it is the lag.

    Random (nu, l', l'_cmd): where the lag's physical demand
    L0 n^2 (k^4 (c - l')/tau - 2 e sin(nu) k^3 l') is within a_max, l'' = (c - l')/tau;
    otherwise the physical acceleration equals a_max with the demand's sign.
    """
    rng = np.random.default_rng(2)
    op = OrbitParams(eccentricity=e)
    scales = Scales(op, L0)
    tau = 0.02
    par = TetherChain((1.0, 2.0), e).param_row(accel_bound=scales.accel_bound(A_MAX),
                                               time_constant=tau)
    nu = rng.uniform(-5.0, 15.0, 2000)
    dl = rng.uniform(-0.3, 0.3, (2000, 2))
    cmd = dl + rng.normal(0.0, 0.02, (2000, 2))
    ddl = _reel_ddlength(par, nu, dl, cmd)
    lag = (cmd - dl) / tau
    demand = scales.reel_accel_si(nu[:, None], e, dl, lag)
    accel = scales.reel_accel_si(nu[:, None], e, dl, ddl)
    inside = np.abs(demand) <= A_MAX
    assert 0.2 < inside.mean() < 0.8  # both branches exercised
    assert np.max(np.abs(accel)) <= A_MAX * (1.0 + 1e-12)
    np.testing.assert_allclose(ddl[inside], lag[inside], rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(accel[~inside], A_MAX * np.sign(demand[~inside]), rtol=1e-12)
    np.testing.assert_allclose(scales.reel_rate_si(nu[:, None], e, dl),
                               L0 * op.rate_scale * (1.0 + e * np.cos(nu[:, None])) ** 2 * dl,
                               rtol=1e-15)


def test_speed_limit_clips_the_command():
    """With a speed limit the command is clipped to |L_dot| = L0 n k^2 |l'_cmd| <= v_max."""
    rng = np.random.default_rng(3)
    e = 0.3
    scales = Scales(OrbitParams(eccentricity=e), L0)
    v_max = 1.5  # [m/s]
    tau = 0.01
    par = TetherChain((1.0, 2.0), e).param_row(speed_bound=scales.speed_bound(v_max),
                                               time_constant=tau)
    nu = rng.uniform(0.0, 2.0 * np.pi, 500)
    dl = rng.uniform(-0.05, 0.05, (500, 2))
    cmd = rng.uniform(-0.3, 0.3, (500, 2))
    cap = scales.speed_bound(v_max) / (1.0 + e * np.cos(nu[:, None])) ** 2
    ddl = _reel_ddlength(par, nu, dl, cmd)
    np.testing.assert_allclose(ddl, (np.clip(cmd, -cap, cap) - dl) / tau,
                               rtol=1e-13, atol=1e-15)
    clipped = np.abs(cmd) > cap
    assert 0.2 < clipped.mean() < 0.9
    # the clipped command is exactly the physical speed limit
    steady = np.clip(cmd, -cap, cap)
    speed = np.abs(scales.reel_rate_si(nu[:, None], e, steady))
    np.testing.assert_allclose(speed[clipped], v_max, rtol=1e-14)
    assert np.all(speed <= v_max * (1.0 + 1e-14))
