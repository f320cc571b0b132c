"""A new PPO run whose actor starts from a trained agent (``init_policy``; fine-tuning).

The config key ``init_policy: PATH`` names a safe agent (``agent.json`` +
``policy.safetensors``, or a run folder holding one), e.g. a ``train.py distill``
student, or a shipped one by name (``distill_bc/seed_0``: a folder of
``agents/pretrained/``). ``{seed}`` in the value stands for the run's training seed, so
that one config fine-tunes each seed's own student (``init_policy:
distill_bc/seed_{seed}``; :func:`init_policy_for`).

Before the first rollout the new model's actor (``mlp_extractor.policy_net`` and
``action_net``) takes the agent's weights, and the training env's observation
statistics (``VecNormalize.obs_rms``) take the agent's, so the first rollout's
deterministic action equals the agent's. The observation statistics then stay fixed for
the whole run (:func:`freeze_obs_stats`, a resumed run too): the actor was fitted on
inputs scaled by them, and running statistics move its inputs under it (measured: a run
at a PPO step of 3e-6, whose actor weights moved by 0.4-3 %, saw the variance of some
normalised inputs grow 9-fold in 0.8M steps and its evaluation return fall from 614 to
311). The critic, the exploration noise (``log_std_init``) and the reward statistics
start new: the agent was fitted without a value or a log-std (DAgger regresses the mean
action only).

Everything that would make the copied actor see other inputs or act in other units is
refused before the run folder is written: another algorithm than an on-policy
actor-critic (PPO, PPO-Lagrangian) or a non-PPO agent, an agent of a residual hybrid,
other input features, another ``action_mode`` (rate vs increment), an observation
normalisation in one of the two and not in the other, and (when the model is built)
another layer layout or activation. A resumed run does not read the agent again: its
weights and statistics come from its own checkpoint.
"""

from __future__ import annotations

from pathlib import Path

from tether_gym.envs.actions import INCREMENT

from ..files.safe_format import AgentLoadError
from ..files.trained import TrainedAgent, pretrained_agents
from .config import ConfigError

__all__ = ["INIT_KEY", "SEED_FIELD", "ACTOR_MODULES", "check_init_policy", "init_policy_for",
           "agent_location", "check_agent_fits", "CONFIG_HINTS", "copy_actor", "warm_start",
           "init_path", "freeze_obs_stats", "FrozenRunningMeanStd"]

INIT_KEY = "init_policy"
"""The config key (one of :data:`~.config.RUN_KEYS`)."""
SEED_FIELD = "{seed}"
"""What :func:`init_policy_for` replaces by the run's training seed."""

ACTOR_MODULES = ("mlp_extractor.policy_net", "action_net")
"""The submodules of an ``ActorCriticPolicy`` copied from the agent (the actor)."""

_ON_POLICY = ("ppo", "ppo_lag")


def init_policy_for(value: str, seed: int) -> str:
    """``value`` with every ``{seed}`` replaced by ``seed`` (no other formatting)."""
    return value.replace(SEED_FIELD, str(int(seed)))


def agent_location(value) -> Path:
    """Where ``init_policy``'s agent is.

    The path as given when it exists, else, when its first part names a shipped agent
    (``distill_bc/seed_0``), that folder of ``agents/pretrained/``; else the path as given
    (loading it then says what is missing).
    """
    path = Path(value)
    if path.exists() or path.is_absolute() or not path.parts:
        return path
    shipped = pretrained_agents().get(path.parts[0])
    return path if shipped is None else shipped.joinpath(*path.parts[1:])


def _load(path, source: str) -> TrainedAgent:
    try:
        # safe files only: no pickle is ever opened here
        return TrainedAgent.load(agent_location(path))
    except AgentLoadError as exc:
        raise ConfigError(f"{source}: {INIT_KEY} {str(path)!r}: {exc}") from None


