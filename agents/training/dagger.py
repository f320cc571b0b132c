"""A policy distilled from ``mpc`` by DAgger: the student network, its data and its loop.

DAgger (Ross, Gordon & Bagnell 2011) with the model-predictive controller of the
benchmark as the expert: the ``mpc`` row's controller
(:class:`~tether_gym_agents.baselines.mpc.ModelPredictiveController` behind the safety
filter, :class:`~tether_gym_agents.hybrids.policies.FilteredPolicy`, as
:func:`tether_gym_agents.evaluation.nominal.nominal_mpc` builds it).

Iteration i rolls out ``episodes`` episodes of the mixture policy that sends the
expert's action with probability beta_i = ``beta_decay`` ** i at each step and the
student's otherwise (iteration 0: the expert alone, beta = 1; with ``mixture="episode"``
each episode is flown by the expert alone with probability beta_i, else by the student
alone). The expert labels EVERY
visited observation: one controller per episode is called on each step's observation
in order (its warm start follows the trajectory actually flown), whichever action is
executed. All (observation, expert action) pairs are aggregated over the iterations,
and the student is refitted after each iteration by supervised regression: the mean
squared error between its deterministic action and the expert's, both in the [-1, 1]
action box. After each refit the student flies ``check_episodes`` episodes alone
(beta = 0, not labelled: they cost no expert time) on fixed seeds of the same
distribution, and their success and tracking RMS are reported.

**Episodes.** The training distribution is ``ppo.yml``'s env arguments (random
initial libration, e in [0, 0.35], masses +-25 %, disturbance 0.1, observation noise
1e-3; :func:`training_env_kwargs`), in ``action_mode="rate"``: the student commands
reel rates, as the expert does, so the label is the expert's action itself (in the
increment mode of the PPO agents the command is a clipped sum of actions, and the
expert's command is not always one increment away). Each labelled episode draws its
e and masses from those ranges (:func:`draw_episode`) and fixes them in its env, so that
the expert designs on the episode's exact model, as ``mpc`` does on every scenario of
the suites. The student sees only the env's observation (``observe_params`` false:
no e, no masses): nothing privileged.

**Student.** A stable-baselines3 ``ActorCriticPolicy`` (so that the agent files are
the PPO agents' format and ``evaluate.py`` scores it by the same path) whose action
network is an MLP, ``net_arch`` (256, 256) tanh by default: tanh keeps the map smooth
(the expert's law is smooth away from its active constraints, and the closed loop asks
for corrections of 1e-5 rad), and two layers of 256 cost about 0.06 ms per step
in the float64 forward pass of evaluation. Its value network (``vf``) is a single
unused linear layer. Observations are normalised with the aggregated dataset's mean and
variance by VecNormalize's formula (clip 10, epsilon 1e-8), saved as ``obs_normalization``
in ``agent.json``. The network is warm-started from the previous iteration's weights;
each refit runs ``epochs`` passes of Adam (minibatch ``batch_size``, learning rate
``learning_rate`` decaying by a cosine to 1 % of it over the refit).

**Outputs** (:func:`train_dagger`): the run folder holds ``agent.json`` +
``policy.safetensors`` (the last student), ``checkpoints/agent_<labels>_steps/`` (the
student after each iteration; its "steps" are the labels it was fitted on, so ``python
evaluate.py curves RUN`` draws a curve over labels), ``dagger_data.npz`` (the
aggregated observations, labels, and each pair's iteration, episode and whether the
expert's action was executed), ``train_log.json`` (one record per iteration),
``train_info.json``, ``config.yml`` and ``command.txt``.

Deterministic for a given seed (one torch thread; the expert is deterministic).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

import numpy as np

import tether_gym

from ..common.features import FeatureSpec, add_features
from ..common.ranges import interval
from ..files.folder_paths import FolderFileError
from ..files.run_folder import (
    CHECKPOINT_AGENT_PREFIX,
    CHECKPOINT_DIR,
    COMMAND_FILE,
    CONFIG_FILE,
    ITERATION_LOG_FILE,
    TRAIN_INFO_FILE,
    append_command,
    check_fresh_run_folder,
    write_config,
    write_text_atomic,
    write_train_info,
)
from ..files.safe_format import (
    AGENT_FILE,
    WEIGHTS_FILE,
    AgentLoadError,
    ObsNormalization,
    save_agent,
)
from ..files.trained import TrainedAgent
from .config import ConfigError, training_distribution
from .dataset_file import read_dataset_arrays

__all__ = ["DaggerSettings", "LIMITS", "Dataset", "Episode", "training_env_kwargs",
           "draw_episode", "make_expert", "rollout", "make_student", "start_from",
           "InitPolicyError", "fit_student", "normalization", "train_dagger", "DATA_FILE",
           "ALGO", "MIXTURES", "check_out"]

DATA_FILE = "dagger_data.npz"
WRITTEN_FILES = (AGENT_FILE, WEIGHTS_FILE, DATA_FILE, ITERATION_LOG_FILE,
                 TRAIN_INFO_FILE, CONFIG_FILE, COMMAND_FILE)
"""The files a DAgger run writes at the top of its folder (besides ``checkpoints/``)."""
ALGO = "ppo"
"""The algorithm recorded in ``agent.json``: the student is a PPO-format policy (its
``training.method`` says ``dagger``)."""
SEED_MAX = 2**31 - 1
LIMITS: dict[str, tuple[float, float]] = {
    "iterations": (0, 100), "episodes": (1, 10_000), "epochs": (1, 100_000),
    "seed": (0, SEED_MAX), "orbits": (0.01, 100.0), "beta_decay": (0.0, 1.0),
    "batch_size": (1, 1_000_000), "learning_rate": (1e-7, 1.0), "check_episodes": (0, 10_000),
    "expert_noise": (0.0, 2.0), "gate": (0.0, 2.0), "symlog_scale": (1e-9, 10.0),
}
"""Valid range (inclusive) of each numeric setting of :class:`DaggerSettings`."""
MIXTURES = ("step", "episode")
"""How the mixture of iteration i mixes: per step or per episode (:class:`DaggerSettings`)."""
_INTEGERS = ("iterations", "episodes", "epochs", "seed", "batch_size", "check_episodes")
_MAX_WIDTH, _MAX_DEPTH = 4096, 8


@dataclass(frozen=True)
class DaggerSettings:
    """The budget and the student of one DAgger run (ranges: :data:`LIMITS`).

    Attributes
    ----------
    iterations : int
        DAgger iterations (iteration 0 is the expert alone); with shared data, the
        labelled iterations after the fit on it (0: behaviour cloning on it alone).
    episodes : int
        Labelled episodes per iteration.
    epochs : int
        Passes over the aggregated dataset per refit.
    seed : int
        Seeds the episodes' draws, the mixture and the network.
    orbits : float or None
        Episode length [orbits] (None: the env's default, 3).
    beta_decay : float
        beta_i = beta_decay ** i, the probability that the mixture sends the expert's
        action in iteration i [-].
    net_arch : tuple of int
        Hidden widths of the student's MLP (tanh).
    batch_size, learning_rate : int, float
        Adam's minibatch and initial step size.
    check_episodes : int
        Unlabelled episodes the student flies alone after each refit (its report).
    mixture : str
        ``"step"``: every step executes the expert's action with probability beta_i;
        ``"episode"``: every episode is flown by the expert alone with probability
        beta_i, else by the student alone (the expert labels both).
    expert_noise : float
        Standard deviation [-] of the Gaussian noise added to the expert's action when
        it is executed, before the expert's safety filter (DART, Laskey et al. 2017: the
        expert's own trajectories are perturbed so that the labels cover the states a
        slightly wrong student reaches; the label stays the expert's clean action).
        0: no noise.
    gate : float or None
        Intervention threshold [-] (HG-DAgger, Kelly et al. 2019, with mpc as the
        gatekeeper): once a student's executed action departs from the expert's label
        by more than ``gate`` (largest component), the expert flies the rest of the
        episode, so that the data stay near states from which the expert's labels are
        its smooth law. None: no intervention.
    drop_failed : bool
        Leave the pairs of terminated episodes out of the aggregate (their last labels
        are the expert's saturated, infeasible recoveries).
    symlog_scale : float or None
        S [rad]: the student's network also sees symlog(e_i / S) and symlog(e_i' / S)
        (the ``symlog_errors`` features of ``ppo_symlog``, recorded in ``agent.json``), so
        that tracking errors far below the first orbit's transient reach it at a usable
        scale. None: the observation alone.
    init_policy : str or None
        A trained rate-mode PPO-format agent (a run folder, or a shipped agent by name,
        ``distill_ppo/seed_{seed}``; ``{seed}`` stands for :attr:`seed`) whose actor and
        observation statistics start the student: DAgger from a policy that already flies
        (e.g. a fine-tuned student), mpc relabelling the states *it* visits. The
        statistics then stay fixed for the run (the actor was fitted on inputs scaled by
        them), and iteration 0 only checks the starting policy (no labels, no refit;
        with ``data``: the refit on it). None: a new network.
    """

    iterations: int = 5
    episodes: int = 6
    epochs: int = 100
    seed: int = 0
    orbits: float | None = None
    beta_decay: float = 0.5
    net_arch: tuple[int, ...] = (256, 256)
    batch_size: int = 256
    learning_rate: float = 1e-3
    check_episodes: int = 4
    mixture: str = "step"
    expert_noise: float = 0.0
    gate: float | None = None
    drop_failed: bool = False
    symlog_scale: float | None = None
    init_policy: str | None = None

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in LIMITS and value is not None:
                _check_number(f.name, value, *LIMITS[f.name], f.name in _INTEGERS)
        if self.mixture not in MIXTURES:
            raise ValueError(f"mixture={self.mixture!r}: allowed one of {list(MIXTURES)}")
        arch = self.net_arch
        if not isinstance(arch, tuple) or not 1 <= len(arch) <= _MAX_DEPTH or not all(
                isinstance(w, int) and not isinstance(w, bool) and 1 <= w <= _MAX_WIDTH
                for w in arch):
            raise ValueError(f"net_arch={arch!r}: allowed a tuple of 1 to {_MAX_DEPTH} layer "
                             f"widths, each an integer in [1, {_MAX_WIDTH}]")
        init = self.init_policy
        if init is not None and (not isinstance(init, str) or not init.strip()):
            raise ValueError(f"init_policy={init!r}: allowed the path or shipped name of a "
                             "trained agent (a folder with agent.json)")


def _check_number(name: str, value, lo: float, hi: float, integer: bool) -> None:
    kind = "an integer" if integer else "a number"
    ok = isinstance(value, int) if integer else isinstance(value, (int, float))
    if not ok or isinstance(value, bool) or not math.isfinite(value) or not lo <= value <= hi:
        raise ValueError(f"{name}={value!r}: allowed {kind} in {interval(lo, hi)}")


# ----------------------------------------------------------------------------- data
@dataclass
class Episode:
    """One rolled-out episode.

    ``obs`` (T, d) float32: the observations acted on; ``labels`` (T, n): the expert's
    action on each (None when not labelled); ``expert_acted`` (T,) bool: whether the
    expert's action was executed; ``survived``: not terminated; ``tracking_rms``
    [rad]: RMS of theta - theta_d over the steps after orbit 1 (None without such steps
    or when terminated); ``final_error`` [rad]: max |theta - theta_d| over the last
    orbit (None when terminated).
    """

    obs: np.ndarray
    labels: np.ndarray | None
    expert_acted: np.ndarray
    survived: bool
    tracking_rms: float | None
    final_error: float | None = None


@dataclass
class Dataset:
    """The aggregated (observation, expert action) pairs of a DAgger run.

    ``obs`` (N, d) float32, ``labels`` (N, n) float64, and per pair its ``iteration``,
    ``episode`` (numbered over the run) and ``expert_acted``; ``episodes`` holds per
    episode what re-creates it: its env seed, e [-], masses, beta [-] and the seed of
    the mixture's draws.
    """

    obs: np.ndarray
    labels: np.ndarray
    iteration: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int32))
    episode: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int32))
    expert_acted: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    episodes: list[dict] = field(default_factory=list)

    @classmethod
    def empty(cls, obs_dim: int, act_dim: int) -> Dataset:
        """No pairs yet."""
        return cls(np.zeros((0, obs_dim), np.float32), np.zeros((0, act_dim)))

    def add(self, episode: Episode, iteration: int, number: int, about: dict) -> None:
        """Append a labelled episode's pairs; ``about``: its entry of ``episodes``."""
        if episode.labels is None:
            raise ValueError("an unlabelled episode cannot be aggregated")
        count = len(episode.obs)
        self.obs = np.concatenate([self.obs, episode.obs.astype(np.float32)])
        self.labels = np.concatenate([self.labels, episode.labels])
        self.iteration = np.concatenate([self.iteration, np.full(count, iteration, np.int32)])
        self.episode = np.concatenate([self.episode, np.full(count, number, np.int32)])
        self.expert_acted = np.concatenate([self.expert_acted, episode.expert_acted])
        self.episodes.append(dict(about))

    def __len__(self) -> int:
        return len(self.obs)

    @classmethod
    def load(cls, path) -> Dataset:
        """Read a :meth:`save`d ``.npz``: no pickle, every array checked first.

        Raises ``ValueError`` naming the file and the key for a file that is not one
        (:func:`~.dataset_file.read_dataset_arrays`).
        """
        z = read_dataset_arrays(path)
        episodes = [{"env_seed": int(z["episode_env_seed"][k]),
                     "eccentricity": float(z["episode_eccentricity"][k]),
                     "masses": [float(m) for m in z["episode_masses"][k]],
                     "beta": float(z["episode_beta"][k]),
                     "mixture_seed": int(z["episode_mixture_seed"][k])}
                    for k in range(len(z["episode_env_seed"]))]
        return cls(z["obs"].astype(np.float32), z["labels"].astype(np.float64),
                   z["iteration"].astype(np.int32), z["episode"].astype(np.int32),
                   z["expert_acted"].astype(bool), episodes)

    def extend(self, other: Dataset) -> None:
        """Append ``other``'s pairs and episodes (its episode numbers shifted after ours)."""
        shift = len(self.episodes)
        self.obs = np.concatenate([self.obs, other.obs])
        self.labels = np.concatenate([self.labels, other.labels])
        self.iteration = np.concatenate([self.iteration, other.iteration])
        self.episode = np.concatenate([self.episode, other.episode + shift])
        self.expert_acted = np.concatenate([self.expert_acted, other.expert_acted])
        self.episodes.extend(dict(e) for e in other.episodes)

    def save(self, path: Path) -> None:
        """Write the arrays as an ``.npz`` (no pickle)."""
        arrays: dict[str, np.ndarray] = {
            "obs": self.obs, "labels": self.labels, "iteration": self.iteration,
            "episode": self.episode, "expert_acted": self.expert_acted}
        for key in ("env_seed", "eccentricity", "masses", "beta", "mixture_seed"):
            arrays[f"episode_{key}"] = np.asarray([e[key] for e in self.episodes])
        np.savez_compressed(path, **arrays)  # type: ignore[arg-type]


# ------------------------------------------------------------------------ episodes
def training_env_kwargs(orbits: float | None = None) -> dict:
    """The training distribution: ``ppo.yml``'s env arguments in ``action_mode="rate"``.

    ``increment_gain`` (meaningless in the rate mode) is left out; ``orbits`` sets
    ``orbits_per_episode`` when given.
    """
    kwargs = {k: v for k, v in training_distribution().items() if k != "increment_gain"}
    kwargs["action_mode"] = "rate"
    if orbits is not None:
        kwargs["orbits_per_episode"] = float(orbits)
    return kwargs


def draw_episode(rng: np.random.Generator, env_kwargs: dict, masses) -> dict:
    """One episode's env arguments: e and the masses drawn from the ranges, then fixed.

    e ~ U(``eccentricity_range``) and m_i ~ m_i U(1 +- ``mass_range``) as the env draws
    them (``masses``: the nominal ones); the ranges are removed and the drawn values
    given, so that the expert can design on the episode's model.
    """
    kwargs = dict(env_kwargs)
    ecc_range = kwargs.pop("eccentricity_range", None)
    mass_range = kwargs.pop("mass_range", None)
    if ecc_range is not None:
        kwargs["eccentricity"] = float(rng.uniform(*ecc_range))
    if mass_range is not None:
        nominal = np.asarray(masses, dtype=float)
        scale = rng.uniform(1.0 - mass_range, 1.0 + mass_range, nominal.shape)
        kwargs["masses"] = tuple(float(m) for m in nominal * scale)
    return kwargs


def make_expert(env):
    """``mpc`` on ``env``'s own model behind the safety filter (one per episode)."""
    from ..baselines.mpc import ModelPredictiveController
    from ..hybrids.policies import FilteredPolicy

    return FilteredPolicy.for_env(ModelPredictiveController.for_env(env), env)


def rollout(env, seed: int, expert=None, student=None, beta: float = 1.0,
            rng: np.random.Generator | None = None, expert_noise: float = 0.0,
            gate: float | None = None) -> Episode:
    """One episode of the mixture: the expert's action with probability ``beta``.

    Parameters
    ----------
    env : gymnasium.Env
        A TetherLibration env in ``action_mode="rate"``; reset with ``seed``.
    seed : int
        The episode's env seed.
    expert : object with ``predict`` or None
        Labels every observation (called on each in order, whoever acts); None: no
        labels, the student acts alone.
    student : callable or None
        ``student(obs) -> action``; None: the expert acts alone.
    beta : float
        Probability [-] that a step executes the expert's action (drawn from ``rng``
        at every step when both act).
    rng : numpy Generator or None
        The mixture's draws (needed when both act, or with ``expert_noise``).
    expert_noise : float
        Standard deviation [-] of Gaussian noise on the expert's executed action (the
        label stays clean; the sum is clipped to [-1, 1] and, when the expert has a
        safety filter, sent through it as the expert's own commands are).
    gate : float or None
        Once a student's action departs from the label by more than this (largest
        component) [-], the expert flies the rest of the episode.
    """
    if expert is None and student is None:
        raise ValueError("rollout needs an expert, a student or both")
    if expert_noise > 0.0 and rng is None:
        raise ValueError("expert_noise needs rng")
    taken_over = False
    cfg = env.unwrapped.config
    per_orbit = cfg.max_episode_steps / cfg.orbits_per_episode
    obs, _ = env.reset(seed=int(seed))
    seen: list[np.ndarray] = []
    labels: list[np.ndarray] = []
    acted: list[bool] = []
    sq, count, survived, t, worst = 0.0, 0, True, 0, 0.0
    last_orbit = cfg.max_episode_steps - per_orbit
    while True:
        label = None if expert is None else np.asarray(expert.predict(obs)[0], np.float64)
        if student is None or taken_over:
            by_expert = True
        elif expert is None:
            by_expert = False
        else:
            if rng is None:
                raise ValueError("a mixture of expert and student needs rng")
            by_expert = bool(rng.random() < beta)
        if by_expert:
            action = label
            if expert_noise > 0.0 and rng is not None and label is not None:
                action = _noisy(expert, obs, label + rng.normal(0.0, expert_noise, label.shape))
        else:
            action = np.asarray(student(obs), np.float64)
            if gate is not None and label is not None and np.max(np.abs(action - label)) > gate:
                taken_over = True  # this step still flies the student's action
        seen.append(np.asarray(obs, np.float32))
        if label is not None:
            labels.append(label)
        acted.append(by_expert)
        obs, _, terminated, truncated, info = env.step(action)
        err = np.asarray(info["theta"], float) - float(info["theta_ref"])
        if t >= per_orbit:
            sq += float(np.mean(err**2))
            count += 1
        if t >= last_orbit:
            worst = max(worst, float(np.max(np.abs(err))))
        t += 1
        if terminated:
            survived = False
        if terminated or truncated:
            break
    rms = math.sqrt(sq / count) if count and survived else None
    return Episode(np.stack(seen), None if expert is None else np.stack(labels),
                   np.asarray(acted, bool), survived, rms, worst if survived else None)


def _noisy(expert, obs, desired: np.ndarray) -> np.ndarray:
    """The expert's perturbed command as it flies.

    Through the expert's own safety filter when it has one (``project``), else clipped
    to [-1, 1].
    """
    project = getattr(expert, "project", None)
    if project is None:
        return np.clip(desired, -1.0, 1.0)
    return np.asarray(project(obs, np.clip(desired, -1.0, 1.0)), np.float64)


# ------------------------------------------------------------------------- student
def student_features(settings: DaggerSettings) -> dict | None:
    """The ``features`` entry of the student's ``agent.json`` (None: no features)."""
    if settings.symlog_scale is None:
        return None
    return FeatureSpec("symlog_errors", settings.symlog_scale).to_dict()


def student_inputs(settings: DaggerSettings, obs: np.ndarray, n_tethers: int) -> np.ndarray:
    """The network's un-normalised input: ``obs`` followed by the student's features."""
    spec = student_features(settings)
    return add_features(None if spec is None else FeatureSpec.from_dict(spec), obs, n_tethers)


def make_student(env, settings: DaggerSettings):
    """A stable-baselines3 ``ActorCriticPolicy`` (MLP of ``net_arch``, tanh) for ``env``.

    Its observation space is the env's, widened by the student's features if any.
    """
    import gymnasium as gym
    import torch
    from stable_baselines3.common.policies import ActorCriticPolicy

    torch.manual_seed(settings.seed)
    space = env.observation_space
    extra = student_inputs(settings, space.low[None], env.action_space.shape[0]).shape[1] \
        - space.shape[0]
    if extra:
        space = gym.spaces.Box(np.concatenate([space.low, np.full(extra, -np.inf, np.float32)]),
                               np.concatenate([space.high, np.full(extra, np.inf, np.float32)]),
                               dtype=np.float32)
    policy = ActorCriticPolicy(space, env.action_space, lambda _: 0.0,
                               net_arch={"pi": list(settings.net_arch), "vf": []},
                               activation_fn=torch.nn.Tanh)
    policy.set_training_mode(False)
    return policy


class InitPolicyError(ValueError):
    """``init_policy`` names an agent that cannot start the student (:func:`start_from`)."""


_DISTILL_HINTS = {"features": "give --symlog-scale as the agent's",
                  "action_mode": "the student commands reel rates, as mpc does"}
"""What ``train.py distill`` changes to fit an agent (``check_agent_fits``' hints)."""


def start_from(settings: DaggerSettings, policy, obs_dim: int) -> TrainedAgent:
    """Load ``settings.init_policy``, check that it fits the student, copy its actor in.

    Parameters
    ----------
    settings : DaggerSettings
        Its ``init_policy`` (not None) names the agent; ``{seed}`` stands for the seed.
    policy : ActorCriticPolicy
        The new student (:func:`make_student`), which takes the agent's actor.
    obs_dim : int
        The env's observation length, before the student's features.

    Returns
    -------
    TrainedAgent
        The agent, whose ``norm`` the run keeps.

    Raises
    ------
    InitPolicyError
        Naming the agent and what does not fit (algorithm, hybrid, features, action
        mode, normalisation, input count, layer widths or activation).
    """
    from .warm_start import agent_location, check_agent_fits, copy_actor, init_policy_for

    value = init_policy_for(str(settings.init_policy), settings.seed)
    what = f"init_policy {value!r}"
    spec = student_features(settings)
    mine = None if spec is None else FeatureSpec.from_dict(spec)
    n_inputs = obs_dim + (0 if mine is None else mine.size(policy.action_space.shape[0]))
    try:
        agent = TrainedAgent.load(agent_location(value))  # safe files only, no pickle
    except AgentLoadError as exc:
        raise InitPolicyError(f"{what}: {exc}") from None
    try:  # the checks train.py's init_policy makes, then the student's own
        check_agent_fits(agent, what, mine, {"action_mode": "rate"}, True, _DISTILL_HINTS)
        if agent.norm is not None and agent.norm.mean.shape != (n_inputs,):
            raise ConfigError(f"{what}: {agent.norm.mean.shape[0]} normalised inputs; the "
                              f"student has {n_inputs}")
        copy_actor(agent.model, policy, what, "--net-arch")
    except ConfigError as exc:
        raise InitPolicyError(str(exc)) from None
    return agent


def normalization(obs: np.ndarray) -> ObsNormalization:
    """VecNormalize-style statistics of the dataset's observations (clip 10, eps 1e-8)."""
    x = np.asarray(obs, dtype=np.float64)
    return ObsNormalization(x.mean(axis=0), x.var(axis=0), float(len(x)), 10.0, 1e-8)


def deterministic_action(policy, obs_normalised):
    """The policy's deterministic (mean) action, before clipping, as a torch tensor."""
    features = policy.extract_features(obs_normalised, policy.pi_features_extractor)
    return policy.action_net(policy.mlp_extractor.forward_actor(features))


def fit_student(policy, data: Dataset, norm: ObsNormalization, settings: DaggerSettings,
                generator) -> float:
    """Refit on all of ``data``: ``epochs`` passes of Adam on the MSE; the last epoch's loss.

    The loss is the mean over pairs and actions of (a_student - a_expert)^2 with
    a_student the deterministic action on the normalised observation.
    """
    import torch

    n = data.labels.shape[1]
    x = torch.as_tensor(norm.apply(student_inputs(settings, data.obs, n)))
    y = torch.as_tensor(data.labels, dtype=torch.float32)
    params = [p for name, p in policy.named_parameters()
              if not name.startswith(("value_net", "mlp_extractor.value_net", "log_std"))]
    opt = torch.optim.Adam(params, lr=settings.learning_rate)
    bs = min(settings.batch_size, len(x))
    steps_per_epoch = math.ceil(len(x) / bs)
    total = settings.epochs * steps_per_epoch
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda k: 0.01 + 0.99 * 0.5 * (1.0 + math.cos(math.pi * min(k, total) / total)))
    policy.set_training_mode(True)
    last = math.nan
    for _ in range(settings.epochs):
        perm = torch.randperm(len(x), generator=generator)
        acc, n = 0.0, 0
        for start in range(0, len(x), bs):
            idx = perm[start:start + bs]
            loss = torch.mean((deterministic_action(policy, x[idx]) - y[idx]) ** 2)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            acc += float(loss.detach()) * len(idx)
            n += len(idx)
        last = acc / n
    policy.set_training_mode(False)
    return last


