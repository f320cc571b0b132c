"""A nonlinear model-predictive reel controller with hard constraints over its horizon.

At every control step k the controller plans the held normalised reel-rate commands
of the next M control steps on the scenario's nominal model, as moves U = (u_0, u_1,
...) each held for a block of steps, and sends u_0 (receding horizon). Its prediction
model is the env's own step, :func:`tether_gym.physics.transition`, in the symbolic
form of :mod:`.mpc_model` (RK4 with the reels in the loop, the env's substeps; tested
equal to ``transition`` to 1e-10), so every derivative is exact.

Problem (per control step; tether j, planned step i = 1..M, nu_i = nu + i dt)::

    min_U   sum_i w_i sum_j [ (theta_ij - theta_d,i)^2 + w_rate (theta'_ij - theta_d,i')^2 ]
              + w_move sum_b |u_b - u_{b-1}|^2
    s.t.    |u_b| <= 1                                 (the action box)
            T^_j >= T_safe at every substep boundary of every planned step (reward.py's
                                                         T_safe; the env fails at T^ <= 0)
            |theta_ij| <= pi/2 - libration_margin      (tumbling: termination.py)
            l_min + m <= l_ij, l_ij,stop <= l_max - m  (length bounds; l_stop the braking
                                                         stop of safety.py)
            |k^4 (u_b l'_max - l') / tau - 2 e sin(nu) k^3 l'| <= a_bound
                    where move b starts                 (the reel-acceleration limit)

with u_{-1} the command the env holds. Move blocking: the plan has 15 moves u_b, the
first ten held for one control step each and the last five for 2, 2, 4, 4 and 8 (M = 30
steps, 0.75 rad at the default step); w_i = 1 on the one-step moves and w_tail = 0.01
on the long ones. The long tail is the controller's foresight: every constraint holds
on it with full force, so the plan never steers into a state that it cannot leave
safely within 0.75 rad (with ten one-step moves alone, 0.25 rad, the plan went
greedily for the error and the chain went slack in one default-suite episode and
tumbled in another); its light weight keeps the held tail moves from biasing the
tracking (with w_tail = 1 the last-orbit error stalled near 1e-6 rad). The move weight
1e-5 costs no measurable precision (1e-3 cost a factor of 60) and damps the reels'
response to observation noise a little.

The reel-acceleration limit is a constraint on what the plan asks of the reels: where a
move starts, the reel's demanded physical acceleration (the lag
:func:`tether_gym.physics.kernels._reel` computes before it saturates) stays within
the limit, so no planned reel saturates. The prediction model saturates anyway (it is
the physics), so every predicted trajectory meets the limit whatever the plan;
``tests/agents/baselines/test_mpc.py`` checks it with the others on the controller's
own predictions. Why a constraint and not just the model's saturation: a saturated
reel does not respond to its command, so the linearised tension at a node where a
planned move jumps had no gradient, the QP could not repair a dip there and paid for
it with the slack (five tumbles and two slack failures in 70 default-suite episodes
before it; the plan's reels reach a new rate more slowly, in a few control steps).
theta_d comes from the observed theta_d, theta_d' (paper Eq. 8,
:func:`.prediction.reference_ahead`).

Solver: a Gauss-Newton sequential quadratic programme, warm-started with the previous
plan shifted by one step (a real-time-iteration scheme with ``iterations`` SQP steps
per control step). Each step linearises the tracking residuals and the constraints with
CasADi's exact Jacobians of the horizon, and solves the condensed QP (15 n moves and
two slacks) with DAQP through ``casadi.conic``. The constraints are hard in the
exact-penalty sense: two slacks s >= 0 relax them, one for T^ >= T_safe (priced at
``tension_slack``), one for the bounds that end an episode (priced at ``slack``, 1000
times more: T^ >= ``tension_floor``, tumbling, lengths, the reels' acceleration), so
the QP always has a solution; when the horizon problem is feasible the penalty is
exact (s = 0), and when it is not (a transient in which no plan keeps T_safe), the plan
gives up tension margin before it gives up a failure bound. With one slack for all the
rows, a tension deficit of 0.3 priced like a libration excess of 0.3 rad: the plan
reeled in hard for tension and the chain tumbled (six of 70 default-suite episodes).
A backtracking line search on the merit 0.5 |r|^2 + prices x largest violations keeps the
steps from overshooting in transients. CasADi is imported lazily (the ``mpc`` extra).

The same figures on every machine. Each SQP step (linearisation, the QP's matrices J^T J
and J^T r, the QP itself) is one CasADi function call, and the merit of the line search
another: CasADi's own scalar operations in a fixed order and DAQP, never numpy's BLAS.
Until 0.6.0 the Python side formed J^T J and J^T r with numpy (OpenBLAS), whose kernel
and so whose summation order depends on the CPU; the closed loop amplifies such
last-bit differences over an episode's transient (ecc_0.1, env seed 0: tracking RMS
9.4e-6 rad with OpenBLAS's Haswell kernel, the machine of the shipped 0.5.0 figures,
1.2e-5 with its SkylakeX kernel, 4.4e-5 with Sandybridge's, and a tumble with Nehalem's,
all from the same code). Now ``OPENBLAS_CORETYPE`` changes nothing
(``tests/agents/baselines/test_mpc_reproduces.py`` re-runs shipped episodes). A
perturbation of the last bit anywhere still moves an episode: with the move weight
scaled by 1 + 1e-15 the paper episode tracks at 1.7e-6 rad instead of 5.7e-7, and
ecc_0.0 seed 0, which goes slack at 2.35 orbits (its tension at T_safe for most of the
episode, its tethers shortening to 0.06), survives at 6.5e-7 to 1.3e-6 rad in all ten
re-runs with 1e-15 <= |eps| <= 1e-10. Compare runs of this controller made with the
same arithmetic, episode by episode, or over many episodes.

Reach: checked on N = 3 (2 tethers) and e <= 0.4 (the default, robust and beyond
suites; at e = 0.4 it survives without converging). At e = 0.5 one of two random-init
episodes tumbled, at e = 0.6 ... 0.9 all of them (two each): a nominal e above
:data:`SUPPORTED_ECCENTRICITY` warns. Its cost grows steeply with the number of tethers
(building the functions and every control step; see :data:`SUPPORTED_TETHERS`, above
which it warns). ``blocks``, ``iterations``, the weights and the margins are bounded
(:data:`MAX_MOVES`, :data:`MAX_HORIZON`, :data:`MAX_ITERATIONS`), and a non-finite
observation is a ValueError.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Iterable, Mapping

import numpy as np

from tether_gym.params import check_masses, check_range
from tether_gym.physics import PARAMS
from tether_gym.tasks.termination import TUMBLE_ANGLE

from ..common.obs import ObservationLayout, ReelRatePolicy
from . import mpc_model
from .prediction import NominalStep, OnNominalStep, reference_ahead

__all__ = ["ModelPredictiveController", "Plan"]

_FUNCTIONS: dict[tuple, tuple] = {}
MAX_MOVES = 40
"""The most moves a plan may hold (``blocks``): the build cost grows with moves x steps."""
MAX_HORIZON = 120
"""The most control steps a plan may span (``sum(blocks)``, 3 rad at the default step)."""
MAX_ITERATIONS = 20
"""The most SQP iterations per control step."""
SUPPORTED_ECCENTRICITY = 0.4
"""The largest nominal e that mpc was checked on (the ``beyond`` suite); above it a warning."""
SUPPORTED_TETHERS = 2
"""The most tethers (N - 1) that mpc was checked on (the suites' chain, N = 3); above it a
warning: building its functions and every control step take much longer (module
docstring, 'Reach')."""
CONVERGED = 1e-7
"""A full, feasible Gauss-Newton step that changes the first move (the command sent) by
less than this [-] ends the control step's iterations: 1e-7 of the command moves theta
by ~1e-10 rad over a step, far below the float32 floor of the observation."""


class Plan:
    """A plan's predicted trajectory (M planned steps, n tethers).

    Attributes
    ----------
    theta, dtheta, length, stop : ndarray, shape (M, n)
        theta [rad], theta' [rad/rad], l [-] and the braking-stop length l_stop [-] at
        the end of each planned step.
    tension : ndarray, shape (M, substeps + 1, n)
        T^ [-] at the substep boundaries of each planned step.
    ddlength : ndarray, shape (M, substeps + 1, n)
        l'' [-] of the reels at those boundaries (the acceleration check).
    nu_nodes : ndarray, shape (M, substeps + 1)
        True anomaly [rad] of those boundaries.
    """

    def __init__(self, values: np.ndarray, m: int, n: int, substeps: int):
        z = np.asarray(values, dtype=float).ravel()
        sizes = [m * n, m * n, m * (substeps + 1) * n, m * n, m * n,
                 m * (substeps + 1) * n, m * (substeps + 1)]
        parts = np.split(z, np.cumsum(sizes)[:-1])
        self.theta = parts[0].reshape(m, n)
        self.dtheta = parts[1].reshape(m, n)
        self.tension = parts[2].reshape(m, substeps + 1, n)
        self.length = parts[3].reshape(m, n)
        self.stop = parts[4].reshape(m, n)
        self.ddlength = parts[5].reshape(m, substeps + 1, n)
        self.nu_nodes = parts[6].reshape(m, substeps + 1)


def _step_blocks(blocks: tuple[int, ...]) -> list[int]:
    """The column of U (the move) that each planned control step holds."""
    return [b for b, size in enumerate(blocks) for _ in range(size)]


def _rollout(ca, nu, y, U, par, h, dims, per_substep: bool):
    """Symbolic plan: per planned step, (nu and state at its end, ...).

    The tuple of a step holds its end's nu and state, then its tensions at the substep
    boundaries (or, ``per_substep``, the (nu, y) of those boundaries), then its move.
    """
    n, substeps, full, blocks = dims
    zero = ca.SX.zeros(n)
    t, state = nu, y
    out: list[tuple] = []
    for i in _step_blocks(blocks):
        cmd = U[:, i]
        if not per_substep:
            t, state, tensions, _ = mpc_model.rk4_step(ca, t, state, cmd, zero, par, h,
                                                       substeps, n, full)
            out.append((t, state, tensions, i))
            continue
        bounds = [(t, state)]
        t0 = t
        for s in range(substeps):
            _, state, _, _ = mpc_model.rk4_step(ca, t, state, cmd, zero, par, h, 1, n, full)
            t = t0 + (s + 1) * h
            bounds.append((t, state))
        out.append((t, state, bounds, i))
    return out


def _stop_length(ca, t, state, par, n: int):
    """l_stop = l + v |v| / (2 a_bound), v = k^2 l' (the braking stop of tether_gym.safety)."""
    idx = mpc_model.param_index(n)
    k = 1.0 + par[idx["eccentricity"]] * ca.cos(t)
    v = k * k * state[3 * n:]
    return state[2 * n:3 * n] + v * ca.fabs(v) / (2.0 * par[idx["accel_bound"]])


def _demand(ca, t, state, command, par, n: int):
    """The reels' demanded L_ddot / (L0 n^2) [-] when ``command`` starts at (t, state).

    k^4 (l'_cmd - l') / tau - 2 e sin(nu) k^3 l' (:func:`tether_gym.physics.kernels._reel`
    before its saturation), the command clipped to the speed bound as the reel does.
    """
    idx = mpc_model.param_index(n)
    ecc = par[idx["eccentricity"]]
    k = 1.0 + ecc * ca.cos(t)
    k2 = k * k
    rate = state[3 * n:]
    cap = par[idx["speed_bound"]] / k2
    cmd = ca.fmin(ca.fmax(command, -cap), cap)
    return k2 * k2 * (cmd - rate) / par[idx["time_constant"]] \
        - 2.0 * ecc * ca.sin(t) * k2 * k * rate


def _symbols(ca, n: int, m: int):
    return (ca.SX.sym("nu"), ca.SX.sym("y", 4 * n), ca.SX.sym("U", n, m),
            ca.SX.sym("par", PARAMS.size(n)), ca.SX.sym("h"))


def _horizon_values(n: int, substeps: int, full: bool, blocks: tuple[int, ...]):
    """``values(nu, y, U, par, h)``, cached: the plan's predicted quantities.

    ``values`` stacks, over the M = sum(blocks) planned steps, theta, theta', the
    tensions at every substep boundary, l and l_stop at the step's end, then the reels'
    demanded acceleration where each move starts; U is (n, len(blocks)) in l'_cmd [-],
    move b held for blocks[b] control steps.
    """
    key = ("values", n, substeps, full, blocks)
    if key in _FUNCTIONS:
        return _FUNCTIONS[key]
    ca = mpc_model.casadi()
    nu, y, U, par, h = _symbols(ca, n, len(blocks))
    steps = _rollout(ca, nu, y, U, par, h, (n, substeps, full, blocks), False)
    th = [s[1][:n] for s in steps]
    dth = [s[1][n:2 * n] for s in steps]
    ten = [ca.vec(s[2]) for s in steps]
    ln = [s[1][2 * n:3 * n] for s in steps]
    stop = [_stop_length(ca, s[0], s[1], par, n) for s in steps]
    starts = [(nu, y)] + [(s[0], s[1]) for s in steps[:-1]]
    demand = [_demand(ca, *starts[i], U[:, b], par, n)
              for i, b in enumerate(_step_blocks(blocks))
              if i == 0 or steps[i - 1][3] != b]  # at the first node of each move
    z = ca.vertcat(*th, *dth, *ten, *ln, *stop, *demand)
    _FUNCTIONS[key] = ca.Function("values", [nu, y, U, par, h], [z])
    return _FUNCTIONS[key]


CONSTANTS = ("max_reel_rate", "rate", "move", "safe_tension", "tension_floor",
             "libration_bound", "length_low", "length_high", "accel_bound",
             "tension_slack", "slack")
"""The controller's constants, in the order of the vector ``c`` that the solver's
functions take (then the M stage weights w_i): l'_cmd [-] at u = 1, the cost weights of
theta' and of the moves, T_safe, the tension floor, the libration bound pi/2 - margin
[rad], the length bounds with their margins [-], the reels' acceleration bound [-] and
the prices of the two slacks."""


def _solver_functions(n: int, substeps: int, full: bool, blocks: tuple[int, ...]):
    """(merit, linearised), the cost and constraints of a plan in CasADi, cached.

    Both take ``(nu, y, u, u_prev, ref, par, h, c)``: u the plan's normalised moves
    (len(blocks) n,) move by move, u_prev (n,) the held command, ref (2M,) theta_d then
    theta_d' over the planned steps, c (:data:`CONSTANTS` then the M stage weights).

    * ``merit`` -> 0.5 |r|^2 + price_T v_T + price v (v_T the largest violation of T^ >=
      T_safe, v of the other rows; inf when the prediction is not finite);
    * ``linearised`` -> (ok, merit, r, J = dr/du, g, G = dg/du): the weighted residuals
      and the constraint rows g >= 0 (module docstring) with their exact Jacobians, and
      ok = 1 when the prediction and its Jacobian are finite (else r, J, g, G are 0).

    Every operation is a scalar operation of CasADi's virtual machine in a fixed order
    (no BLAS, no SIMD reductions), so the figures are the same on any x86-64 CPU. Up to
    two tethers, common subexpressions are evaluated once (bitwise the same values; at
    N = 3 a fifth fewer instructions, 6.2 -> 4.4 ms per linearisation, for about 10 s more
    build); with more tethers that elimination costs more to build than it saves (N = 4:
    44 s and 2.2 GB to build, N = 5: 98 s and 5 GB), so it is left out.
    """
    key = ("solver", n, substeps, full, blocks)
    if key in _FUNCTIONS:
        return _FUNCTIONS[key]
    ca = mpc_model.casadi()
    moves, m, sub = len(blocks), sum(blocks), substeps
    nu, y, _, par, h = _symbols(ca, n, moves)
    u = ca.SX.sym("u", moves * n)
    u_prev = ca.SX.sym("u_prev", n)
    ref = ca.SX.sym("ref", 2 * m)
    c = ca.SX.sym("c", len(CONSTANTS) + m)
    k = dict(zip(CONSTANTS, ca.vertsplit(c[:len(CONSTANTS)]), strict=True))
    values = _horizon_values(n, substeps, full, blocks)
    z = values(nu, y, k["max_reel_rate"] * ca.reshape(u, n, moves), par, h)
    sizes = [m * n, m * n, m * (sub + 1) * n, m * n, m * n, moves * n]
    th, dth, ten, ln, stop, demand = ca.vertsplit(z, [0, *np.cumsum(sizes).tolist()])

    def per_tether(v):  # (m,) -> (m n,), step by step (np.repeat(v, n))
        return ca.vec(ca.repmat(v.T, n, 1))

    sw = per_tether(ca.sqrt(c[len(CONSTANTS):]))
    e = sw * (th - per_tether(ref[:m]))
    ed = ca.sqrt(k["rate"]) * sw * (dth - per_tether(ref[m:]))
    du = u - ca.vertcat(u_prev, u[:-n])
    r = ca.vertcat(e, ed, ca.sqrt(k["move"]) * du)
    bound = k["libration_bound"]
    lo, hi, a_bound = k["length_low"], k["length_high"], k["accel_bound"]
    # the tension rows T^ >= T_safe first (their own slack), then the bounds that end an
    # episode: tension floor, tumbling, lengths, and the reels' acceleration
    g_raw = ca.vertcat(ten - k["safe_tension"], ten - k["tension_floor"], bound - th,
                       bound + th, ln - lo, hi - ln, stop - lo, hi - stop,
                       a_bound - demand, a_bound + demand)
    g = ca.fmin(g_raw, 1e9)  # a missing limit (inf) is a row that never binds
    rows = m * (sub + 1) * n  # the rows of T^ >= T_safe

    def merit_of(r, g):
        v_tension = ca.fmax(0.0, -ca.mmin(g[:rows]))
        v_bounds = ca.fmax(0.0, -ca.mmin(g[rows:]))
        return 0.5 * ca.dot(r, r) + k["tension_slack"] * v_tension + k["slack"] * v_bounds

    args = [nu, y, u, u_prev, ref, par, h, c]
    names = ["nu", "y", "u", "u_prev", "ref", "par", "h", "c"]
    finite = ca.sum1(ca.fabs(z)) < math.inf  # False for inf and NaN
    options = {"cse": n <= 2}
    merit = ca.Function("merit", args, [ca.if_else(finite, merit_of(r, g), math.inf)],
                        names, ["merit"], options)
    jac = ca.jacobian(ca.vertcat(r, g_raw), u)
    ok = ca.logic_and(finite, ca.sum1(ca.sum2(ca.fabs(jac))) < math.inf)
    jr, jg = jac[:r.numel(), :], jac[r.numel():, :]
    outs = [ok, ca.if_else(ok, merit_of(r, g), math.inf)]
    outs += [ca.if_else(ok, x, ca.SX.zeros(x.sparsity())) for x in (r, jr, g, jg)]
    linearised = ca.Function("linearised", args, outs, names,
                             ["ok", "merit", "r", "J", "g", "G"], options)
    _FUNCTIONS[key] = (merit, linearised)
    return _FUNCTIONS[key]


def _sqp_step_function(linearised, qp, n_moves: int, rows: int):
    """``sqp(nu, y, u, u_prev, ref, par, h, c) -> (ok, merit, x)``: one Gauss-Newton QP.

    Linearises at u and solves the condensed QP (module docstring) inside CasADi: x =
    (du (n_moves,), the two slacks); the QP's matrices never leave CasADi (its own
    sparse products, no BLAS). ``qp`` is the controller's own DAQP solver.
    """
    ca = mpc_model.casadi()
    ins = [ca.MX.sym(linearised.name_in(i), linearised.sparsity_in(i))
           for i in range(linearised.n_in())]
    ok, merit, r, J, g, G = linearised(*ins)
    c = ins[-1]
    prices = ca.vertcat(c[CONSTANTS.index("tension_slack")], c[CONSTANTS.index("slack")])
    H = ca.diagcat(ca.mtimes(J.T, J) + 1e-12 * ca.DM.eye(n_moves), ca.diag(prices))
    grad = ca.vertcat(ca.mtimes(J.T, r), prices)
    total = g.numel()
    tension = ca.DM([1.0] * rows + [0.0] * (total - rows))
    A = ca.horzcat(G, tension, 1.0 - tension)
    u = ins[2]
    sol = qp(h=H, g=grad, a=A, lba=-g, uba=ca.DM.inf(total),
             lbx=ca.vertcat(-1.0 - u, 0.0, 0.0), ubx=ca.vertcat(1.0 - u, math.inf, math.inf))
    return ca.Function("sqp", ins, [ok, merit, sol["x"]],
                       [linearised.name_in(i) for i in range(linearised.n_in())],
                       ["ok", "merit", "x"])


def _diagnostics_function(n: int, substeps: int, full: bool, blocks: tuple[int, ...]):
    """``plan(nu, y, U, par, h)``: what :class:`Plan` holds, substep by substep (cached)."""
    key = ("plan", n, substeps, full, blocks)
    if key in _FUNCTIONS:
        return _FUNCTIONS[key]
    ca = mpc_model.casadi()
    nu, y, U, par, h = _symbols(ca, n, len(blocks))
    rhs = mpc_model.rhs_function(n, full)
    zero = ca.SX.zeros(n)
    th, dth, ten, ln, stop, ddl, nodes = [], [], [], [], [], [], []
    for t, state, bounds, i in _rollout(ca, nu, y, U, par, h, (n, substeps, full, blocks),
                                        True):
        for tb, yb in bounds:
            dy, tension = rhs(tb, yb, U[:, i], zero, par)
            ten.append(tension)
            ddl.append(dy[3 * n:])
            nodes.append(tb)
        th.append(state[:n])
        dth.append(state[n:2 * n])
        ln.append(state[2 * n:3 * n])
        stop.append(_stop_length(ca, t, state, par, n))
    z = ca.vertcat(*th, *dth, *ten, *ln, *stop, *ddl, *nodes)
    _FUNCTIONS[key] = ca.Function("plan", [nu, y, U, par, h], [z])
    return _FUNCTIONS[key]


class ModelPredictiveController(OnNominalStep, ReelRatePolicy):
    """Nonlinear MPC of the reel rates on the nominal model (module docstring).

    Parameters
    ----------
    step : NominalStep
        The nominal model's control step (e, masses, reel limits, steps, T_safe).
    layout : ObservationLayout
        How to read the env's observation (rate mode).
    blocks : sequence of int
        Move blocking: move b of the plan is held for ``blocks[b]`` control steps (each
        >= 1); the horizon is M = sum(blocks) control steps (default
        :data:`DEFAULT_BLOCKS`); at most :data:`MAX_MOVES` moves and
        :data:`MAX_HORIZON` steps.
    iterations : int
        Gauss-Newton SQP iterations per control step, 1 ... :data:`MAX_ITERATIONS`
        (default 2).
    weights : dict or None
        ``rate`` (theta' error) [-], ``terminal`` (factor on the last step) [-], ``tail``
        (factor on the steps of the blocks longer than one step) [-], ``move``
        (|u_b - u_{b-1}|^2) [rad^2], ``tension_slack`` (price of a violation of T^ >=
        T_safe) [rad^2] and ``slack`` (price of a violation of a failure bound) [rad^2];
        see :data:`DEFAULT_WEIGHTS`. The first four in [0, 1e6], the prices in (0, 1e12].
    margins : dict or None
        ``libration`` [rad] kept from pi/2, ``length`` [-] kept from each length bound
        and ``tension_floor`` [-], the smallest T^ allowed when T_safe cannot be kept;
        see :data:`DEFAULT_MARGINS`. ``libration`` in [0, pi/2), ``length`` in [0, half
        the length range), ``tension_floor`` in [0, max(T_safe, 0.05)].

    Raises
    ------
    TypeError, ValueError
        Before anything is built, for an argument of the wrong type or outside its range
        (the message names the value and the range); a nominal e above
        :data:`SUPPORTED_ECCENTRICITY` or more than :data:`SUPPORTED_TETHERS` tethers
        warn (UserWarning).

    Notes
    -----
    One object plans one episode at a time (its warm start is the last plan); build one
    per episode (the registry does) or call :meth:`reset`. Batches are planned row by
    row, each row from its own previous plan. ``solve_times`` lists the wall time [s]
    (``time.perf_counter``) of every plan; ``last_slack`` is the QP's slack of the last
    one [-] (0: every linearised constraint holds; inf: the prediction diverged and the
    held command was sent again).
    """

    DEFAULT_BLOCKS = (1,) * 10 + (2, 2, 4, 4, 8)
    """Ten moves of one control step, then five longer ones: 30 control steps (0.75 rad
    at the default step) for 15 moves."""
    DEFAULT_WEIGHTS = {"rate": 0.1, "terminal": 1.0, "tail": 0.01, "move": 1e-5,
                       "tension_slack": 10.0, "slack": 1e4}
    """Cost weights (the tracking weight on theta is 1 [1/rad^2]; do not modify: pass
    ``weights``)."""
    DEFAULT_MARGINS = {"libration": 0.05, "length": 0.0, "tension_floor": 0.05}
    """Distances kept from the tumble angle [rad] and the length bounds [-], and the
    tension floor [-] kept when T_safe cannot be."""
    batch_invariant = False

    def __init__(self, step: NominalStep, layout: ObservationLayout,
                 blocks: tuple[int, ...] | None = None,
                 iterations: int = 2, weights: dict | None = None,
                 margins: dict | None = None):
        ca = mpc_model.casadi()  # first: a missing CasADi names its pip command
        if step.n_tethers != layout.n_tethers:
            raise ValueError(f"model has {step.n_tethers} tethers, the env {layout.n_tethers}")
        layout.require_rate_mode(type(self).__name__)
        _check_step(step)
        self.step = step
        self.layout = layout
        self.weights = _merged("weights", self.DEFAULT_WEIGHTS, weights, _WEIGHT_RANGES)
        self.margins = _merged("margins", self.DEFAULT_MARGINS, margins,
                               _margin_ranges(step))
        self.blocks = _checked_blocks(self.DEFAULT_BLOCKS if blocks is None else blocks)
        self.horizon = sum(self.blocks)
        self.moves = len(self.blocks)
        self.iterations = _count("iterations", iterations, MAX_ITERATIONS)
        _warn_beyond_reach(step)
        stage_weights = np.array([1.0 if self.blocks[i] == 1 else self.weights["tail"]
                                  for i in _step_blocks(self.blocks)])
        stage_weights[-1] *= self.weights["terminal"]
        constants = {"max_reel_rate": step.max_reel_rate, "rate": self.weights["rate"],
                     "move": self.weights["move"], "safe_tension": step.safe_tension,
                     "tension_floor": self.margins["tension_floor"],
                     "libration_bound": TUMBLE_ANGLE - self.margins["libration"],
                     "length_low": step.length_bounds[0] + self.margins["length"],
                     "length_high": step.length_bounds[1] - self.margins["length"],
                     "accel_bound": step.accel_bound,
                     "tension_slack": self.weights["tension_slack"],
                     "slack": self.weights["slack"]}
        self._constants = np.concatenate([[constants[name] for name in CONSTANTS],
                                          stage_weights])
        self._merit_function, linearised = _solver_functions(
            step.n_tethers, step.substeps, step.full_gravity, self.blocks)
        nv = self.moves * step.n_tethers + 2
        nc = self._constraint_count()
        # one QP solver per controller (per episode), as one plan per episode
        qp = ca.conic("mpc_qp", "daqp", {"h": ca.Sparsity.dense(nv, nv),
                                         "a": ca.Sparsity.dense(nc, nv)},
                      {"error_on_fail": False})
        self._sqp = _sqp_step_function(linearised, qp, nv - 2, self._tension_rows)
        self.plans: list[np.ndarray | None] = []
        self.solve_times: list[float] = []
        self.last_slack = math.nan

    @classmethod
    def for_env(cls, env, nominal: dict | None = None, **kwargs) -> ModelPredictiveController:
        """Build for a TetherLibration env, on its model or on ``nominal``.

        ``nominal`` holds the :class:`~.prediction.NominalStep` arguments that differ
        from the env's (a scenario's ``nominal``: ``eccentricity`` in [0, 1),
        ``masses`` (n_tethers values > 0), ``reel_time_constant`` [rad] > 0,
        ``accel_limit`` [m/s^2] > 0); each is checked before anything is built.
        """
        _check_nominal(nominal, env)
        return super().for_env(env, nominal, **kwargs)

    def reset(self) -> None:
        """Forget the warm starts (a new episode)."""
        self.plans = []

    def __repr__(self) -> str:
        return (f"ModelPredictiveController(blocks={self.blocks}, "
                f"iterations={self.iterations}, weights={self.weights})")

    # ------------------------------------------------------------------ #
    def _constraint_count(self) -> int:
        m, n, sub = self.horizon, self.step.n_tethers, self.step.substeps
        return m * n * 2 + 2 * m * (sub + 1) * n + 4 * m * n + 2 * self.moves * n

    @property
    def _tension_rows(self) -> int:
        return self.horizon * (self.step.substeps + 1) * self.step.n_tethers

    def predicted(self, nu: float, y: np.ndarray, command: np.ndarray) -> Plan:
        """The nominal prediction of a plan: moves (len(blocks), n) normalised, from (nu, y)."""
        U = np.clip(np.asarray(command, dtype=float), -1.0, 1.0) * self.step.max_reel_rate
        plan = _diagnostics_function(self.step.n_tethers, self.step.substeps,
                                     self.step.full_gravity, self.blocks)
        z = plan(nu, y, U.T, self.step.params, self.step.physics_step)
        return Plan(np.asarray(z), self.horizon, self.step.n_tethers, self.step.substeps)

    def _args(self, nu, y, U, u_prev, ref) -> tuple:
        return (nu, y, U.ravel(), u_prev, ref, self.step.params, self.step.physics_step,
                self._constants)

    def _linearised_step(self, args) -> tuple[bool, float, np.ndarray, float]:
        """(ok, merit at the plan, the QP's step dU (moves, n), slack) at ``args``."""
        ok_flag, merit, x = self._sqp(*args)
        ok = float(ok_flag) > 0.5
        x = np.asarray(x).ravel()
        nv = self.moves * self.step.n_tethers
        if not np.all(np.isfinite(x)):  # the QP failed: no step
            return ok, float(merit), np.zeros((self.moves, self.step.n_tethers)), math.inf
        return (ok, float(merit), x[:nv].reshape(self.moves, self.step.n_tethers),
                float(x[nv:].max()))

    def plan(self, nu: float, y: np.ndarray, u_prev: np.ndarray, ref, warm=None):
        """The plan U (len(blocks), n) [-] from one state: ``iterations`` SQP steps.

        ``ref`` = (theta_d, theta_d') over the M planned steps; ``u_prev`` the held
        command; ``warm`` the initial plan (None: the held command throughout).
        """
        u_prev = np.asarray(u_prev, dtype=float)
        ref = np.concatenate([np.asarray(ref[0], dtype=float).ravel(),
                              np.asarray(ref[1], dtype=float).ravel()])
        held = np.repeat(u_prev[None], self.moves, axis=0)
        U = np.clip(held if warm is None else np.array(warm, dtype=float), -1.0, 1.0)
        ok, merit, dU, slack = self._linearised_step(self._args(nu, y, U, u_prev, ref))
        if not ok and warm is not None:  # a diverged warm start
            U = np.clip(held, -1.0, 1.0)
            ok, merit, dU, slack = self._linearised_step(self._args(nu, y, U, u_prev, ref))
        if not ok:  # the prediction itself diverges: hold the command
            self.last_slack = math.inf
            return U
        for it in range(self.iterations):
            alpha, accepted = 1.0, False
            for _ in range(4):  # backtracking on the merit
                cand = np.clip(U + alpha * dU, -1.0, 1.0)
                mc = float(self._merit_function(*self._args(nu, y, cand, u_prev, ref)))
                if mc <= merit * (1.0 + 1e-9):
                    accepted = True
                    break
                alpha *= 0.5
            if not accepted:
                break
            U, merit = cand, mc
            if alpha == 1.0 and slack == 0.0 and np.abs(dU[0]).max() < CONVERGED:
                break  # a full, feasible step that left the move to send as it was
            if it + 1 < self.iterations:
                ok, _, dU_next, slack_next = self._linearised_step(
                    self._args(nu, y, U, u_prev, ref))
                if not ok:
                    break
                dU, slack = dU_next, slack_next
        self.last_slack = slack
        return U

    def reel_rate(self, obs: np.ndarray) -> np.ndarray:
        """Commanded l' [-] (B, n): the first step of each row's plan.

        Raises ValueError, before any planning, when an observation is not finite.
        """
        lay = self.layout
        finite = np.isfinite(obs)
        if not finite.all():
            row = int(np.flatnonzero(~finite.all(axis=1))[0])
            cols = np.flatnonzero(~finite[row]).tolist()
            raise ValueError(f"mpc: observation row {row} has non-finite entries at indices "
                             f"{cols} ({obs[row, cols].tolist()}); every entry must be finite")
        st = lay.split(obs)
        nu, y = lay.state(obs)
        delta = self.step.control_step * np.arange(1, self.horizon + 1)
        out = np.empty((obs.shape[0], lay.n_tethers))
        if len(self.plans) != obs.shape[0]:
            self.plans = [None] * obs.shape[0]
        for b in range(obs.shape[0]):
            t0 = time.perf_counter()
            ref = reference_ahead(st.theta_ref[b], st.dtheta_ref[b], lay.frequency, delta)
            u_prev = np.clip(st.command[b], -1.0, 1.0)
            prev = self.plans[b]
            warm = None if prev is None else np.vstack([prev[1:], prev[-1:]])
            U = self.plan(float(nu[b]), y[b], u_prev, ref, warm)
            self.plans[b] = U
            out[b] = U[0] * self.step.max_reel_rate
            self.solve_times.append(time.perf_counter() - t0)
        return out

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        """stable-baselines3 interface; a True ``episode_start`` forgets the warm start."""
        if episode_start is not None and np.any(episode_start):
            self.reset()
        return super().predict(observation, state, episode_start, deterministic)


def _count(name: str, value, high: int) -> int:
    """``value`` checked to be an int in [1, ``high``]."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an int in [1, {high}], got "
                        f"{type(value).__name__} {value!r}")
    if not 1 <= value <= high:
        raise ValueError(f"{name}={value!r} is outside the valid range [1, {high}]")
    return int(value)


def _checked_blocks(blocks) -> tuple[int, ...]:
    """Move blocking checked: a sequence of 1 ... MAX_MOVES ints >= 1 summing to <= MAX_HORIZON."""
    if isinstance(blocks, (str, bytes, Mapping)) or not isinstance(blocks, Iterable):
        raise TypeError(f"blocks must be a sequence of ints >= 1 (the control steps each move "
                        f"is held), e.g. {ModelPredictiveController.DEFAULT_BLOCKS}; got "
                        f"{type(blocks).__name__} {blocks!r}")
    blocks = tuple(blocks)
    if not 1 <= len(blocks) <= MAX_MOVES:
        raise ValueError(f"blocks holds {len(blocks)} moves; valid: 1 ... {MAX_MOVES} (the "
                         f"default holds {len(ModelPredictiveController.DEFAULT_BLOCKS)})")
    out = tuple(_count(f"blocks[{i}]", b, MAX_HORIZON) for i, b in enumerate(blocks))
    if sum(out) > MAX_HORIZON:
        raise ValueError(f"blocks={out} plans {sum(out)} control steps; valid: at most "
                         f"{MAX_HORIZON} (the default plans "
                         f"{sum(ModelPredictiveController.DEFAULT_BLOCKS)})")
    return out


_WEIGHT_RANGES = {"rate": (0.0, 1e6, False, False), "terminal": (0.0, 1e6, False, False),
                  "tail": (0.0, 1e6, False, False), "move": (0.0, 1e6, False, False),
                  "tension_slack": (0.0, 1e12, True, False), "slack": (0.0, 1e12, True, False)}
"""(low, high, low_open, high_open) of each weight: the slack prices must be > 0 (the
QP's slacks are then bounded), the others >= 0."""


def _margin_ranges(step: NominalStep) -> dict:
    """(low, high, low_open, high_open) of each margin for ``step``'s bounds."""
    lo, hi = step.length_bounds
    half = 0.5 * (hi - lo) if math.isfinite(hi - lo) else 1e9
    floor = max(step.safe_tension, ModelPredictiveController.DEFAULT_MARGINS["tension_floor"])
    return {"libration": (0.0, TUMBLE_ANGLE, False, True), "length": (0.0, half, False, True),
            "tension_floor": (0.0, floor, False, False)}


def _merged(name: str, defaults: dict, given, ranges: dict) -> dict:
    """``defaults`` updated with ``given``, each value checked against ``ranges[key]``.

    Raises TypeError when ``given`` is not a dict (or None) or a value not a real number,
    ValueError for an unknown key (listing the valid ones) or a value out of its range.
    """
    if given is None:
        given = {}
    if not isinstance(given, Mapping):
        raise TypeError(f"{name} must be a dict with keys from {sorted(defaults)} (or None), "
                        f"got {type(given).__name__} {given!r}")
    unknown = sorted(str(k) for k in set(given) - set(defaults))
    if unknown:
        raise ValueError(f"unknown {name} {unknown}; valid: {sorted(defaults)}")
    out = {**defaults, **given}
    for key, value in out.items():
        low, high, low_open, high_open = ranges[key]
        out[key] = check_range(f"{name}[{key!r}]", value, low, high, low_open=low_open,
                               high_open=high_open)
    return out


def _check_step(step: NominalStep) -> None:
    """The nominal model's eccentricity in [0, 1) and masses > 0 (a NominalStep built by hand)."""
    sl = PARAMS.slices(step.n_tethers)
    ecc = float(step.params[sl["eccentricity"]][0])
    check_range("the nominal model's eccentricity", ecc, 0.0, 1.0, high_open=True)
    tail = step.params[sl["tail_mass"]]
    if not (np.all(np.isfinite(tail)) and np.all(tail > 0.0)):
        raise ValueError(f"the nominal model's masses must be finite and > 0 (tail masses "
                         f"{tail.tolist()})")


def _check_nominal(nominal, env) -> None:
    """A scenario's ``nominal`` dict checked before any model is built (ValueError/TypeError)."""
    if nominal is None:
        return
    if not isinstance(nominal, Mapping):
        raise TypeError(f"nominal must be a dict with keys from {list(_NOMINAL)} (or None), "
                        f"got {type(nominal).__name__} {nominal!r}")
    unknown = sorted(str(k) for k in set(nominal) - set(_NOMINAL))
    if unknown:
        raise ValueError(f"unknown nominal {unknown}; valid: {list(_NOMINAL)}")
    n = env.unwrapped.config.n_tethers
    for key, value in nominal.items():
        if value is None:
            continue
        if key == "masses":
            try:
                check_masses(value, n)
            except (TypeError, ValueError) as exc:
                raise type(exc)(f"nominal masses for {n} tethers: {exc}") from None
        elif key == "eccentricity":
            check_range("nominal eccentricity", value, 0.0, 1.0, high_open=True)
        else:
            check_range(f"nominal {key}", value, 0.0, low_open=True)


_NOMINAL = ("eccentricity", "masses", "reel_time_constant", "accel_limit")
"""The keys of a nominal model (:data:`~tether_gym_agents.evaluation.scenarios.NOMINAL_KEYS`):
e in [0, 1), masses > 0, tau [rad] > 0 and the acceleration limit [m/s^2] > 0."""


def _warn_beyond_reach(step: NominalStep) -> None:
    """A UserWarning where mpc runs but is beyond what it was built and checked for."""
    ecc = float(step.params[PARAMS.slices(step.n_tethers)["eccentricity"]][0])
    if ecc > SUPPORTED_ECCENTRICITY:
        warnings.warn(f"mpc: nominal eccentricity {ecc} is beyond the {SUPPORTED_ECCENTRICITY} "
                      "it was checked on (module docstring, 'Reach'); expect failures",
                      UserWarning, stacklevel=3)
    if step.n_tethers > SUPPORTED_TETHERS:
        warnings.warn(f"mpc: {step.n_tethers} tethers (N = {step.n_tethers + 1} bodies) is "
                      f"beyond the {SUPPORTED_TETHERS} it was checked on (module docstring, "
                      "'Reach'): building and every control step take much longer",
                      UserWarning, stacklevel=3)