def check_init_policy(value, source: str, algo: str, features, env_kwargs: dict,
                      normalize, seed: int = 0) -> str:
    """Validate ``init_policy`` against the run; its value for this seed.

    Parameters
    ----------
    value : object
        The config's value (a path string, or a shipped agent's name and seed folder;
        ``{seed}`` stands for ``seed``).
    source : str
        The config file, for messages.
    algo : str
        The run's algorithm.
    features : FeatureSpec or None
        The run's input features.
    env_kwargs : dict
        The run's resolved env kwargs (``action_mode``).
    normalize : bool or dict
        The config's ``normalize``.
    seed : int
        The run's training seed.

    Returns
    -------
    str
        ``value`` with ``{seed}`` replaced (:func:`init_policy_for`), as the run records it.

    Raises
    ------
    ConfigError
        Naming the key, the value and what does not fit.
    """
    if not isinstance(value, str) or not value.strip():
        raise ConfigError(f"{source}: {INIT_KEY} {value!r}: must be the path of a trained "
                          "agent (a folder with agent.json, e.g. a train.py distill run)")
    if algo not in _ON_POLICY:
        raise ConfigError(f"{source}: {INIT_KEY} starts an on-policy actor-critic's actor; "
                          f"--algo {algo} is not one of {list(_ON_POLICY)}")
    value = init_policy_for(value, seed)
    agent = _load(value, source)
    check_agent_fits(agent, f"{source}: {INIT_KEY} {value!r}", features, env_kwargs,
                     normalize, CONFIG_HINTS)
    return value


CONFIG_HINTS = {"features": "set the config's features to the agent's",
                "action_mode": "set env_kwargs.action_mode: {theirs}"}
"""What a ``train.py`` config changes to fit an agent (:func:`check_agent_fits`)."""


def check_agent_fits(agent: TrainedAgent, what: str, features, env_kwargs: dict, normalize,
                     hints: dict[str, str]) -> None:
    """Refuse an agent whose actor would see other inputs or act in other units than the run's.

    Parameters
    ----------
    agent : TrainedAgent
        The agent that is to start the run's actor.
    what : str
        Names the agent, for messages.
    features : FeatureSpec or None
        The run's input features.
    env_kwargs : dict
        The run's env kwargs (``action_mode``).
    normalize : bool or dict
        The run's ``normalize`` (observation normalisation on or off).
    hints : dict
        ``"features"`` and ``"action_mode"``: what the user changes to fit the agent
        (``{theirs}`` in the second stands for the agent's action mode).

    Raises
    ------
    ConfigError
        For another algorithm than ppo, the residual of a hybrid, other input features,
        another action mode, or normalisation in one and not in the other.
    """
    if agent.algo != "ppo":
        raise ConfigError(f"{what}: a {agent.algo} agent; only a ppo agent's actor "
                          "(ActorCriticPolicy) can start the run")
    if agent.hybrid is not None:
        raise ConfigError(f"{what}: the residual of a hybrid ({agent.hybrid}); give an agent "
                          "that acts alone")
    if agent.features != features:
        raise ConfigError(f"{what}: its input features {agent.features} differ from the "
                          f"run's {features} ({hints['features']})")
    mine = env_kwargs.get("action_mode", INCREMENT)
    theirs = agent.env_kwargs.get("action_mode", INCREMENT)
    if mine != theirs:
        raise ConfigError(f"{what}: trained with action_mode={theirs!r}, the run has "
                          f"{mine!r} ({hints['action_mode'].format(theirs=theirs)})")
    norm_obs = normalize is True or (isinstance(normalize, dict)
                                     and normalize.get("norm_obs", True))
    if (agent.norm is not None) != bool(norm_obs):
        have = "normalises" if agent.norm is not None else "does not normalise"
        raise ConfigError(f"{what}: the agent {have} its observations, the run's normalize "
                          f"is {normalize!r}; they must agree")