# ---------------------------------------------------------------------------- loop
def _flier(policy, norm, settings: DaggerSettings) -> Callable[[np.ndarray], np.ndarray]:
    """``student(obs) -> action``: the network's deterministic action, as its agent acts."""
    agent = TrainedAgent(policy, norm, algo=ALGO, features=student_features(settings))

    def student(obs):
        return agent.predict(obs, deterministic=True)[0]

    return student


def check_out(out: Path) -> None:
    """Make the run folder ``out``; refuse one that holds an earlier run or cannot be written.

    DAgger has no resume: a second run there would leave its checkpoints beside the
    first run's (:func:`~tether_gym_agents.files.run_folder.check_fresh_run_folder`).

    Raises
    ------
    FolderFileError
        A ``ValueError`` whose message starts with ``--out 'OUT':`` and says what is wrong.
    """
    try:
        check_fresh_run_folder(out, WRITTEN_FILES, "give a new --out, or remove it first "
                               "(train.py distill has no --resume)")
    except FolderFileError as exc:
        raise FolderFileError(f"--out {str(out)!r}: {exc}") from None


def _save(folder: Path, policy, norm, env_kwargs: dict, training: dict,
          features: dict | None) -> None:
    save_agent(folder, policy, ALGO, norm, env_id=tether_gym.ENV_ID, env_kwargs=env_kwargs,
               training=training, features=features)


