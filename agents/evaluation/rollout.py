"""Run policies on the native vector env and record every episode: the one rollout path.

:func:`rollout` is used by the benchmark (:mod:`tether_gym_agents.evaluation.benchmark`) and by
the paper reproduction (:mod:`tether_gym_agents.paper`). It builds
``gym.make_vec(tether_gym.ENV_ID, num_envs=len(seeds),
vectorization_mode="vector_entry_point", **env_kwargs)``, resets sub-env i with
``seeds[i]`` and steps all of them together until each has ended once. Every policy is
called through stable-baselines3's interface, ``policy.predict(obs, deterministic=True)``,
with **one observation per call** (``obs[i:i + 1]``): a batched forward pass of a torch
network changes an action by ~1e-7 with the batch size, which a closed loop can amplify
into a different episode. The exception are policies that declare ``batch_invariant``
(trained MLPs, :mod:`tether_gym_agents.files.mlp`; the sliding-mode law, the safety filter
and the hybrids built of such parts): their rows are bitwise independent of the batch,
so the episodes that share one get a single call. Either way an episode's actions
depend on its seed, the env arguments and the policy only, never on how many episodes
run beside it or in which order the policies are evaluated.

Every sample also keeps the step's constraint cost, ``info["cost"]`` and its parts
``info["cost_<part>"]`` (:mod:`tether_gym.tasks.cost`; 0 at the reset row), when the env
reports them.

A policy with memory keeps it in stable-baselines3's recurrent ``state``: ``predict``
returns ``(actions, state)`` with one state row per observation, and gets that row back
on the episode's next call (``episode_start`` is True on its first). A policy with a
safety filter reports which rows it changed in ``last_filter_active`` ((B,) bool).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import gymnasium as gym
import numpy as np

from tether_gym import ENV_ID
from tether_gym.tasks.cost import COST_NAMES

from ..common.obs import ObservationLayout

__all__ = ["Trajectory", "rollout", "RECORDED_KEYS", "COST_KEYS"]

RECORDED_KEYS = ("nu", "theta", "dtheta", "length", "dlength", "tension", "tension_min",
                 "theta_ref", "reel_accel")
"""The env ``info`` entries kept for every sample of a :class:`Trajectory`."""
COST_KEYS = COST_NAMES
"""The cost entries of the env ``info`` (``cost``, ``cost_slack``, ``cost_length``,
``cost_tumble``), kept for every sample when the env reports them."""
_COMMAND = "command"  # info["command"]: the normalised command u of the step

ORBIT = 2.0 * math.pi


@dataclass
class Trajectory:
    """One episode: the reset state (row 0) and the state after every control step.

    The arrays named in :data:`RECORDED_KEYS` have K + 1 rows for K steps (row 0 from
    the reset ``info``); ``action`` (as given to the env), ``command`` (the commanded
    reel rate l'_cmd [-] held over step k: the env's command u times max_reel_rate) and
    ``reward`` have K rows.
    ``tension`` is T^ at the sample, ``tension_min`` the smallest T^ at the physics
    substep boundaries of the step that ended there.

    Attributes
    ----------
    failure : str or None
        Why the episode was terminated (``info["failure"]`` of its last step).
    truncated : bool
        Ended by the time limit (and not terminated).
    seed : int or None
        The env seed of the episode.
    settings : dict
        The env configuration values the paper tables quote.
    """

    nu: np.ndarray
    theta: np.ndarray
    dtheta: np.ndarray
    length: np.ndarray
    dlength: np.ndarray
    tension: np.ndarray
    tension_min: np.ndarray
    theta_ref: np.ndarray
    reel_accel: np.ndarray
    action: np.ndarray
    command: np.ndarray
    reward: np.ndarray
    failure: str | None
    truncated: bool
    seed: int | None = None
    settings: dict = field(default_factory=dict)
    filter_active: np.ndarray | None = None
    """(K,) bool: whether a safety filter changed step k's action; None for policies
    without one (those that do not set ``last_filter_active``, see
    :class:`tether_gym_agents.hybrids.policies.FilteredPolicy`)."""
    cost: np.ndarray | None = None
    """(K + 1,) the constraint cost [-] of each sample, ``info["cost"]`` (row 0: the
    reset's, 0; row k: step k's, in {0, 1, 2, 3}); None when the env reports none."""
    cost_slack: np.ndarray | None = None
    """(K + 1,) ``info["cost_slack"]`` [-] per sample (the slack part of ``cost``)."""
    cost_length: np.ndarray | None = None
    """(K + 1,) ``info["cost_length"]`` [-] per sample (the length part of ``cost``)."""
    cost_tumble: np.ndarray | None = None
    """(K + 1,) ``info["cost_tumble"]`` [-] per sample (the tumble part of ``cost``)."""

    @property
    def orbits(self) -> np.ndarray:
        """(nu - nu(0)) / 2 pi [orbits] of each sample."""
        return (self.nu - self.nu[0]) / ORBIT

    @property
    def tracking_error(self) -> np.ndarray:
        """max_i |theta_i - theta_d| [rad] per sample."""
        return np.abs(self.theta - self.theta_ref[:, None]).max(axis=1)

    @property
    def duration(self) -> float:
        """Orbits actually simulated."""
        return float(self.orbits[-1])

    @property
    def steps(self) -> int:
        """Number of control steps K."""
        return int(self.action.shape[0])


def _settings(cfg) -> dict:
    return {"control_step": cfg.control_step, "physics_step": cfg.physics_step,
            "reel_time_constant": cfg.reel_time_constant, "accel_limit": cfg.accel_limit,
            "eccentricity": cfg.eccentricity, "amplitude": cfg.amplitude,
            "max_reel_rate": cfg.max_reel_rate, "total_tether_length": cfg.total_tether_length}


def make_vector_env(num_envs: int, env_kwargs: dict | None = None):
    """The native vector env of the rollouts.

    An episode ends when the env's own configuration says so (``orbits_per_episode``);
    pass ``max_episode_steps`` in ``env_kwargs`` to cap it at a step count.
    """
    kwargs = dict(env_kwargs or {})
    kwargs.setdefault("max_episode_steps", -1)
    return gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        **kwargs)


def rollout(policies, seeds: Sequence[int | None], env_kwargs: dict | None = None,
            options: dict | None = None, env=None) -> list[Trajectory]:
    """One episode per seed, run side by side on the native vector env.

    Parameters
    ----------
    policies : object with ``predict`` or a sequence of them
        ``policies[i]`` drives the episode of ``seeds[i]`` (one object for all when a
        single policy is given). Each is called as ``predict(obs[i:i + 1],
        deterministic=True)`` and must return an action of shape (1, N-1) or (N-1,).
    seeds : sequence of int or None
        Env seed of each episode (sub-env i is reset with ``seeds[i]``).
    env_kwargs : dict or None
        Arguments of the env (see :func:`make_vector_env`); ignored when ``env`` is given.
    options : dict or None
        Reset options applied to every episode (see ``TetherLibrationEnv.reset``).
    env : TetherLibrationVectorEnv or None
        An existing vector env with ``len(seeds)`` sub-envs (left open); None builds
        one and closes it afterwards.

    Returns
    -------
    list of Trajectory
        One per seed, in the order of ``seeds``.
    """
    seeds = list(seeds)
    num = len(seeds)
    if num < 1:
        raise ValueError("rollout needs at least one seed")
    if hasattr(policies, "predict"):
        policies = [policies] * num
    policies = list(policies)
    if len(policies) != num:
        raise ValueError(f"got {len(policies)} policies for {num} seeds; give one policy or "
                         "one per seed")
    own = env is None
    venv = make_vector_env(num, env_kwargs) if own else env
    try:
        return _run(venv, policies, seeds, options)
    finally:
        if own:
            venv.close()


def _checked(action, policy, n_act: int, rows: int) -> np.ndarray:
    """A policy's action for ``rows`` observations as a (rows, n_act) float32 array."""
    action = np.asarray(action, dtype=np.float32)
    if action.size != n_act * rows:
        raise ValueError(f"policy {policy!r} returned an action of shape {action.shape}; "
                         f"this env needs ({n_act},) per observation")
    return action.reshape(rows, n_act)


