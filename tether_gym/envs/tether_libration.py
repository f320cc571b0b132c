"""The Gymnasium environment ``tether_gym/TetherLibration-v2``."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from ..physics import TetherChain
from ..physics.layout import at
from ..physics.state import P
from .batch import ChainBatch
from .config import EnvConfig
from .layout import INFO, OBSERVATION, markdown_table, observation_bounds

__all__ = ["TetherLibrationEnv"]


def observation_space(config: EnvConfig) -> spaces.Box:
    """Box of the observation layout (:data:`tether_gym.envs.layout.OBSERVATION`)."""
    low, high = observation_bounds(config.n_tethers, config.observed)
    return spaces.Box(low, high, dtype=np.float32)


def eccentricity_of(batch: ChainBatch, b: int) -> float:
    """e of row b (it is drawn per episode when randomised)."""
    return float(batch.par[b, at(P.eccentricity, batch.n)])


def action_space(config: EnvConfig) -> spaces.Box:
    return spaces.Box(-1.0, 1.0, (config.n_tethers,), dtype=np.float32)


def check_action(action, out: np.ndarray) -> np.ndarray:
    """Copy the action into ``out``, a float64 (1, n) buffer, and return ``out``.

    Raises TypeError for anything but real numbers and ValueError for a shape other than
    (n,); NaN and inf are rejected by the step itself, before it changes anything.
    """
    raw = np.asarray(action)
    if raw.dtype.kind not in "iuf":
        raise TypeError(f"action={action!r} must hold real numbers (no bools or complex), "
                        f"got dtype {raw.dtype}")
    if raw.shape != out.shape[1:]:
        raise ValueError(f"action must have shape {out.shape[1:]}, got {raw.shape}: "
                         f"{action!r}")
    out[0] = raw
    return out


class TetherLibrationEnv(gym.Env):
    r"""Libration tracking of a tethered multi-satellite chain on an elliptic orbit.

    ## Description

    A heavy main satellite follows a Keplerian ellipse; N-1 subsatellites hang below
    it in a chain of massless tethers whose lengths are reeled in and out (Shi, Zhu &
    Zhu, Aerospace Science and Technology 91 (2019) 41-48). The orbit's changing
    gravity gradient and the Coriolis force of reeling drive the librations. The agent
    commands the reel rates so that every libration angle tracks
    theta_d = A sin(w nu) (the paper's Sec. 4; A = 0 is the zero state of Sec. 3.1)
    while every tether stays taut and within its length bounds. The independent
    variable is the true anomaly nu [rad]; one control step advances nu by
    ``control_step``. Angles: theta_i [rad] from the local vertical (pointing to
    Earth) to tether i, positive when the lower body trails the upper one (paper
    Eq. 1). Lengths are l_i = L_i / L0 [-]; primes are d/dnu.

    The defaults reproduce the paper's Sec. 4.3 case: Table 1 (N = 3, M1/M2 = 0.5,
    l(0) = (0.5, 0.5), e = 0.2, p = 8520 km), L0 = 20 km, a reel acceleration limit of
    0.01 m/s^2 per tether, theta(0) = (0.1, 0), theta'(0) = A w = 0.2.

    ## Action Space

    ``Box(-1, 1, (N-1,), float32)``, clipped to [-1, 1]. It sets the normalised
    reel-rate command u in [-1, 1]^(N-1), which maps to l'_cmd,i = u_i *
    ``max_reel_rate`` [-]:

    * ``action_mode="increment"`` (default): the action is a change of the command,
      u_i <- clip(u_i + ``increment_gain`` * action_i, -1, 1) (gain 0.25). At reset u
      is the reels' rate, clip(l'/``max_reel_rate``, -1, 1).
    * ``action_mode="rate"``: the action is the command, u_i = action_i (v0's action,
      and the paper's control input; the sliding-mode baseline runs in this mode).

    The reels follow l'_cmd as a first-order lag (``reel_time_constant``) saturated at
    the physical acceleration limit ``accel_limit``. A NaN or inf action raises
    ValueError.

    | Index | Action ("increment" / "rate")                 | Min | Max |
    |-------|-----------------------------------------------|-----|-----|
    | i     | change of u_i / reel-rate command u_i         | -1  | 1   |

    ## Observation Space

    ``Box(float32)`` of size 8(N-1) + 4, plus 1 with e observed and N - 1 more with the
    mass fractions (``observe_params``: True both, ``"eccentricity"`` e alone; by
    default both exactly when they are randomised):

    {observation_table}

    (n = N-1.) With the frequency w known, (nu, theta, theta', l, l', u) is the full
    state, so the observation is Markov. ``obs_noise`` adds Gaussian noise of that
    standard deviation to the theta, theta', l and l' entries (and so to the errors
    and ln l computed from them); ``obs_bias`` adds a constant offset to every
    observed theta_i (a misaligned sensor). ``info`` holds the true state.

    ## Rewards

    With e_i = theta_i - theta_d, e_i' = theta_i' - theta_d', the cost c = mean(e_i^2)
    + 0.1 mean(e_i'^2), the command u and the weights of ``reward_weights``
    (defaults in brackets):

        r = (1 - W) r_track (1 - p) + w_slack (1 - q_slack) + w_length (1 - q_length),
        W = w_slack + w_length,
        r_track = (1 - s) / (1 + c / sigma^2) + s clip(ln(sqrt(c)) / ln(1e-4), 0, 1)
                                                  [s = log_share 0.5, sigma 0.05 rad]
        p = w_effort mean(u_i^2) + w_accel mean(min(1, (L_ddot_i / a_ref)^2))  [0.05, 0]
        q_slack  = mean(clip(1 - T^_i,min / T_safe, 0, 1)^2)         [w 0.2, T_safe 0.5]
        q_length = mean(min(1, h(ln(l_i / l_i,nom)) / h(ln 10)))     [w 0.2]
        h(x) = sqrt(1 + (x / 0.2)^2) - 1

    with a_ref the acceleration limit (0.01 m/s^2 without one) and l_i,nom =
    ``initial_lengths``. The logarithmic part of r_track pays equally for every decade
    of tracking precision down to 1e-4 rad; the margin terms are added, so their
    gradient does not depend on the tracking. r lies in [0, 1], so ending an episode
    early never pays. ``info`` holds the components, which add up to r:
    ``reward_tracking`` = (1 - W) r_track, the penalties ``reward_effort`` and
    ``reward_accel`` (<= 0) and the margin terms ``reward_slack`` and
    ``reward_length`` (in [0, w]). docs/task_design.md gives the reasons and the
    ablation behind each choice.

    ## Cost

    For safe reinforcement learning (Safety-Gymnasium's convention; docs/safe_rl.md),
    every step's ``info["cost"]`` counts the constraints the chain came near, each an
    indicator in {{0, 1}} (thresholds of ``cost_thresholds``, defaults in brackets):

        cost = cost_slack + cost_length + cost_tumble  in {{0, 1, 2, 3}}
        cost_slack  = 1 if min_i T^_i,min < T_c                    [tension T_c = 0.5]
        cost_length = 1 if any l_i < f l_min or l_i > l_max / f    [length_factor f = 1.25]
        cost_tumble = 1 if any |theta_i| >= g pi/2                 [tumble_fraction g = 0.5]

    with (l_min, l_max) = ``length_bounds``. The step that terminates an episode costs
    at least 1; the reset costs 0. The reward does not depend on the cost.
    ``tether_gym.tasks.cost.COST_LIMIT`` (0.01) is the benchmark's limit on an
    episode's mean cost per step. ``tether_gym.safety_gymnasium`` wraps the env to
    Safety-Gymnasium's 6-tuple step.

    ## Starting State

    nu = ``initial_nu`` (0); theta = ``initial_theta`` (0.1, 0, ..., 0) + U(+-
    ``init_theta_range``); theta' = theta_d'(nu) + U(+-``init_dtheta_range``);
    l = ``initial_lengths`` + U(+-``init_length_range``); l' from the open-loop
    periodic law (paper Eq. 10) on the reference (0 at nu = 0). e and each mass are
    drawn uniformly from ``eccentricity_range`` and (1 +- ``mass_range``) m_i when
    given. ``reset(options=...)`` may fix any of ``"nu"``, ``"theta"``, ``"dtheta"``,
    ``"length"``, ``"dlength"`` (per tether), overriding the draw.

    A start is never failed: a draw that starts slack (any T^_i <= 0), tumbled (any
    |theta_i| >= pi/2), with a length outside ``length_bounds`` or non-finite is drawn
    again, up to 1000 times per reset. ``gym.make`` refuses (ValueError) a configuration
    whose every start is certainly failed: theta_d'(``initial_nu``) = A w cos(w
    ``initial_nu``) = -1 (Eq. 10's start rate divides by 1 + theta_d'), or a start with
    nothing drawn (``init_*_range`` 0, e and masses fixed) that fails. Other
    configurations whose ranges reach into the failure bounds can, rarely, fail all
    1000 draws of a reset; that episode then starts failed instead of raising (also at
    a vector env's autoreset inside ``step``): the observation is the last draw's,
    ``info["failure"]`` at the reset names the reason, and the first step terminates
    with that failure and reward 0 without moving the chain (a RuntimeWarning says it
    once per env). Reset options that fix a failed start, or whose draws all fail,
    raise ValueError.

    ## Episode End

    *Terminated* (``info["failure"]`` names the reason, None while healthy):
    ``"slack"`` any T^_i <= 0 at a physics substep boundary of the step;
    ``"tumble"`` any |theta_i| >= pi/2; ``"length"`` any l_i outside
    ``length_bounds``; ``"nonfinite"`` a NaN or inf state, ``"diverged"`` a state or
    tension beyond +-1e6 (in both cases the last healthy state is kept in the
    observation, which is always finite, and the reward is 0).
    *Truncated* only by the time limit: after ``orbits_per_episode`` orbits of true
    anomaly, whatever the configuration (``max_episode_steps``: 754 steps with the
    defaults). No step limit is registered, so ``gym.make`` adds no TimeLimit that could
    cut a lengthened episode; ``gym.make(..., max_episode_steps=k)`` still adds one.

    ## Arguments

    ``gym.make("tether_gym/TetherLibration-v2", **kwargs)``; unknown names raise
    ValueError with the list of valid ones.

    | Argument             | Default        | Meaning                                         |
    |----------------------|----------------|-------------------------------------------------|
    | n_bodies             | 3              | N, bodies including the main satellite (>= 2)   |
    | masses               | (1, 2)*        | subsatellite masses, any unit (* equal if N!=3) |
    | initial_lengths      | (1/n, ...)     | l_i(0) [-]                                      |
    | initial_theta        | (0.1, 0, ...)  | theta_i(0) [rad] before randomisation           |
    | initial_nu           | 0              | nu at reset [rad]                               |
    | eccentricity         | 0.2            | e [-], [0, 1)                                   |
    | semi_latus_rectum    | 8.52e6         | p [m]                                           |
    | mu                   | 3.986004418e14 | gravitational parameter [m^3/s^2]               |
    | total_tether_length  | 2e4            | L0 [m] (enters only through the reel limits)    |
    | gravity              | "gradient"     | "gradient" or "full"                            |
    | amplitude, frequency | 0.2, 1         | A [rad] and w [-] of theta_d = A sin(w nu)      |
    | control_step         | 0.025          | true anomaly per env step [rad]                 |
    | physics_step         | 0.0125         | RK4 step [rad]; divides control_step            |
    | max_reel_rate        | 0.5            | l'_cmd at abs(u) = 1 [-]                        |
    | action_mode          | "increment"    | "increment" or "rate" (Action Space)            |
    | increment_gain       | 0.25           | largest change of u per step [-], (0, 2]        |
    | accel_limit          | 0.01           | reel acceleration limit [m/s^2]; None: off      |
    | speed_limit          | None           | reel speed limit [m/s]                          |
    | reel_time_constant   | 0.0125         | reel lag tau [rad] (>= physics_step / 2)        |
    | length_bounds        | (0.05, 1.5)    | allowed l_i [-]                                 |
    | orbits_per_episode   | 3              | episode length [orbits]                         |
    | init_theta_range     | 0              | half-width of the theta_i(0) draw [rad]         |
    | init_dtheta_range    | 0              | half-width of the theta_i'(0) draw [rad/rad]    |
    | init_length_range    | 0              | half-width of the l_i(0) draw [-]               |
    | obs_noise            | 0              | std of observation noise                        |
    | obs_bias             | 0              | offset of every observed theta_i [rad]          |
    | disturbance          | 0              | bound of d in theta'' += d (Eq. 20) [rad/rad^2] |
    | eccentricity_range   | None           | (low, high) to draw e per episode               |
    | mass_range           | None           | relative half-width to draw each mass           |
    | observe_params       | None           | True: e, M_i in the obs; "eccentricity": e      |
    | reward_weights       | None           | dict overriding RewardWeights fields            |
    | cost_thresholds      | None           | dict overriding CostThresholds fields (Cost)    |
    | render_mode          | None           | None, "rgb_array" or "human"                    |

    ## Info

    Every step's and reset's ``info`` holds, in this order (per-tether entries are
    (n,) arrays):

    {info_table}

    ## Version History

    * v2 (tether_gym 0.7.0): a constraint-cost signal for safe reinforcement learning.
      ``info`` adds ``cost``, ``cost_slack``, ``cost_length`` and ``cost_tumble`` (the
      Cost section) and ``gym.make`` the argument ``cost_thresholds``. Observations,
      actions, rewards, terminations, starting states and trajectories are v1's,
      bitwise, so agents trained on v1 run on v2 unchanged. v1 stays registered and
      returns exactly what it returned (no cost entries; ``cost_thresholds`` is refused).
    * v1 (tether_gym 0.3.0): a task that rewards what the benchmark measures
      (docs/task_design.md has the ablation over training seeds behind each change).
      Actions are increments of the reel-rate command by default
      (``action_mode="rate"`` gives v0's direct command): i.i.d. exploration noise on
      a direct command makes every step a burst at the acceleration limit, which
      drove v0 agents to reel out to the length bound. The observation adds the
      tracking errors, ln(l / l_nom) and the command in force (Markov with
      increments). The reward adds a logarithmic tracking part that keeps paying
      down to 1e-4 rad, makes the slack and length terms additive (the length term a
      pseudo-Huber function of ln(l / l_nom), with a gradient everywhere) and
      penalises the effort of the command u rather than of the action; ``info``
      adds ``command``. Physics, termination, starting states and arguments are
      unchanged, as are the trajectories for the same reel commands. v0 is no
      longer registered (``gym.make`` of v0 names v1). tether_gym 0.4.0 adds
      ``observe_params="eccentricity"`` (e without the mass fractions); every
      configuration that existed before returns what it returned. tether_gym 0.5.0:
      a configuration whose every start is certainly failed is refused by
      ``gym.make``, and a start that 1000 draws cannot make valid (where 0.4.x raised
      after 100, at a reset or inside a vector env's ``step``) begins an episode
      that is failed from the start (Starting State); every start that 0.4.x drew
      is drawn bitwise the same, so every configuration that worked returns what it
      returned, and no id changes. tether_gym 0.6.0 adds ``obs_bias`` (0 by default:
      every configuration that existed before returns what it returned).
    * v0: initial release. tether_gym 0.2.0 keeps v0: with every configuration that
      worked before, trajectories, observations, terminations and info entries are
      bitwise those of 0.1.0, except that the reel acceleration is now computed by one
      helper for the reels, the reward and ``info["reel_accel"]``, so the reward can
      differ in its last bit (1 ulp) and ``reel_accel`` by a relative 2e-13. Fixed in
      0.2.0, where 0.1.0 broke its own spec: no step limit is registered any more, so
      an episode lasts ``orbits_per_episode`` orbits whatever the control step (0.1.0
      cut every episode at 754 steps); a state or tension beyond 1e6 terminates as
      ``"diverged"`` with a finite observation (it reached the float32 observation as
      inf); a reset never starts slack, tumbled, out of bounds or non-finite (a failed
      random draw is drawn again); invalid arguments, options and actions raise.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 30}

    def __init__(self, render_mode: str | None = None, **kwargs: Any):
        self.config = EnvConfig.from_kwargs(render_mode=render_mode, **kwargs)
        self.render_mode = self.config.render_mode
        self.action_space = action_space(self.config)
        self.observation_space = observation_space(self.config)
        self._batch = ChainBatch(self.config, 1)
        self._action = np.zeros((1, self.config.n_tethers))  # the step's action buffer
        self._rngs: list[np.random.Generator | None] = [None]
        self._needs_reset = True
        self._renderer = None

    @property
    def n_tethers(self) -> int:
        """n = N - 1."""
        return self.config.n_tethers

    @property
    def max_episode_steps(self) -> int:
        """Control steps per episode of this configuration."""
        return self.config.max_episode_steps

    @property
    def model(self) -> TetherChain:
        """The nominal physics model (config's e and masses) for model-based controllers."""
        return self.config.model

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode; ``options`` may fix nu and any state field (see Starting State)."""
        super().reset(seed=seed)
        self._rngs[0] = self.np_random
        self._batch.reset_rows((0,), self._rngs, options)
        self._needs_reset = False
        if self.render_mode == "human":
            self.render()
        return self._batch.obs[0].copy(), self._batch.info(0)

    def step(self, action):
        """Advance one control step; see the class docstring."""
        if self._needs_reset:
            raise RuntimeError("call reset() before step() (the episode has ended or not begun)")
        batch = self._batch
        rows = batch.rows
        act = check_action(action, self._action)
        try:
            batch.step(act, self._rngs)
        except ValueError:
            raise ValueError(f"action={action!r} must be finite (no NaN or inf)") from None
        terminated = rows.failure.item(0) != 0
        truncated = rows.truncated.item(0) and not terminated
        self._needs_reset = terminated or truncated
        if self.render_mode == "human":
            self.render()
        return rows.obs[0].copy(), rows.reward.item(0), terminated, truncated, batch.info(0)

    def render(self):
        """The current frame (``rgb_array``) or draw it in a window (``human``)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode="
                            "'rgb_array' or 'human' to gym.make")
            return None
        if self._renderer is None:
            from .rendering import ChainRenderer

            self._renderer = ChainRenderer(self.config, self.render_mode)
        return self._renderer.draw(self._batch.info(0), eccentricity_of(self._batch, 0))

    def close(self):
        """Stop worker threads and close the renderer."""
        self._batch.close()
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __repr__(self) -> str:
        return f"TetherLibrationEnv(n_bodies={self.config.n_bodies}, e={self.config.eccentricity})"



def _indent(text: str) -> str:
    return text.replace("\n", "\n    ")


# the spec sheet's tables come from the layout declarations (tether_gym.envs.layout)
TetherLibrationEnv.__doc__ = (TetherLibrationEnv.__doc__ or "").format(
    observation_table=_indent(markdown_table(OBSERVATION, "Observation")),
    info_table=_indent(markdown_table(INFO, "Entry", keyed=True)))