def train_dagger(settings: DaggerSettings, out, command: str = "",
                 log: Callable[[str], None] | None = print,
                 initial: Dataset | None = None) -> dict:
    """Run DAgger with ``mpc`` as the expert; write the run folder ``out``.

    ``initial``: pairs labelled beforehand (a shared expert dataset, e.g. written by a
    run with ``iterations=1``); the student is first fitted on them (recorded as
    iteration 0, no labels spent) and the labelled iterations are 1 .. ``iterations``.

    Returns the run's summary (also in ``train_info.json``): labels, wall time [s],
    labels per second, and the per-iteration records of ``train_log.json``.
    """
    import gymnasium as gym
    import torch

    from tether_gym.envs.config import env_config

    if settings.iterations == 0 and initial is None:
        raise ValueError("iterations=0: allowed only with shared data to fit on (--data)")
    t0 = time.perf_counter()
    torch.set_num_threads(1)
    env_kwargs = training_env_kwargs(settings.orbits)
    check_env = gym.make(tether_gym.ENV_ID, **env_kwargs)
    masses = env_config(check_env).masses
    rng = np.random.default_rng(settings.seed)
    check_seeds = [int(s) for s in rng.integers(0, 2**31 - 1, settings.check_episodes)]
    policy = make_student(check_env, settings)
    obs_dim, act_dim = env_config(check_env).obs_dim, env_config(check_env).n_tethers
    try:
        start = None if settings.init_policy is None else start_from(settings, policy, obs_dim)
    except InitPolicyError:
        check_env.close()
        raise
    out = Path(out)
    check_out(out)
    write_config(out, {"algo": "dagger", "expert": "mpc", "env_id": tether_gym.ENV_ID,
                       "hyperparams": {**asdict(settings), "net_arch": list(settings.net_arch)},
                       "env_kwargs": env_kwargs})
    if command:
        append_command(out, command)
    generator = torch.Generator().manual_seed(settings.seed)
    data = Dataset.empty(obs_dim, act_dim)
    kept = None if start is None else start.norm  # the starting policy's statistics, fixed
    student = None if start is None else _flier(policy, kept, settings)  # flies iteration 1
    history: list[dict] = []
    label_time = 0.0
    number = 0
    dropped = 0
    if initial is not None:  # iteration 0 is the fit on the shared data alone
        data.extend(initial)
        number = len(data.episodes)
    zeroth = initial is not None or start is not None  # iteration 0: no labels
    for it in range(settings.iterations + zeroth):
        beta = settings.beta_decay ** it
        t_it = time.perf_counter()
        label_start = label_time
        for _ in range(0 if zeroth and it == 0 else settings.episodes):
            kwargs = draw_episode(rng, env_kwargs, masses)
            env_seed = int(rng.integers(0, 2**31 - 1))
            mix_seed = int(rng.integers(0, 2**31 - 1))
            mix = np.random.default_rng(mix_seed)
            flown = beta
            if settings.mixture == "episode":  # one actor for the whole episode
                flown = 1.0 if mix.random() < beta else 0.0
            env = gym.make(tether_gym.ENV_ID, **kwargs)
            expert = make_expert(env)  # its first build (~10 s) is not labelling time
            t_ep = time.perf_counter()
            episode = rollout(env, env_seed, expert, student, flown, mix,
                              settings.expert_noise, settings.gate)
            label_time += time.perf_counter() - t_ep
            if settings.drop_failed and not episode.survived:
                dropped += len(episode.obs)
                env.close()
                continue
            data.add(episode, it, number, {
                "env_seed": env_seed, "eccentricity": env_config(env).eccentricity,
                "masses": list(env_config(env).masses), "beta": flown,
                "mixture_seed": mix_seed})
            env.close()
            number += 1
        norm = (kept if kept is not None
                else normalization(student_inputs(settings, data.obs, act_dim)))
        loss = fit_student(policy, data, norm, settings, generator) if len(data) else None
        student = _flier(policy, norm, settings)
        checks = [rollout(check_env, s, student=student) for s in check_seeds]
        wall = time.perf_counter() - t0
        rms = [c.tracking_rms for c in checks if c.tracking_rms is not None]
        final = [c.final_error for c in checks if c.final_error is not None]
        record = {"iteration": it, "beta": beta, "episodes": number, "labels": len(data),
                  "wall_time_s": round(wall, 2),
                  "iteration_s": round(time.perf_counter() - t_it, 2),
                  "labels_per_s": _rate(len(data) - (history[-1]["labels"] if history
                                                     else len(initial or ())),
                                        label_time - label_start),
                  "expert_acted": float(np.mean(data.expert_acted[data.iteration == it]))
                  if np.any(data.iteration == it) else 1.0,
                  "dropped_labels": dropped,
                  "loss": loss,
                  "check_survived": float(np.mean([c.survived for c in checks]))
                  if checks else None,
                  "check_tracking_rms": float(np.median(rms)) if rms else None,
                  "check_final_error": float(np.median(final)) if final else None}
        history.append(record)
        training = {"method": "dagger", "expert": "mpc", "seed": settings.seed,
                    "command": command, "num_timesteps": len(data), "iteration": it,
                    "wall_time_s": round(wall, 1)}
        _save(out / CHECKPOINT_DIR / f"{CHECKPOINT_AGENT_PREFIX}_{len(data)}_steps", policy,
              norm, env_kwargs, training, student_features(settings))
        if log:
            log(_progress(record, settings))
    check_env.close()
    wall = time.perf_counter() - t0
    _save(out, policy, norm, env_kwargs, training, student_features(settings))
    data.save(out / DATA_FILE)
    write_text_atomic(out / ITERATION_LOG_FILE, json.dumps(history, indent=1))
    summary = {"algo": "dagger", "expert": "mpc", "env_id": tether_gym.ENV_ID,
               "seed": settings.seed, "command": command, "status": "finished",
               "tether_gym": tether_gym.__version__, "torch": torch.__version__,
               "num_timesteps": len(data), "labels": len(data), "episodes": number,
               "wall_time_s": round(wall, 1), "label_time_s": round(label_time, 1),
               "labels_per_s": _rate(len(data) - len(initial or ()), label_time),
               "history": history}
    write_train_info(out, summary)
    return summary


