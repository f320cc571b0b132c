"""One compiled control step for a batch of environments: physics, task, observation.

Both :class:`~tether_gym.envs.TetherLibrationEnv` (a batch of one) and
:class:`~tether_gym.envs.vector.TetherLibrationVectorEnv` step through
:func:`_step_row` (:func:`step_rows` over the listed rows, :func:`step_rows_parallel`
over them on numba's threads), so their trajectories are identical for the same
inputs; :func:`start_rows` finishes their resets. Each row's observation and
``info`` entries are written by :func:`write_outputs` in the same compiled loop.
The loops are compiled without reference counting (:mod:`tether_gym.physics.jit`),
so their scratch comes from :func:`make_row_work`.

Observation layout (float32), n = N-1 tethers:
``[sin nu, cos nu, theta (n), theta' (n), l (n), l' (n), theta_d, theta_d'``
``(, e, M_1..M_n when EnvConfig.with_params)]``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..physics import kernels
from ..physics.jit import INLINE, KERNEL, LOOP
from ..tasks.reward import reward_terms
from ..tasks.termination import failure_code

__all__ = ["step_rows", "step_rows_parallel", "start_rows", "write_outputs", "anomaly_terms",
           "make_row_work",
           "INFO_SCALARS", "INFO_VECTORS", "N_COMPONENTS"]

N_COMPONENTS = 5


INFO_SCALARS = ("nu", "theta_ref", "dtheta_ref", "eccentricity")
"""Per-row floats of the ``info`` buffers, followed by the reward components."""

INFO_VECTORS = ("theta", "dtheta", "length", "dlength", "ddlength", "tension", "tension_min",
                "reel_accel")
"""Per-row (n,) arrays of the ``info`` buffers."""


@njit(**INLINE)
def anomaly_terms(nu, amplitude, frequency):
    """(sin nu, cos nu, theta_d, theta_d') with theta_d = A sin(w nu) [rad] (paper Eq. 8)."""
    phase = frequency * nu
    return (math.sin(nu), math.cos(nu), amplitude * math.sin(phase),
            amplitude * frequency * math.cos(phase))


@njit(**INLINE)
def write_outputs(b, nu, sn, cn, ref, dref, y, par, with_params, noise, obs, deriv_end,
                  tension_end, tension_min, components, accel_scale, scalars, vectors):
    """Row b's observation and ``info`` entries, from its state at true anomaly nu.

    ``sn, cn, ref, dref`` are :func:`anomaly_terms` of nu, computed once by the
    caller. The observation row (layout in the module docstring) gets ``noise[b]``
    added to [theta, theta', l, l'].
    ``scalars[:, b]`` (len(INFO_SCALARS) + N_COMPONENTS entries) and ``vectors[:, b]``
    (len(INFO_VECTORS), n) receive the info entries (see ChainBatch.info) in the
    orders of INFO_SCALARS (then the reward components) and INFO_VECTORS; the
    derived one is the reels' physical acceleration reel_accel = L0 n^2 (k^4 l'' -
    2 e sin(nu) k^3 l') [m/s^2], k = 1 + e cos(nu), with powers from ``math.pow``
    (libm), as numpy's scalar ``**`` does.
    """
    m = y.shape[1]
    n = m // 4
    out = obs[b]
    out[0] = sn
    out[1] = cn
    for i in range(m):
        out[2 + i] = y[b, i] + noise[b, i]
    out[2 + m] = ref
    out[3 + m] = dref
    ecc = par[kernels.P_ECC]
    if with_params:
        out[4 + m] = ecc
        for j in range(n):
            out[5 + m + j] = (par[kernels.P_TAIL + j]
                              - (par[kernels.P_TAIL + j + 1] if j + 1 < n else 0.0))
    scalars[0, b] = nu
    scalars[1, b] = ref
    scalars[2, b] = dref
    scalars[3, b] = ecc
    for c in range(components.shape[1]):
        scalars[4 + c, b] = components[b, c]
    k = 1.0 + ecc * cn
    k4 = math.pow(k, 4.0)
    coriolis = 2.0 * ecc * sn * math.pow(k, 3.0)
    for j in range(n):
        vectors[0, b, j] = y[b, j]
        vectors[1, b, j] = y[b, n + j]
        vectors[2, b, j] = y[b, 2 * n + j]
        vectors[3, b, j] = y[b, 3 * n + j]
        vectors[4, b, j] = deriv_end[b, 3 * n + j]
        vectors[5, b, j] = tension_end[b, j]
        vectors[6, b, j] = tension_min[b, j]
        vectors[7, b, j] = accel_scale * (k4 * deriv_end[b, 3 * n + j]
                                          - coriolis * y[b, 3 * n + j])


@njit(**LOOP)
def step_rows(rows, nu, y, action, max_reel_rate, dist, par, h, n_sub, amplitude, frequency,
              weights, length_min, length_max, accel_ref, length_nominal, with_params, noise,
              obs, reward, components, failure, tension_min, tension_end, deriv_end, accel_scale,
              info_s, info_v, work):
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
    accel_scale : float  L0 n^2 [m/s^2] of the info entry reel_accel.
    info_s, info_v : the info buffers, written by :func:`write_outputs`.
    work : tuple  scratch from :func:`make_row_work` (lane 0 is used).

    A row whose state turns non-finite keeps its previous state (so nothing non-finite
    reaches the observation) and gets failure code 1 and reward 0 (the lowest).
    """
    lane = _row_lane(work, 0)
    for i in range(rows.shape[0]):
        _step_row(rows[i], nu, y, action, max_reel_rate, dist, par, h, n_sub, amplitude,
                  frequency, weights, length_min, length_max, accel_ref, length_nominal,
                  with_params, noise, obs, reward, components, failure, tension_min,
                  tension_end, deriv_end, accel_scale, info_s, info_v, lane)


@njit(parallel=True, **LOOP)
def step_rows_parallel(rows, n_chunks, nu, y, action, max_reel_rate, dist, par, h, n_sub,
                       amplitude, frequency, weights, length_min, length_max, accel_ref,
                       length_nominal, with_params, noise, obs, reward, components, failure,
                       tension_min, tension_end, deriv_end, accel_scale, info_s, info_v,
              work):
    """:func:`step_rows` on numba's threads: ``n_chunks`` contiguous chunks of ``rows``.

    Chunk c uses lane c of ``work`` (which needs at least n_chunks lanes) and every
    row runs the same :func:`_step_row`, so the results are bitwise those of
    :func:`step_rows`.
    """
    count = rows.shape[0]
    for c in prange(n_chunks):
        lane = _row_lane(work, c)
        for i in range(c * count // n_chunks, (c + 1) * count // n_chunks):
            _step_row(rows[i], nu, y, action, max_reel_rate, dist, par, h, n_sub, amplitude,
                      frequency, weights, length_min, length_max, accel_ref, length_nominal,
                      with_params, noise, obs, reward, components, failure, tension_min,
                      tension_end, deriv_end, accel_scale, info_s, info_v, lane)


@njit(**KERNEL)
def make_row_work(n, lanes):
    """Scratch of :func:`_step_row` for n tethers, one set per lane (thread chunk).

    A flat tuple (a parallel loop cannot take nested tuples): the arrays of
    :func:`tether_gym.physics.kernels.make_scratch`, then (lanes, 3, n) for the
    command, the clipped action and the reel acceleration, and (lanes, 4n) for the
    previous state.
    """
    S, R, V, tens, K = kernels.make_scratch(n, lanes)
    slots = lanes * kernels.LANE_STRIDE
    return S, R, V, tens, K, np.empty((slots, 3, n)), np.empty((slots, 4 * n))


@njit(**INLINE)
def _row_lane(work, c):
    """Lane c of :func:`make_row_work`: (physics scratch, cmd, act, accel, prev)."""
    S, R, V, tens, K, small, prev = work
    i = c * kernels.LANE_STRIDE
    return (kernels.scratch_lane((S, R, V, tens, K), c), small[i, 0], small[i, 1],
            small[i, 2], prev[i])


@njit(**INLINE)
def _step_row(b, nu, y, action, max_reel_rate, dist, par, h, n_sub, amplitude, frequency,
              weights, length_min, length_max, accel_ref, length_nominal, with_params, noise, obs,
              reward,
              components, failure, tension_min, tension_end, deriv_end, accel_scale, info_s,
              info_v, work):
    """One control step of row b (the body shared by every batched entry point)."""
    scratch, cmd, act, accel, prev = work
    m = y.shape[1]
    n = m // 4
    shared = par.shape[0] == 1
    pb = par[0] if shared else par[b]
    yb = y[b]
    for i in range(m):
        prev[i] = yb[i]
    for j in range(n):
        a = min(max(action[b, j], -1.0), 1.0)
        act[j] = a
        cmd[j] = a * max_reel_rate
    nu_new = kernels.advance_one(nu[b], yb, cmd, dist[b], pb, h, n_sub, scratch,
                                 tension_min[b], deriv_end[b], tension_end[b])
    nu[b] = nu_new
    sn, cn, ref, dref = anomaly_terms(nu_new, amplitude, frequency)
    code = failure_code(yb, tension_min[b], length_min, length_max)
    failure[b] = code
    if code == 1:
        for i in range(m):
            yb[i] = prev[i]
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
        k = 1.0 + ecc * cn
        k3 = k * k * k
        cor = 2.0 * ecc * sn * k3
        for j in range(n):
            accel[j] = (k3 * k * deriv_end[b, 3 * n + j] - cor * yb[3 * n + j]) / accel_ref
        reward[b] = reward_terms(yb[0:n], yb[n:2 * n], yb[2 * n:3 * n], ref, dref, act,
                                 accel, tension_min[b], length_nominal, weights,
                                 components[b])
    write_outputs(b, nu_new, sn, cn, ref, dref, y, pb, with_params, noise, obs, deriv_end,
                  tension_end, tension_min, components, accel_scale, info_s, info_v)


@njit(**LOOP)
def start_rows(rows, nu, y, par, amplitude, frequency, with_params, noise, obs, components,
               tension_min, tension_end, deriv_end, accel_scale, info_s, info_v, work):
    """Finish the reset of the listed rows, whose ``nu``, ``y``, ``par`` and ``noise`` are set.

    Each row gets dy/dnu and T^ at its initial state with the reels holding their
    rate (l'_cmd = l', no disturbance: the state the first step starts from) in
    ``deriv_end``, ``tension_end`` and ``tension_min``, its observation in ``obs`` and
    its info entries in ``info_s``, ``info_v`` (:func:`write_outputs`; the reward
    components must be set). ``work`` is scratch from :func:`make_row_work` (lane 0 is used).
    """
    n = y.shape[1] // 4
    (S, R, V, tens, _, _, _), hold, still, _, _ = _row_lane(work, 0)
    for j in range(n):
        still[j] = 0.0
    shared = par.shape[0] == 1
    for i in range(rows.shape[0]):
        b = rows[i]
        pb = par[0] if shared else par[b]
        yb = y[b]
        for j in range(n):
            hold[j] = yb[3 * n + j]
        kernels.controlled_rhs_tension(nu[b], yb, (hold, still, pb, S, R, V, tens),
                                       deriv_end[b])
        for j in range(n):
            tension_end[b, j] = tens[j]
            tension_min[b, j] = tens[j]
        sn, cn, ref, dref = anomaly_terms(nu[b], amplitude, frequency)
        write_outputs(b, nu[b], sn, cn, ref, dref, y, pb, with_params, noise, obs, deriv_end,
                      tension_end, tension_min, components, accel_scale, info_s, info_v)