def copy_actor(theirs, mine, what: str, widths: str) -> None:
    """Copy ``theirs``' actor (:data:`ACTOR_MODULES`) into the policy ``mine``.

    Both are stable-baselines3 ``ActorCriticPolicy`` objects; ``what`` names the source
    and ``widths`` the setting that fixes ``mine``'s layer widths, for messages.

    Raises
    ------
    ConfigError
        If the activation or a copied layer's shape differs.
    """
    import torch

    if theirs.activation_fn is not mine.activation_fn:
        raise ConfigError(f"{what}: activation {theirs.activation_fn.__name__}, the run's "
                          f"policy has {mine.activation_fn.__name__}")
    for name in ACTOR_MODULES:
        src, dst = theirs.get_submodule(name).state_dict(), mine.get_submodule(name)
        shapes = {k: tuple(v.shape) for k, v in src.items()}
        want = {k: tuple(v.shape) for k, v in dst.state_dict().items()}
        if shapes != want:
            raise ConfigError(f"{what}: its {name} has layers {shapes}, the run's policy "
                              f"{want} (set {widths} to the agent's widths)")
        with torch.no_grad():
            dst.load_state_dict(src, strict=True)


def warm_start(model, venv, path) -> TrainedAgent:
    """Copy the agent at ``path``'s actor and observation statistics into a new model.

    Parameters
    ----------
    model : stable_baselines3 PPO
        The new model (its ``policy`` an ``ActorCriticPolicy``).
    venv : VecEnv
        Its training env: a ``VecNormalize`` whose ``obs_rms`` takes the agent's
        statistics when the agent has them.
    path : path-like
        The agent (checked by :func:`check_init_policy`).

    Returns
    -------
    TrainedAgent
        The agent the weights came from.

    Raises
    ------
    ConfigError
        If a copied layer's shape, the activation or the normalisation's clip differs.
    """
    agent = _load(path, INIT_KEY)
    what = f"{INIT_KEY} {str(path)!r}"
    copy_actor(agent.model, model.policy, what, "policy_kwargs.net_arch.pi")
    if agent.norm is not None:
        rms = venv.obs_rms
        if rms.mean.shape != agent.norm.mean.shape:
            raise ConfigError(f"{what}: {agent.norm.mean.shape[0]} normalised inputs, the "
                              f"run has {rms.mean.shape[0]}")
        for key in ("clip_obs", "epsilon"):
            if float(getattr(venv, key)) != float(getattr(agent.norm, key)):
                raise ConfigError(f"{what}: {key} {getattr(agent.norm, key)}, the run's "
                                  f"normalize gives {getattr(venv, key)}")
        rms.mean = agent.norm.mean.astype(float).copy()
        rms.var = agent.norm.var.astype(float).copy()
        rms.count = float(agent.norm.count)
    return agent


def init_path(run: dict) -> Path | None:
    """The run's ``init_policy`` as a path (None when the config has none)."""
    value = run.get(INIT_KEY)
    return None if value is None else agent_location(value)


def _running_mean_std():
    from stable_baselines3.common.running_mean_std import RunningMeanStd
    return RunningMeanStd


class FrozenRunningMeanStd(_running_mean_std()):  # type: ignore[misc]
    """``RunningMeanStd`` whose statistics no longer change (``update`` does nothing)."""

    def update(self, arr) -> None:  # noqa: D102 - the parent's, made a no-op
        return None


def freeze_obs_stats(venv) -> None:
    """Fix a ``VecNormalize``'s observation statistics at their current values.

    The statistics object is replaced by a :class:`FrozenRunningMeanStd` with the same
    mean, variance and count (saved and reloaded as usual); a non-normalising env is
    left alone.
    """
    rms = getattr(venv, "obs_rms", None)
    if rms is None or isinstance(rms, FrozenRunningMeanStd):
        return
    frozen = FrozenRunningMeanStd(shape=rms.mean.shape)
    frozen.mean, frozen.var, frozen.count = rms.mean.copy(), rms.var.copy(), rms.count
    venv.obs_rms = frozen
