"""The chain's controlled step on torch tensors: physics, task and observation, batched.

This is a port of the compiled step (:func:`tether_gym.envs.step_kernel.step_rows`
with :func:`tether_gym.physics.kernels.advance_one`) to whole-batch torch operations,
so that thousands of chains step at once on a CUDA device (or on the CPU, through the
same code). It holds no equation of its own: every line mirrors a line of the numba
kernels, which carry the derivation (paper Sec. 2, Eqs. 4-6 and 20; docs/model.md),
in the same order of operations, and tests/agents/accel/test_accel_chain.py checks every
output against the numba step to 1e-12 (relative, float64).

Notation as in :mod:`tether_gym.physics.kernels`: tether j = 0..n-1 at angle th_j
[rad] from the local vertical (positive when the lower body trails), length l_j [-],
primes d/dnu; q = 2 e sin(nu) / k, k = 1 + e cos(nu), w_j = 1 + th_j',
Mt_jk = Mt_{max(j,k)}, c_jk = cos(th_k - th_j), s_jk = sin(th_k - th_j).

Shapes: B rows (chains), n tethers. ``nu`` (B,), ``y`` (B, 4n) in the STATE layout
[theta, theta', l, l'], parameter rows ``par`` (B, P) in the PARAMS layout. Every
function is a pure function of tensors (no in-place writes into its inputs), so the
step can be traced by ``torch.compile`` or captured in a CUDA graph.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from tether_gym.physics.state import PARAMS
from tether_gym.tasks.cost import COST_PARTS, CostParams
from tether_gym.tasks.reward import TERMS, RewardParams
from tether_gym.tasks.termination import (
    DIVERGENCE_BOUND,
    KEEP_PREVIOUS,
    TUMBLE_ANGLE,
    Failure,
)

__all__ = ["ChainConsts", "StepResult", "TaskStep", "control_step", "rhs", "advance",
           "reel_accel", "failure_code", "reward", "cost", "observation", "info_vectors",
           "TUMBLE_ANGLE"]

if COST_PARTS != ("slack", "length", "tumble"):  # a part added there and not in cost()
    raise RuntimeError(f"the torch cost computes slack, length, tumble, not {COST_PARTS}")

LENGTH_FLOOR = 1.0e-6
"""Smallest l [-] whose logarithm the observation takes (as the numba step)."""


class ChainConsts(NamedTuple):
    """Constants of one batch, from the env's configuration (``StepConfig`` on torch).

    Built by :func:`tether_gym_agents.accel.vec_env.chain_consts`.
    """

    n: int                      # tethers
    full_gravity: bool          # the batch's gravity model (one per configuration)
    max_reel_rate: float        # l'_cmd at |u| = 1 [-]
    incremental: bool           # action_mode "increment"
    increment_gain: float       # [-]
    h: float                    # RK4 step [rad]
    substeps: int               # RK4 steps per control step
    amplitude: float            # A [rad]
    frequency: float            # w [-]
    length_min: float           # [-]
    length_max: float           # [-]
    accel_ref: float            # a_ref / (L0 n^2) [-]
    accel_scale: float          # L0 n^2 [m/s^2]
    with_eccentricity: bool     # e closes the observation
    with_masses: bool           # the mass fractions follow it
    reward: RewardParams        # the reward's weights (tasks.reward)
    cost: CostParams            # the constraint cost's thresholds (tasks.cost)
    length_nominal: torch.Tensor  # (n,) l_i,nom [-]
    mt_index: torch.Tensor      # (n, n) int64: max(j, k)


class StepResult(NamedTuple):
    """What :func:`advance` returns besides the new true anomaly."""

    y: torch.Tensor            # (B, 4n) state at the end
    tension_min: torch.Tensor  # (B, n) smallest T^ over the substep boundaries
    derivative: torch.Tensor   # (B, 4n) dy/dnu at the end (holds theta'', l'')
    tension: torch.Tensor      # (B, n) T^ at the end


def _split(y: torch.Tensor, n: int):
    """(theta, theta', l, l'), each (B, n), in the STATE layout's order."""
    return y[:, :n], y[:, n:2 * n], y[:, 2 * n:3 * n], y[:, 3 * n:]


