"""One compiled control step for a batch of environments: physics, task, observation.

Both :class:`~tether_gym.envs.TetherLibrationEnv` (a batch of one) and
:class:`~tether_gym.envs.vector.TetherLibrationVectorEnv` step through
:func:`_step_row` (:func:`step_rows` over the listed rows, :func:`step_rows_parallel`
over them on numba's threads), so their trajectories are identical for the same
inputs.

Observation layout (float32), n = N-1 tethers:
``[sin nu, cos nu, theta (n), theta' (n), l (n), l' (n), theta_d, theta_d'``
``(, e, M_1..M_n when EnvConfig.with_params)]``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..physics import kernels
from ..tasks.reward import reward_terms
from ..tasks.termination import failure_code

__all__ = ["step_rows", "step_rows", "step_rows_parallel", "info_batch", "write_obs",
           "N_COMPONENTS"]

N_COMPONENTS = 5


@njit(cache=True, inline="always")
def write_obs(nu, y, amplitude, frequency, par, with_params, noise, out):
    """Fill one observation row; ``noise`` (4n,) is added to [theta, theta', l, l']."""
    m = y.shape[0]
    n = m // 4
    out[0] = math.sin(nu)
    out[1] = math.cos(nu)
    for i in range(m):
        out[2 + i] = y[i] + noise[i]
    phase = frequency * nu
    out[2 + m] = amplitude * math.sin(phase)
    out[3 + m] = amplitude * frequency * math.cos(phase)
    if with_params:
        out[4 + m] = par[kernels.P_ECC]
        tail = par[kernels.P_TAIL:]
        for j in range(n):
            out[5 + m + j] = tail[j] - (tail[j + 1] if j + 1 < n else 0.0)


@njit(cache=True)
def step_rows(rows, nu, y, action, max_reel_rate, dist, par, h, n_sub, amplitude, frequency,
              weights, length_min, length_max, accel_ref, length_nominal, with_params, noise,
              obs, reward, components, failure, tension_min, tension_end, deriv_end):
    """Advance the rows listed in ``rows`` (int64) by one control step, in place.

    Rows not listed are left untouched.

    Parameters
    ----------
    nu, y : (B,), (B, 4n)  true anomaly [rad] and state rows, updated.
    action : (B, n)  normalised reel-rate commands, clipped to [-1, 1];
        l'_cmd = action * max_reel_rate.
    dist : (B, n)  disturbance on theta'' held over the step (paper Eq. 20).
    par : (B, 6+n) or (1, 6+n)  kernel parameter rows.
    weights : tuple  RewardWeights.as_tuple().
    length_nominal : (n,)  nominal tether lengths l_i,nom [-] of the length penalty.
    noise : (B, 4n)  observation noise.
    obs, reward, components, failure, tension_min, tension_end, deriv_end : outputs.

    A row whose state turns non-finite keeps its previous state (so nothing non-finite
    reaches the observation) and gets failure code 1 and reward 0 (the lowest).
    """
    work = _row_work(y.shape[1] // 4)
    for i in range(rows.shape[0]):
        _step_row(rows[i], nu, y, action, max_reel_rate, dist, par, h, n_sub, amplitude,
                  frequency, weights, length_min, length_max, accel_ref, length_nominal,
                  with_params, noise,
                  obs, reward, components, failure, tension_min, tension_end, deriv_end, work)


@njit(cache=True, parallel=True)
def step_rows_parallel(rows, n_chunks, nu, y, action, max_reel_rate, dist, par, h, n_sub,
                       amplitude, frequency, weights, length_min, length_max, accel_ref,
                       length_nominal, with_params, noise, obs, reward, components, failure,
                       tension_min,
                       tension_end, deriv_end):
    """:func:`step_rows` on numba's threads: ``n_chunks`` contiguous chunks of ``rows``.

    Each chunk has its own scratch and every row runs the same :func:`_step_row`, so
    the results are bitwise those of :func:`step_rows`.
    """
    count = rows.shape[0]
    n = y.shape[1] // 4
    for c in prange(n_chunks):
        work = _row_work(n)
        for i in range(c * count // n_chunks, (c + 1) * count // n_chunks):
            _step_row(rows[i], nu, y, action, max_reel_rate, dist, par, h, n_sub, amplitude,
                      frequency, weights, length_min, length_max, accel_ref, length_nominal,
                      with_params, noise, obs, reward, components, failure, tension_min,
                      tension_end,
                      deriv_end, work)


@njit(cache=True)
def _row_work(n):
    """Scratch of :func:`_step_row` for n tethers."""
    return (kernels.make_scratch(n), np.empty(n), np.empty(n), np.empty(n), np.empty(4 * n))


@njit(cache=True, inline="always")
def _step_row(b, nu, y, action, max_reel_rate, dist, par, h, n_sub, amplitude, frequency,
              weights, length_min, length_max, accel_ref, length_nominal, with_params, noise, obs,
              reward,
              components, failure, tension_min, tension_end, deriv_end, work):
    """One control step of row b (the body shared by every batched entry point)."""
    scratch, cmd, act, accel, prev = work
    m = y.shape[1]
    n = m // 4
    shared = par.shape[0] == 1
    pb = par[0] if shared else par[b]
    yb = y[b]
    prev[:] = yb
    for j in range(n):
        a = min(max(action[b, j], -1.0), 1.0)
        act[j] = a
        cmd[j] = a * max_reel_rate
    nu_new = kernels.advance_one(nu[b], yb, cmd, dist[b], pb, h, n_sub, scratch,
                                 tension_min[b], deriv_end[b], tension_end[b])
    nu[b] = nu_new
    code = failure_code(yb, tension_min[b], length_min, length_max)
    failure[b] = code
    if code == 1:
        yb[:] = prev
        for c in range(components.shape[1]):
            components[b, c] = 0.0
        reward[b] = 0.0
        for j in range(n):
            if not math.isfinite(tension_end[b, j]):
                tension_end[b, j] = 0.0
            if not math.isfinite(tension_min[b, j]):
                tension_min[b, j] = 0.0
        for i in range(m):
            if not math.isfinite(deriv_end[b, i]):
                deriv_end[b, i] = 0.0
    else:
        ecc = pb[kernels.P_ECC]
        k = 1.0 + ecc * math.cos(nu_new)
        k3 = k * k * k
        cor = 2.0 * ecc * math.sin(nu_new) * k3
        for j in range(n):
            accel[j] = (k3 * k * deriv_end[b, 3 * n + j] - cor * yb[3 * n + j]) / accel_ref
        phase = frequency * nu_new
        ref = amplitude * math.sin(phase)
        dref = amplitude * frequency * math.cos(phase)
        reward[b] = reward_terms(yb[0:n], yb[n:2 * n], yb[2 * n:3 * n], ref, dref, act,
                                 accel, tension_min[b], length_nominal, weights,
                                 components[b])
    write_obs(nu_new, yb, amplitude, frequency, pb, with_params, noise[b], obs[b])


@njit(cache=True)
def info_batch(nu, y, par, deriv_end, amplitude, frequency, accel_scale,
               theta_ref, dtheta_ref, reel_accel):
    """The derived ``info`` entries of every row (see ChainBatch.info).

    theta_ref = A sin(w nu) [rad], dtheta_ref = A w cos(w nu) [rad/rad] and the reels'
    physical acceleration reel_accel = L0 n^2 (k^4 l'' - 2 e sin(nu) k^3 l') [m/s^2],
    k = 1 + e cos(nu); written into the (B,), (B,) and (B, n) outputs. Powers use
    ``math.pow`` (libm), as numpy's scalar ``**`` does.
    """
    batch, m = y.shape
    n = m // 4
    shared = par.shape[0] == 1
    for b in range(batch):
        ecc = par[0, kernels.P_ECC] if shared else par[b, kernels.P_ECC]
        x = nu[b]
        phase = frequency * x
        theta_ref[b] = amplitude * math.sin(phase)
        dtheta_ref[b] = amplitude * frequency * math.cos(phase)
        k = 1.0 + ecc * math.cos(x)
        k4 = math.pow(k, 4.0)
        coriolis = 2.0 * ecc * math.sin(x) * math.pow(k, 3.0)
        for j in range(n):
            reel_accel[b, j] = accel_scale * (k4 * deriv_end[b, 3 * n + j]
                                              - coriolis * y[b, 3 * n + j])
