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
"""

from __future__ import annotations

import math
import time

import numpy as np

from tether_gym.params import check_range
from tether_gym.tasks.termination import TUMBLE_ANGLE

from ..common.obs import ObservationLayout, ReelRatePolicy
from . import mpc_model
from .prediction import NominalStep, OnNominalStep, reference_ahead

__all__ = ["ModelPredictiveController", "Plan"]

_FUNCTIONS: dict[tuple, tuple] = {}
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
    from tether_gym.physics import PARAMS

    return (ca.SX.sym("nu"), ca.SX.sym("y", 4 * n), ca.SX.sym("U", n, m),
            ca.SX.sym("par", PARAMS.size(n)), ca.SX.sym("h"))


def _horizon_functions(n: int, substeps: int, full: bool, blocks: tuple[int, ...]):
    """(values(nu, y, U, par, h), linearise(...) -> (values, d values / d U)), cached.

    ``values`` stacks, over the M = sum(blocks) planned steps, theta, theta', the
    tensions at every substep boundary, l and l_stop at the step's end; U is (n,
    len(blocks)) in l'_cmd [-], move b held for blocks[b] control steps.
    """
    key = ("solve", n, substeps, full, blocks)
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
    values = ca.Function("values", [nu, y, U, par, h], [z])
    linearise = ca.Function("linearise", [nu, y, U, par, h], [z, ca.jacobian(z, ca.vec(U))])
    _FUNCTIONS[key] = (values, linearise)
    return _FUNCTIONS[key]


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
    blocks : tuple of int
        Move blocking: move b of the plan is held for ``blocks[b]`` control steps (each
        >= 1); the horizon is M = sum(blocks) control steps (default
        :data:`DEFAULT_BLOCKS`).
    iterations : int
        Gauss-Newton SQP iterations per control step, >= 1 (default 2).
    weights : dict or None
        ``rate`` (theta' error) [-], ``terminal`` (factor on the last step) [-], ``tail``
        (factor on the steps of the blocks longer than one step) [-], ``move``
        (|u_b - u_{b-1}|^2) [rad^2], ``tension_slack`` (price of a violation of T^ >=
        T_safe) [rad^2] and ``slack`` (price of a violation of a failure bound) [rad^2];
        see :data:`DEFAULT_WEIGHTS`.
    margins : dict or None
        ``libration`` [rad] kept from pi/2, ``length`` [-] kept from each length bound
        and ``tension_floor`` [-], the smallest T^ allowed when T_safe cannot be kept;
        see :data:`DEFAULT_MARGINS`.

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
        self.step = step
        self.layout = layout
        self.weights = _merged("weights", self.DEFAULT_WEIGHTS, weights)
        self.margins = _merged("margins", self.DEFAULT_MARGINS, margins)
        blocks = self.DEFAULT_BLOCKS if blocks is None else tuple(blocks)
        if not blocks:
            raise ValueError("blocks must hold at least one block length")
        self.blocks = tuple(_count("blocks[i]", b) for b in blocks)
        self.horizon = sum(self.blocks)
        self.moves = len(self.blocks)
        self._stage_weights = np.array([1.0 if self.blocks[i] == 1 else self.weights["tail"]
                                        for i in _step_blocks(self.blocks)])
        self._stage_weights[-1] *= self.weights["terminal"]
        self.iterations = _count("iterations", iterations)
        self._values, self._linearise = _horizon_functions(
            step.n_tethers, step.substeps, step.full_gravity, self.blocks)
        nv = self.moves * step.n_tethers + 2
        nc = self._constraint_count()
        self._qp = ca.conic("mpc_qp", "daqp", {"h": ca.Sparsity.dense(nv, nv),
                                               "a": ca.Sparsity.dense(nc, nv)},
                            {"error_on_fail": False})
        self.plans: list[np.ndarray | None] = []
        self.solve_times: list[float] = []
        self.last_slack = math.nan

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

    def predicted(self, nu: float, y: np.ndarray, command: np.ndarray) -> Plan:
        """The nominal prediction of a plan: moves (len(blocks), n) normalised, from (nu, y)."""
        U = np.clip(np.asarray(command, dtype=float), -1.0, 1.0) * self.step.max_reel_rate
        plan = _diagnostics_function(self.step.n_tethers, self.step.substeps,
                                     self.step.full_gravity, self.blocks)
        z = plan(nu, y, U.T, self.step.params, self.step.physics_step)
        return Plan(np.asarray(z), self.horizon, self.step.n_tethers, self.step.substeps)

    def _split(self, z):
        m, n, sub = self.horizon, self.step.n_tethers, self.step.substeps
        sizes = [m * n, m * n, m * (sub + 1) * n, m * n, m * n, self.moves * n]
        return np.split(z, np.cumsum(sizes)[:-1])

    def _constraints(self, z, jz):
        """g(U) >= 0 (C,) and dg/dU (C, M n) from the stacked values and their Jacobian."""
        th, _, ten, ln, stop, demand = self._split(z)
        jth, _, jten, jln, jstop, jdemand = self._split(jz)
        a_bound = self.step.accel_bound
        bound = TUMBLE_ANGLE - self.margins["libration"]
        lo = self.step.length_bounds[0] + self.margins["length"]
        hi = self.step.length_bounds[1] - self.margins["length"]
        # the tension rows T^ >= T_safe first (their own slack), then the bounds that end
        # an episode: tension floor, tumbling, lengths, and the reels' acceleration
        g = np.concatenate([ten - self.step.safe_tension, ten - self.margins["tension_floor"],
                            bound - th, bound + th, ln - lo, hi - ln, stop - lo, hi - stop,
                            a_bound - demand, a_bound + demand])
        G = np.concatenate([jten, jten, -jth, jth, jln, -jln, jstop, -jstop, -jdemand,
                            jdemand])
        g = np.minimum(g, 1e9)  # a missing limit (inf) is a row that never binds
        return g, G

    @property
    def _tension_rows(self) -> int:
        return self.horizon * (self.step.substeps + 1) * self.step.n_tethers

    def _violations(self, g) -> tuple[float, float]:
        """(largest violation of T^ >= T_safe, of the other constraints) [-], >= 0."""
        k = self._tension_rows
        return max(0.0, float(-g[:k].min())), max(0.0, float(-g[k:].min()))

    def _residuals(self, z, jz, U, u_prev, ref):
        """Weighted residuals r (R,) and dr/dU (R, M n) of the cost (module docstring)."""
        n, moves = self.step.n_tethers, self.moves
        th, dth = self._split(z)[:2]
        jth, jdth = self._split(jz)[:2]
        w = self._stage_weights
        sw = np.repeat(np.sqrt(w), n)
        rate = math.sqrt(self.weights["rate"])
        e = sw * (th - np.repeat(ref[0], n))
        ed = rate * sw * (dth - np.repeat(ref[1], n))
        move = math.sqrt(self.weights["move"])
        # u in l'_cmd [-] over max_reel_rate: differences of the normalised plan
        du = (U - np.vstack([u_prev[None], U[:-1]])).ravel()
        dmat = np.eye(moves * n) - np.eye(moves * n, k=-n)
        r = np.concatenate([e, ed, move * du])
        J = np.vstack([sw[:, None] * jth, rate * sw[:, None] * jdth, move * dmat])
        return r, J

    def _merit(self, r, g) -> float:
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(g))):
            return math.inf
        v_tension, v_bounds = self._violations(g)
        return (0.5 * float(r @ r) + self.weights["tension_slack"] * v_tension
                + self.weights["slack"] * v_bounds)

    def _evaluate(self, nu, y, U, u_prev, ref, jacobian: bool):
        rate = self.step.max_reel_rate
        args = (nu, y, (U * rate).T, self.step.params, self.step.physics_step)
        if jacobian:
            z, jz = self._linearise(*args)
            z = np.asarray(z).ravel()
            jz = np.asarray(jz) * rate
        else:
            z = np.asarray(self._values(*args)).ravel()
            jz = np.zeros((z.size, U.size))
        r, J = self._residuals(z, jz, U, u_prev, ref)
        g, G = self._constraints(z, jz)
        return r, J, g, G

    def _qp_step(self, U, r, J, g, G):
        """The Gauss-Newton QP: (dU (M, n), slack) (module docstring)."""
        nv = U.size
        prices = np.array([self.weights["tension_slack"], self.weights["slack"]])
        H = np.zeros((nv + 2, nv + 2))
        H[:nv, :nv] = J.T @ J + 1e-12 * np.eye(nv)
        H[nv:, nv:] = np.diag(prices)
        grad = np.concatenate([J.T @ r, prices])
        k = self._tension_rows
        rows = G.shape[0]
        A = np.hstack([G, np.zeros((rows, 2))])
        A[:k, nv] = 1.0
        A[k:, nv + 1] = 1.0
        u = U.ravel()
        sol = self._qp(h=H, g=grad, a=A, lba=-g, uba=np.full(g.size, np.inf),
                       lbx=np.concatenate([-1.0 - u, [0.0, 0.0]]),
                       ubx=np.concatenate([1.0 - u, [np.inf, np.inf]]))
        x = np.asarray(sol["x"]).ravel()
        if not np.all(np.isfinite(x)):
            return np.zeros_like(U), math.inf
        return x[:nv].reshape(U.shape), float(x[nv:].max())

    def plan(self, nu: float, y: np.ndarray, u_prev: np.ndarray, ref, warm=None):
        """The plan U (len(blocks), n) [-] from one state: ``iterations`` SQP steps.

        ``ref`` = (theta_d, theta_d') over the M planned steps; ``u_prev`` the held
        command; ``warm`` the initial plan (None: the held command throughout).
        """
        U = (np.repeat(u_prev[None], self.moves, axis=0) if warm is None
             else np.array(warm, dtype=float))
        U = np.clip(U, -1.0, 1.0)
        r, J, g, G = self._evaluate(nu, y, U, u_prev, ref, True)
        if not _finite(r, J, g, G) and warm is not None:  # a diverged warm start
            U = np.repeat(u_prev[None], self.moves, axis=0)
            r, J, g, G = self._evaluate(nu, y, U, u_prev, ref, True)
        if not _finite(r, J, g, G):  # the prediction itself diverges: hold the command
            self.last_slack = math.inf
            return U
        merit = self._merit(r, g)
        slack = math.nan
        for it in range(self.iterations):
            dU, slack = self._qp_step(U, r, J, g, G)
            alpha, accepted = 1.0, False
            for _ in range(4):  # backtracking on the merit
                cand = np.clip(U + alpha * dU, -1.0, 1.0)
                rc, _, gc, _ = self._evaluate(nu, y, cand, u_prev, ref, False)
                mc = self._merit(rc, gc)
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
                r, J, g, G = self._evaluate(nu, y, U, u_prev, ref, True)
                if not _finite(r, J, g, G):
                    break
        self.last_slack = slack
        return U

    def reel_rate(self, obs: np.ndarray) -> np.ndarray:
        """Commanded l' [-] (B, n): the first step of each row's plan."""
        lay = self.layout
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


def _finite(*arrays) -> bool:
    return all(bool(np.all(np.isfinite(a))) for a in arrays)


def _count(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{name}={value!r} must be an int >= 1")
    return value


def _merged(name: str, defaults: dict, given: dict | None) -> dict:
    """``defaults`` updated with ``given``; unknown keys raise ValueError listing the valid."""
    given = dict(given or {})
    unknown = sorted(set(given) - set(defaults))
    if unknown:
        raise ValueError(f"unknown {name} {unknown}; valid: {sorted(defaults)}")
    out = {**defaults, **given}
    for key, value in out.items():
        check_range(f"{name}[{key!r}]", value, 0.0)
    return out