def _par(par: torch.Tensor, n: int):
    """(e, L0/p, a_bound, v_bound, tau, Mt (B, n)) from parameter rows (PARAMS layout)."""
    sl = PARAMS.slices(n)
    col = {name: par[:, s.start] for name, s in sl.items() if name != "tail_mass"}
    return (col["eccentricity"], col["length_ratio"], col["accel_bound"], col["speed_bound"],
            col["time_constant"], par[:, sl["tail_mass"]])


def _cumsum(x: torch.Tensor, reverse: bool = False) -> torch.Tensor:
    """Running sums along the tethers, one addition at a time (the kernels' order)."""
    n = x.shape[1]
    order = range(n - 1, -1, -1) if reverse else range(n)
    out: list = [None] * n
    acc = torch.zeros_like(x[:, 0])
    for j in order:
        acc = acc + x[:, j]
        out[j] = acc
    return torch.stack(out, dim=1)


def _links(nu, th, dth, ln, e, eps, mt, full: bool):
    """Link trigonometry and tail gravity (``kernels._links``).

    Returns (q, sin nu, k, cos th, sin th, w, G^perp, G^par), the last five (B, n).
    """
    sn = torch.sin(nu)
    cn = torch.cos(nu)
    k = 1.0 + e * cn
    q = 2.0 * e * sn / k
    c = torch.cos(th)
    s = torch.sin(th)
    w = 1.0 + dth
    rr = -_cumsum(ln * c)
    rv = -_cumsum(ln * s)
    if full:
        ke = (k * eps)[:, None]
        xr = ke * rr
        xv = ke * rv
        qq = 2.0 * xr + xr * xr + xv * xv
        fm = torch.expm1(-1.5 * torch.log1p(qq))  # |e_r + x|^-3 - 1
        scale = (-1.0 / (k * k * eps))[:, None]
        gr = scale * (fm + xr * (1.0 + fm))
        gv = scale * (xv * (1.0 + fm))
    else:
        gr = 2.0 * rr / k[:, None]
        gv = -rv / k[:, None]
    mass = mt - torch.cat([mt[:, 1:], torch.zeros_like(mt[:, :1])], dim=1)  # M_j
    Gr = _cumsum(mass * gr, reverse=True)
    Gv = _cumsum(mass * gv, reverse=True)
    g_perp = -Gr * s + Gv * c
    g_par = Gr * c + Gv * s
    return q, sn, k, c, s, w, g_perp, g_par


def _pairs(c, s, mt, cc: ChainConsts):
    """(Mt_jk, c_jk, s_jk), each (B, n, n) [j, k] (``kernels._coefficients``)."""
    mtj = mt[:, cc.mt_index]
    cjk = c[:, None, :] * c[:, :, None] + s[:, None, :] * s[:, :, None]
    sjk = s[:, None, :] * c[:, :, None] - c[:, None, :] * s[:, :, None]
    return mtj, cjk, sjk


def _solve_spd(S: torch.Tensor, R: torch.Tensor) -> torch.Tensor:
    """S^-1 R for symmetric positive definite S (B, n, n), R (B, n): ``kernels._solve_spd``.

    Gaussian elimination without pivoting, in the kernel's order of operations.
    """
    n = S.shape[1]
    a = [[S[:, i, j] for j in range(n)] for i in range(n)]
    r = [R[:, i] for i in range(n)]
    for p in range(n):
        inv = 1.0 / a[p][p]
        for i in range(p + 1, n):
            fac = a[i][p] * inv
            for j in range(p + 1, n):
                a[i][j] = a[i][j] - fac * a[p][j]
            r[i] = r[i] - fac * r[p]
    x: list = [None] * n
    for p in range(n - 1, -1, -1):
        acc = r[p]
        for j in range(p + 1, n):
            acc = acc - a[p][j] * x[j]
        x[p] = acc / a[p][p]
    return torch.stack(x, dim=1)


def _reel(k, sn, dl, cmd, e, a_bound, v_bound, tau):
    """Actual l'' [-] of the reels (``kernels._reel``); arguments (B, 1) or (B, n)."""
    k2 = k * k
    k4 = k2 * k2
    cap = v_bound / k2
    cmd = torch.minimum(torch.maximum(cmd, -cap), cap)  # inf cap: unchanged
    cor = 2.0 * e * sn * (k * k) * k * dl
    a = k4 * (cmd - dl) / tau - cor
    a = torch.minimum(torch.maximum(a, -a_bound), a_bound)
    return (a + cor) / k4