@dataclass
class _Book:
    """What the rollout keeps: every step's samples, and each episode's memory.

    Per episode: where it ended and why, its recurrent state row, and the filter's flags.
    """

    rows: dict
    """Per kept ``info`` key, the (num,) row of every sample."""
    end: np.ndarray
    truncated: np.ndarray
    failure: list
    states: list
    started: np.ndarray
    filtered: list
    actions: list = field(default_factory=list)
    rewards: list = field(default_factory=list)

    @classmethod
    def start(cls, info: dict, num: int) -> _Book:
        """The book of ``num`` episodes, with the reset ``info`` as row 0."""
        keys = RECORDED_KEYS + (_COMMAND,) + tuple(k for k in COST_KEYS if k in info)
        return cls(rows={key: [np.array(info[key], dtype=float)] for key in keys},
                   end=np.zeros(num, dtype=np.int64), truncated=np.zeros(num, dtype=bool),
                   failure=[None] * num, states=[None] * num,
                   started=np.zeros(num, dtype=bool), filtered=[[] for _ in range(num)])

    def act(self, policy, idx: list[int], obs: np.ndarray, n_act: int) -> np.ndarray:
        """``policy``'s actions (len(idx), n_act) for the episodes ``idx``, in one call.

        Hands each episode its recurrent state row (and ``episode_start`` on its first
        call), keeps the new rows and the filter's flags of the step.
        """
        held = [self.states[i] for i in idx]
        state = None if any(h is None for h in held) else np.stack(held)
        action, new_state = policy.predict(obs[idx], state=state,
                                           episode_start=~self.started[idx],
                                           deterministic=True)
        self.started[idx] = True
        checked = _checked(action, policy, n_act, len(idx))
        if new_state is not None:
            for j, i in enumerate(idx):
                self.states[i] = np.asarray(new_state)[j]
        flag = getattr(policy, "last_filter_active", None)
        if flag is not None:
            for i, f in zip(idx, np.asarray(flag, dtype=bool).reshape(-1), strict=True):
                self.filtered[i].append(bool(f))
        return checked

    def record(self, step: int, actions: np.ndarray, outcome: tuple,
               active: np.ndarray) -> np.ndarray:
        """Keep step ``step``'s samples; return which active episodes ended there.

        ``outcome`` is ``(reward, terminated, truncated, info)`` of ``venv.step``.
        """
        reward, terminated, trunc, info = outcome
        self.actions.append(actions.copy())
        self.rewards.append(np.array(reward, dtype=float))
        for key, row in self.rows.items():
            row.append(np.array(info[key], dtype=float))
        ended = active & (terminated | trunc)
        for i in np.flatnonzero(ended).tolist():
            self.end[i] = step
            self.failure[i] = info["failure"][i]
            self.truncated[i] = bool(trunc[i] and not terminated[i])
        return ended

    def trajectories(self, seeds: list, settings: dict,
                     layout: ObservationLayout) -> list[Trajectory]:
        """One Trajectory per episode, cut at its end."""
        stacked = {key: np.stack(value) for key, value in self.rows.items()}
        acts = np.stack(self.actions)
        rews = np.stack(self.rewards)
        out = []
        for i, seed in enumerate(seeds):
            k = int(self.end[i])
            arrays = {key: stacked[key][:k + 1, i] for key in RECORDED_KEYS + COST_KEYS
                      if key in stacked}
            command = layout.to_reel_rate(stacked[_COMMAND][1:k + 1, i])
            flags = self.filtered[i]
            out.append(Trajectory(**arrays, action=acts[:k, i], command=command,
                                  reward=rews[:k, i], failure=self.failure[i],
                                  truncated=bool(self.truncated[i]), seed=seed,
                                  settings=dict(settings),
                                  filter_active=(np.array(flags, dtype=bool)
                                                 if len(flags) == k else None)))
        return out