def fmt_rate(value: float | None) -> str:
    """A labelling rate for a progress line."""
    return "no labelling" if value is None else f"{value:.1f} labels/s"


def _rate(labels: int, seconds: float) -> float | None:
    """Labels per second of labelling time; None when nothing was labelled."""
    return round(labels / seconds, 2) if labels > 0 and seconds > 0.0 else None


def _progress(r: dict, settings: DaggerSettings) -> str:
    """The iteration's progress line."""
    def fmt(value, unit=""):
        return "n/a" if value is None else f"{value:.2e}{unit}"

    check = ""
    if r["check_survived"] is not None:
        n = settings.check_episodes
        check = (f"; student alone: {round(r['check_survived'] * n)}/{n} survived, median "
                 f"tracking RMS {fmt(r['check_tracking_rms'], ' rad')}, last-orbit max "
                 f"error {fmt(r['check_final_error'], ' rad')}")
    who = (f"beta {r['beta']:.3g}, expert acted {r['expert_acted']:.2f}" if r["labels"]
           else "the starting policy, before any label")
    return (f"iteration {r['iteration']} ({who}): {r['episodes']} episodes, {r['labels']} labels, "
            f"{fmt_rate(r['labels_per_s'])}, {r['wall_time_s']:.1f} s; "
            f"loss {'n/a (no refit)' if r['loss'] is None else format(r['loss'], '.3e')}"
            f"{check}")