def reel_accel(k, sn, e, dl, ddl):
    """L_ddot / (L0 n^2) = k^4 l'' - 2 e sin(nu) k^3 l' [-] (``orbit.reel_accel``)."""
    k2 = k * k
    return k2 * k2 * ddl - 2.0 * e * sn * (k * k) * k * dl


def rhs(nu, y, command, disturbance, par, cc: ChainConsts, node: bool):
    """dy/dnu of the chains with their reels (``kernels.controlled_rhs``).

    ``command`` holds l'_cmd [-] and ``disturbance`` d [rad/rad^2] (B, n). Returns
    (dy, tension), tension (B, n) at (nu, y) when ``node`` else None.
    """
    n = cc.n
    th, dth, ln, dl = _split(y, n)
    e, eps, a_bound, v_bound, tau, mt = _par(par, n)
    q, sn, k, c, s, w, g_perp, g_par = _links(nu, th, dth, ln, e, eps, mt, cc.full_gravity)
    def col(v):
        return (v[:, None])
    ddl = _reel(col(k), col(sn), dl, command, col(e), col(a_bound), col(v_bound), col(tau))
    mtj, cjk, sjk = _pairs(c, s, mt, cc)
    lk = ln[:, None, :]
    wk = w[:, None, :]
    # entries (j, k) of the theta-equations (kernels._coefficients)
    a_jk = mtj * ln[:, :, None] * lk * cjk
    p_jk = mtj * (2.0 * wk * cjk - col(q)[:, :, None] * sjk)
    q_jk = mtj * sjk
    b_jk = -mtj * lk * wk * (wk * sjk + col(q)[:, :, None] * cjk)
    terms = b_jk + p_jk * dl[:, None, :] + q_jk * ddl[:, None, :]
    b = _rowsum(g_perp, terms)
    ddth = _solve_spd(a_jk, -ln * b)
    tension = None
    if node:
        lam = ddl - col(q) * dl
        sig = w * (2.0 * dl - col(q) * ln)
        inner = mtj * (-(lam[:, None, :] - lk * wk * wk) * cjk
                       + (lk * ddth[:, None, :] + sig[:, None, :]) * sjk)
        tension = _rowsum(-g_par, inner)
    dy = torch.cat([dth, ddth + disturbance, dl, ddl], dim=1)
    return dy, tension


