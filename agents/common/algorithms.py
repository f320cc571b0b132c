"""The learning algorithms that train.py trains and agent files hold: one table, plain data.

Everything that depends on which algorithm an agent or a run uses reads it here: the
class ``train.py --algo NAME`` trains (:attr:`Algorithm.model`), the library class that
reads its pickled model (:attr:`Algorithm.library_model`), on- or off-policy, the policy
class recorded in ``agent.json`` and the part of it whose weights are saved, the
``net_arch`` keys, the ``policy_kwargs`` and constructor keywords a config or an agent
file may hold, the bounds of the counts that size the networks, and the install extra.
Classes are named as ``"module:Class"`` strings, never imported here: this module imports
nothing beyond the standard library (it is the lowest layer, read by files/ and training/).

Adding an algorithm is one row of :data:`ALGORITHMS` plus its config
(``agents/configs/<name>.yml``) and a test (docs/architecture.md, "where a change goes").
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

__all__ = ["Algorithm", "ALGORITHMS", "ALGOS", "algorithm", "install_hint", "split_name"]

_OFF_POLICY = frozenset({
    "learning_rate", "buffer_size", "learning_starts", "batch_size", "tau", "gamma",
    "train_freq", "gradient_steps", "action_noise", "replay_buffer_class",
    "replay_buffer_kwargs", "optimize_memory_usage", "n_steps", "stats_window_size",
    "policy_kwargs"})
_SAC = _OFF_POLICY | {"ent_coef", "target_update_interval", "target_entropy", "use_sde",
                      "sde_sample_freq", "use_sde_at_warmup"}
_CAPS = frozenset({"caps_temporal", "caps_spatial", "caps_magnitude", "caps_sigma"})
"""CapsMixin's smoothness weights (tether_gym_agents.training.caps)."""
_POLICY_COMMON = frozenset({"net_arch", "activation_fn", "features_extractor_class",
                            "features_extractor_kwargs", "normalize_images",
                            "optimizer_kwargs", "share_features_extractor"})
_SAC_POLICY = _POLICY_COMMON | {"use_sde", "log_std_init", "use_expln", "clip_mean",
                                "n_critics"}


@dataclass(frozen=True)
class Algorithm:
    """One learning algorithm: how it is trained, saved, loaded and checked.

    Attributes
    ----------
    name : str
        ``train.py --algo`` value and ``agent.json``'s ``algo`` (``"ppo"``, ...).
    model : str
        ``"module:Class"`` of the class ``train.py`` trains.
    library_model : str
        ``"module:Class"`` of the library's class that loads a pickled model of it.
    on_policy : bool
        True for rollout-based algorithms (PPO); False for replay-buffer ones, whose
        buffer is saved with each checkpoint.
    policy : str
        The stable-baselines3 policy class name recorded in ``agent.json``
        (``policy_class``).
    policy_module : str
        The module that defines :attr:`policy` (looked up by name, never from a file).
    weights : str
        The part of the policy whose ``state_dict`` an agent file holds: ``"policy"``
        (all of it) or ``"actor"`` (what ``predict`` uses; the critics are not needed).
    net_keys : tuple of str
        The keys of a mapping ``net_arch``: the actor's, then the critic's.
    policy_kwargs : frozenset of str
        The ``policy_kwargs`` keys a config or an agent file may hold.
    hyperparams : frozenset of str
        The constructor keywords of :attr:`model` a config may set (``policy_kwargs``
        included; train.py's own keys are not algorithm keywords).
    extra : str
        The install extra of tether_gym that provides the algorithm (``pip install -e
        ".[extra]"`` in a clone).
    requirement : str
        The pip requirement of the library that defines it (the extra lists it).
    stochastic_actor : bool
        The actor is a Gaussian with ``log_std`` (PPO, SAC, TQC); False for a
        deterministic actor (TD3), whose exploration is action noise.
    critic : str
        ``"value"``: one V(s) network (PPO); ``"q"``: ``n_critics`` Q(s, a) networks.
    actor_outputs : int
        Outputs of the actor's last layer per action entry: 1 (a mean, or TD3's
        action) or 2 (SAC's/TQC's mean and log_std heads).
    copies : tuple of int
        How many copies of (actor, critics) the policy builds (targets included).
    defaults : Mapping[str, int]
        The policy's defaults of the counts that size its networks (``n_critics``,
        ``n_quantiles``), used when an agent file or config does not set them.
    bounds : Mapping[str, tuple of int]
        The allowed range [low, high] of each such count in ``policy_kwargs``.
    action_noise : bool
        Whether the algorithm takes exploration noise on its actions (``noise_type``
        and ``noise_std`` in a config).
    """

    name: str
    model: str
    library_model: str
    on_policy: bool
    policy: str
    policy_module: str
    weights: str
    net_keys: tuple[str, ...]
    policy_kwargs: frozenset[str]
    hyperparams: frozenset[str]
    extra: str = "train"
    requirement: str = "stable-baselines3>=2.4"
    stochastic_actor: bool = True
    critic: str = "q"
    actor_outputs: int = 1
    copies: tuple[int, int] = (1, 2)
    defaults: Mapping[str, int] = field(default_factory=lambda: MappingProxyType({}))
    bounds: Mapping[str, tuple[int, int]] = field(
        default_factory=lambda: MappingProxyType({}))
    action_noise: bool = False

    @property
    def package(self) -> str:
        """The top-level package :attr:`model` comes from (what a missing install lacks)."""
        return split_name(self.library_model)[0].split(".")[0]

    def install(self) -> str:
        """How to install what the algorithm needs (the pip command of its extra)."""
        return install_hint(self.extra, self.requirement)