def _groups(policies: list) -> list[list[int]]:
    """Episodes that share one ``predict`` call per step.

    A batch-invariant policy shared by several episodes gets their observations in one
    call (row i of the batch is bitwise row i alone); every other policy one each.
    """
    groups: dict[int, list[int]] = {}
    for i, policy in enumerate(policies):
        group = id(policy) if getattr(policy, "batch_invariant", False) else -1 - i
        groups.setdefault(group, []).append(i)
    return list(groups.values())


def _run(venv, policies: list, seeds: list, options: dict | None) -> list[Trajectory]:
    base = venv.unwrapped
    if base.num_envs != len(seeds):
        raise ValueError(f"env has {base.num_envs} sub-envs for {len(seeds)} seeds")
    n_act = int(base.single_action_space.shape[0])
    num = len(seeds)
    obs, info = venv.reset(seed=seeds, options=options)
    book = _Book.start(info, num)
    active = np.ones(num, dtype=bool)
    actions = np.zeros((num, n_act), dtype=np.float32)
    groups = _groups(policies)
    step = 0
    while active.any():
        for members in groups:
            idx = [i for i in members if active[i]]
            if idx:
                actions[idx] = book.act(policies[idx[0]], idx, obs, n_act)
        actions[~active] = 0.0
        obs, *outcome = venv.step(actions)
        step += 1
        active &= ~book.record(step, actions, tuple(outcome), active)
    return book.trajectories(seeds, _settings(base.config), ObservationLayout.from_env(base))