def _rowsum(start: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """start_j + sum_k x[:, j, k], one addition at a time in k (the kernels' order), (B, n)."""
    acc = start
    for kk in range(x.shape[2]):
        acc = acc + x[:, :, kk]
    return acc


def _fold_min(running: torch.Tensor, value: torch.Tensor) -> torch.Tensor:
    """Python's ``min(running, value)``: a NaN value leaves the running minimum as it is."""
    return torch.where(value < running, value, running)


def advance(nu, y, command, disturbance, par, cc: ChainConsts, substeps: int):
    """``substeps`` RK4 steps of h from (nu, y) with the reels (``kernels.advance_one``).

    Returns (nu_end, :class:`StepResult`). With ``substeps == 0`` only the derivative
    and the tension at (nu, y) are evaluated (the reset's evaluation).
    """
    h = cc.h
    half = 0.5 * h
    sixth = h / 6.0
    t = nu
    tmin = torch.full_like(y[:, :cc.n], math.inf)
    for i in range(substeps):
        k1, ten = rhs(t, y, command, disturbance, par, cc, True)
        tmin = _fold_min(tmin, ten)
        k2, _ = rhs(t + half, y + half * k1, command, disturbance, par, cc, False)
        k3, _ = rhs(t + half, y + half * k2, command, disturbance, par, cc, False)
        k4, _ = rhs(t + h, y + h * k3, command, disturbance, par, cc, False)
        y = y + sixth * (k1 + 2.0 * (k2 + k3) + k4)
        t = nu + (i + 1) * h
    deriv, ten = rhs(t, y, command, disturbance, par, cc, True)
    tmin = _fold_min(tmin, ten)
    return t, StepResult(y, tmin, deriv, ten)


class TaskStep(NamedTuple):
    """Everything one control step produces for every row (:func:`control_step`)."""

    nu: torch.Tensor
    y: torch.Tensor
    u: torch.Tensor            # the normalised command in force [-]
    tension: torch.Tensor
    tension_min: torch.Tensor
    derivative: torch.Tensor
    reward: torch.Tensor
    components: torch.Tensor
    cost: torch.Tensor         # (B, len(COST_NAMES)) the cost and its parts
    failure: torch.Tensor      # int64 Failure codes
    obs: torch.Tensor          # float32


def control_step(nu, y, u, action, disturbance, noise, par, cc: ChainConsts) -> TaskStep:
    """One control step of every row (``step_kernel.step_rows`` with reset False).

    The action sets the command (``envs.actions.next_command``), the chain advances
    (:func:`advance`), the failure code, reward, cost and observation follow
    (``step_kernel._task``, ``write_outputs``); a non-finite or diverged step keeps the
    previous state with reward 0 and its non-finite tensions and derivative zeroed, and
    its cost is computed from those (a zeroed tension costs ``cost_slack`` = 1).
    A pure function of tensors: ``torch.compile`` can fuse it.
    """
    n = cc.n
    clipped = torch.clamp(action, -1.0, 1.0)
    u = torch.clamp(u + cc.increment_gain * clipped, -1.0, 1.0) if cc.incremental \
        else clipped
    nu, res = advance(nu, y, u * cc.max_reel_rate, disturbance, par, cc, cc.substeps)
    code = failure_code(res.y, res.tension_min, cc)
    keep = (code == KEEP_PREVIOUS[0]) | (code == KEEP_PREVIOUS[1])
    kc = keep[:, None]
    y = torch.where(kc, y, res.y)

    def finite_or_zero(x):
        return torch.where(kc & ~torch.isfinite(x), torch.zeros_like(x), x)

    tension = finite_or_zero(res.tension)
    tension_min = finite_or_zero(res.tension_min)
    derivative = finite_or_zero(res.derivative)
    sn = torch.sin(nu)[:, None]
    e = par[:, :1]
    k = 1.0 + e * torch.cos(nu)[:, None]
    accel = reel_accel(k, sn, e, y[:, 3 * n:], derivative[:, 3 * n:]) / cc.accel_ref
    ref = cc.amplitude * torch.sin(cc.frequency * nu)
    dref = cc.amplitude * cc.frequency * torch.cos(cc.frequency * nu)
    rew, comps = reward(y, u, accel, tension_min, ref, dref, cc)
    rew = torch.where(keep, torch.zeros_like(rew), rew)
    comps = torch.where(kc, torch.zeros_like(comps), comps)
    costs = cost(y, tension_min, cc)
    obs = observation(nu, y, noise, par, u, cc)
    return TaskStep(nu, y, u, tension, tension_min, derivative, rew, comps, costs, code, obs)


def failure_code(y, tension_min, cc: ChainConsts) -> torch.Tensor:
    """Failure codes (B,) int64, checked in ``termination.failure_code``'s order."""
    n = cc.n
    finite = torch.isfinite(y).all(dim=1) & torch.isfinite(tension_min).all(dim=1)
    big = ((y.abs() > DIVERGENCE_BOUND).any(dim=1)
           | (tension_min.abs() > DIVERGENCE_BOUND).any(dim=1))
    slack = (tension_min <= 0.0).any(dim=1)
    th, _, ln, _ = _split(y, n)
    tumble = (th.abs() >= TUMBLE_ANGLE).any(dim=1)
    length = ((ln < cc.length_min) | (ln > cc.length_max)).any(dim=1)
    code = torch.zeros_like(y[:, 0], dtype=torch.int64)
    # highest precedence last
    for flag, value in ((length, Failure.LENGTH), (tumble, Failure.TUMBLE),
                        (slack, Failure.SLACK), (big, Failure.DIVERGED)):
        code = torch.where(flag, torch.full_like(code, int(value)), code)
    return torch.where(finite, code, torch.full_like(code, int(Failure.NONFINITE)))


def reward(y, u, accel_ratio, tension_min, ref, dref, cc: ChainConsts):
    """(reward (B,), components (B, 1 + terms)): ``reward.term_sums`` + ``reward_terms``.

    ``u`` is the normalised command (B, n), ``accel_ratio`` L_ddot / a_ref (B, n).
    """
    p = cc.reward
    n = cc.n
    th, dth, ln, _ = _split(y, n)
    margin = torch.clamp(1.0 - tension_min / p.safe_tension, 0.0, 1.0)
    x = torch.log(torch.clamp(ln, min=1e-300) / cc.length_nominal) / p.length_delta
    per = {"effort": u * u,
           "accel": torch.clamp(accel_ratio * accel_ratio, max=1.0),
           "slack": margin * margin,
           "length": torch.clamp((torch.sqrt(1.0 + x * x) - 1.0) / p.length_norm, max=1.0)}
    raw = [_sum_along(per[name]) for name in TERMS]  # KeyError if a term is added there
    e = th - ref[:, None]
    de = dth - dref[:, None]
    err = _sum_along(e * e)
    rate = _sum_along(de * de)
    cost = (err + p.rate_weight * rate) / n
    lorentz = 1.0 / (1.0 + cost / (p.sigma * p.sigma))
    rms = torch.sqrt(cost)
    log_part = torch.clamp(torch.log(torch.clamp(rms, min=1e-300)) / p.log_floor_ln, max=1.0)
    log_part = torch.where(rms <= 1.0, log_part, torch.zeros_like(log_part))
    track = p.track_weight * ((1.0 - p.log_share) * lorentz + p.log_share * log_part)
    parts = [track]
    total = track
    for i, r in enumerate(raw):
        if p.margin[i]:
            part = p.weight[i] * (1.0 - r / n)
        else:
            part = -track * p.weight[i] * r / n
        parts.append(part)
        total = total + part
    return total, torch.stack(parts, dim=1)


def cost(y, tension_min, cc: ChainConsts) -> torch.Tensor:
    """The cost and its parts (B, len(COST_NAMES)), in COST_NAMES' order (``cost_terms``).

    Each part is 1.0 where any tether of the row is near its bound, else 0.0; the
    comparisons are ``tasks.cost.cost_terms``' own, negated, so a NaN costs as it does
    there.
    """
    p = cc.cost
    th, _, ln, _ = _split(y, cc.n)
    slack = (~(tension_min >= p.tension)).any(dim=1)
    length = (~((ln >= p.length_low) & (ln <= p.length_high))).any(dim=1)
    tumble = (~(th.abs() < p.tumble)).any(dim=1)
    parts = [flag.to(y.dtype) for flag in (slack, length, tumble)]
    return torch.stack([parts[0] + parts[1] + parts[2], *parts], dim=1)


def _sum_along(x: torch.Tensor) -> torch.Tensor:
    """sum_j x[:, j], one addition at a time (the kernels' order), (B,)."""
    acc = torch.zeros_like(x[:, 0])
    for j in range(x.shape[1]):
        acc = acc + x[:, j]
    return acc


def observation(nu, y, noise, par, u, cc: ChainConsts, dtype=torch.float32):
    """Observations (B, obs_dim) in the OBSERVATION layout (``step_kernel.write_outputs``).

    The observed state entries are rounded to the observation's dtype before the errors
    and log-lengths are computed from them, as the numba step computes them from the
    float32 entries it has just written.
    """
    n = cc.n
    ref = cc.amplitude * torch.sin(cc.frequency * nu)
    dref = cc.amplitude * cc.frequency * torch.cos(cc.frequency * nu)
    seen = (y + noise).to(dtype)
    th, dth, ln, dl = _split(seen, n)
    wide = y.dtype
    err = (th.to(wide) - ref[:, None]).to(dtype)
    derr = (dth.to(wide) - dref[:, None]).to(dtype)
    loglen = torch.log(torch.clamp(ln.to(wide), min=LENGTH_FLOOR) / cc.length_nominal).to(dtype)
    parts = [torch.sin(nu)[:, None], torch.cos(nu)[:, None], th, dth, ln, dl,
             ref[:, None], dref[:, None], err, derr, loglen, u]
    if cc.with_eccentricity:
        parts.append(par[:, PARAMS.slices(n)["eccentricity"]])
    if cc.with_masses:
        mt = par[:, PARAMS.slices(n)["tail_mass"]]
        parts.append(mt - torch.cat([mt[:, 1:], torch.zeros_like(mt[:, :1])], dim=1))
    return torch.cat([p.to(dtype) for p in parts], dim=1)


def info_vectors(nu, y, par, result: StepResult, cc: ChainConsts):
    """(reel_accel [m/s^2], ddlength) (B, n) of the ``info`` (``write_outputs``)."""
    n = cc.n
    e = par[:, PARAMS.slices(n)["eccentricity"]]
    k = 1.0 + e * torch.cos(nu)[:, None]
    sn = torch.sin(nu)[:, None]
    dl = y[:, 3 * n:]
    ddl = result.derivative[:, 3 * n:]
    return cc.accel_scale * reel_accel(k, sn, e, dl, ddl), ddl