def split_name(ref: str) -> tuple[str, str]:
    """``("module", "Class")`` of a ``"module:Class"`` reference."""
    module, _, name = ref.partition(":")
    return module, name


def install_hint(extra: str, requirement: str) -> str:
    """The pip command of tether_gym's ``extra`` (from a clone), or of ``requirement`` alone."""
    return (f'pip install -e ".[{extra}]" in a clone of tether_gym (or pip install '
            f'"{requirement}")')


def _frozen(**items) -> Mapping:
    return MappingProxyType(dict(items))


_CRITIC_BOUNDS = (1, 16)
"""Most Q networks: SB3 builds 2; REDQ-style ensembles use up to 10."""

_PPO_POLICY = _POLICY_COMMON | {"ortho_init", "use_sde", "log_std_init", "full_std",
                                "use_expln", "squash_output"}
_PPO = frozenset({
    "learning_rate", "n_steps", "batch_size", "n_epochs", "gamma", "gae_lambda",
    "clip_range", "clip_range_vf", "normalize_advantage", "ent_coef", "vf_coef",
    "max_grad_norm", "use_sde", "sde_sample_freq", "rollout_buffer_class",
    "rollout_buffer_kwargs", "target_kl", "stats_window_size", "policy_kwargs"})
_LAGRANGE = frozenset({"cost_limit", "lagrange_lr", "lagrange_init", "failure_cost"})
"""PPOLagrangian's constraint settings (tether_gym_agents.training.lagrangian)."""

ALGORITHMS: Mapping[str, Algorithm] = MappingProxyType({a.name: a for a in (
    Algorithm(
        name="ppo", model="stable_baselines3:PPO", library_model="stable_baselines3:PPO",
        on_policy=True, policy="ActorCriticPolicy",
        policy_module="stable_baselines3.common.policies", weights="policy",
        net_keys=("pi", "vf"),
        policy_kwargs=_PPO_POLICY, hyperparams=_PPO,
        critic="value", actor_outputs=1, copies=(1, 1)),
    Algorithm(
        name="ppo_lag", model="tether_gym_agents.training.lagrangian:PPOLagrangian",
        library_model="tether_gym_agents.training.lagrangian:PPOLagrangian",
        on_policy=True, policy="ActorCriticPolicy",
        policy_module="stable_baselines3.common.policies", weights="policy",
        net_keys=("pi", "vf"), policy_kwargs=_PPO_POLICY, hyperparams=_PPO | _LAGRANGE,
        critic="value", actor_outputs=1, copies=(1, 1)),
    Algorithm(
        name="sac", model="tether_gym_agents.training.caps:CapsSAC",
        library_model="stable_baselines3:SAC", on_policy=False, policy="SACPolicy",
        policy_module="stable_baselines3.sac.policies", weights="actor",
        net_keys=("pi", "qf"), policy_kwargs=_SAC_POLICY, hyperparams=_SAC | _CAPS,
        actor_outputs=2, copies=(1, 2), defaults=_frozen(n_critics=2),
        bounds=_frozen(n_critics=_CRITIC_BOUNDS), action_noise=True),
    Algorithm(
        name="tqc", model="tether_gym_agents.training.caps:CapsTQC",
        library_model="sb3_contrib:TQC", on_policy=False, policy="TQCPolicy",
        policy_module="sb3_contrib.tqc.policies", weights="actor",
        net_keys=("pi", "qf"), policy_kwargs=_SAC_POLICY | {"n_quantiles"},
        hyperparams=_SAC | _CAPS | {"top_quantiles_to_drop_per_net"}, extra="tqc",
        requirement="sb3-contrib>=2.4",
        actor_outputs=2, copies=(1, 2), defaults=_frozen(n_critics=2, n_quantiles=25),
        bounds=_frozen(n_critics=_CRITIC_BOUNDS, n_quantiles=(1, 256)), action_noise=True),
    Algorithm(
        name="td3", model="stable_baselines3:TD3", library_model="stable_baselines3:TD3",
        on_policy=False, policy="TD3Policy", policy_module="stable_baselines3.td3.policies",
        weights="actor", net_keys=("pi", "qf"), policy_kwargs=_POLICY_COMMON | {"n_critics"},
        hyperparams=_OFF_POLICY | {"policy_delay", "target_policy_noise",
                                   "target_noise_clip"},
        stochastic_actor=False, actor_outputs=1, copies=(2, 2),
        defaults=_frozen(n_critics=2), bounds=_frozen(n_critics=_CRITIC_BOUNDS),
        action_noise=True),
)})
"""Every algorithm, by name."""

ALGOS: tuple[str, ...] = tuple(sorted(ALGORITHMS))
"""The names of :data:`ALGORITHMS`, sorted (``train.py --algo``'s choices)."""


def algorithm(name) -> Algorithm:
    """The row of ``name`` (``"ppo"``, ``"sac"``, ``"tqc"``, ``"td3"``; case-insensitive).

    Raises
    ------
    TypeError
        For a name that is not a string (e.g. ``["ppo"]`` read from a file).
    ValueError
        For an unknown name, listing the valid ones.
    """
    if not isinstance(name, str):
        raise TypeError(f"algorithm {name!r} must be a string, one of {list(ALGOS)}")
    row = ALGORITHMS.get(name.lower())
    if row is None:
        raise ValueError(f"algorithm {name!r} is not one of {list(ALGOS)}")
    return row
