"""The one policy registry: every name ``evaluate.py`` accepts resolves here.

A policy name is, in the order tried:

1. a **registered policy**: the built-in baselines (see :data:`BASELINES`; the
   sliding-mode law of the paper, alone and behind the model-based safety filter of
   :mod:`tether_gym.safety`, open-loop laws, the one-step ``predictive`` law and the
   nonlinear ``mpc`` (needs CasADi; run only when named, :data:`OPT_IN`); all
   commanding reel rates, ``action_mode="rate"``) and whatever :func:`register_policy`
   added, in user code or in a plugin package (entry-point group
   :data:`ENTRY_POINT_GROUP`, loaded the first time a name is not found);
2. ``filtered:AGENT`` (e.g. ``filtered:distilled``): a trained agent that commands reel
   rates, behind the safety filter of ``smc_filtered`` (predicting with the scenario's
   nominal model); ``handover:AGENT`` (e.g. ``handover:ppo``): the hybrid
   :class:`~tether_gym_agents.hybrids.policies.HandoverPolicy` of a trained agent, which
   steers the transient and hands over to the sliding-mode law inside its boundary
   layer, all of it behind the safety filter;
3. a **shipped agent** (``ppo``, ...: a folder of ``agents/pretrained/``);
4. a **path**: a run folder or model file written by ``train.py``, or a folder of seed
   run folders (``runs/ppo/seed_0/``, ``seed_1/``, ...), which is one policy with one
   run per folder.

An agent whose files record a ``hybrid`` (trained with a ``residual`` config) is of kind
``hybrid``: it runs as the residual of
:class:`~tether_gym_agents.hybrids.policies.ResidualPolicy` around the sliding-mode law
(and the filter, when it was trained with one). The model-based parts of every hybrid,
like ``smc`` and ``smc_filtered``, design on the scenario's nominal model
(:mod:`.nominal`). Anything else is a ValueError that lists the valid names.

:func:`resolve_policy` turns a name into a :class:`PolicySpec`, which builds one
``predict`` object per episode for a scenario's env (:meth:`PolicySpec.policies`).
"""

from __future__ import annotations

import difflib
import functools
import re
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from enum import Enum
from importlib import metadata
from pathlib import Path
from types import MappingProxyType

from ..baselines.open_loop import PeriodicReel, RandomPolicy, ZeroStateReel
from ..common.obs import RATE_ENV_KWARGS, with_rate_mode
from ..files import TrainedAgent, hybrid_of, pretrained_agents, seed_runs
from . import nominal
from .scenarios import Scenario

__all__ = ["PolicyKind", "PolicyEntry", "PolicySpec", "AgentForm", "register_policy",
           "resolve_policy", "make_policy", "default_policies",
           "shipped_agents", "load_plugins", "BASELINES", "OPT_IN", "HANDOVER",
           "HANDOVER_OF", "FILTERED", "FILTERED_OF", "ENTRY_POINT_GROUP", "ACTION_KEYS",
           "OBSERVATION_KEYS", "TRAINED_ON_KEYS", "trained_on", "check_given_env_kwargs"]

HANDOVER = "handover:"
"""Prefix of a handover hybrid's policy name: ``handover:`` + a trained agent's name."""
HANDOVER_OF = ("ppo",)
"""Shipped agents whose handover hybrid ``python evaluate.py`` benchmarks by default."""
FILTERED = "filtered:"
"""Prefix of a filtered agent's policy name: ``filtered:`` + a rate-mode trained agent."""
FILTERED_OF = ("distill_ppo",)
"""Shipped rate-mode agents that ``python evaluate.py`` also benchmarks behind the safety
filter by default (issue 36's distilled row: the filter's cost counts in its ms/step)."""
ENTRY_POINT_GROUP = "tether_gym_agents.policies"
"""Entry-point group of plugin packages: each entry names a function that registers the
package's policies with :func:`register_policy` (called without arguments)."""
ACTION_KEYS = ("action_mode", "increment_gain")
"""Env arguments that define what a policy's action means."""
OBSERVATION_KEYS = ("observe_params",)
"""Env arguments that define what a policy's observation holds."""
TRAINED_ON_KEYS = ("n_bodies", "amplitude", "frequency", "control_step")
"""Env arguments that define the chain and the task a trained agent was trained on: an
evaluation runs every scenario, for every policy, with the values its agents recorded
(under the scenario's own arguments and ``--env-kwargs``; see :func:`trained_on`)."""
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_.+\-]*\Z")


class PolicyKind(Enum):
    """What a policy is, as recorded in results.json."""

    BASELINE = "baseline"
    RL = "rl"
    HYBRID = "hybrid"  # learning combined with a model-based law (residual, handover)

    @classmethod
    def of(cls, value) -> PolicyKind:
        """``value`` as a PolicyKind (a member or its string value)."""
        if isinstance(value, cls):
            return value
        try:
            return cls(value)
        except ValueError:
            raise ValueError(f"kind={value!r} must be one of "
                             f"{[k.value for k in cls]} or a PolicyKind") from None


def _rate_mode() -> dict:
    """Env arguments of the policies that command reel rates (baselines, hybrids)."""
    return dict(RATE_ENV_KWARGS)


# --------------------------------------------------------------------------- #
# registered policies
# --------------------------------------------------------------------------- #
@dataclass(frozen=True)
class PolicyEntry:
    """A registered policy: how to build it for a scenario's env, and that env.

    Parameters
    ----------
    name : str
        The policy's name in tables, results.json and on the command line.
    factory : callable
        ``factory(env, scenario)`` returns an object with stable-baselines3's
        ``predict(obs, state=None, episode_start=None, deterministic=True) ->
        (actions, state)``; with ``per_seed``, ``factory(env, scenario, seed)``.
    kind : PolicyKind or str
        ``"baseline"``, ``"rl"`` or ``"hybrid"``, as reported.
    env_kwargs : mapping
        Env arguments the policy needs on every scenario, such as
        ``{"action_mode": "rate"}`` (they override the scenario's).
    per_seed : bool
        Build one object per episode, given the episode's env seed (a stochastic
        policy seeded per episode, or one with per-episode memory). Otherwise one object
        drives every episode of a scenario, one observation per ``predict`` call.
    """

    name: str
    factory: Callable
    kind: PolicyKind = PolicyKind.BASELINE
    env_kwargs: Mapping = field(default_factory=dict)
    per_seed: bool = False

    def __post_init__(self) -> None:
        _check_name(self.name)
        if not callable(self.factory):
            raise TypeError(f"policy {self.name!r}: factory must be callable as "
                            f"factory(env, scenario), got {type(self.factory).__name__} "
                            f"{self.factory!r}")
        if not isinstance(self.per_seed, bool):
            raise TypeError(f"policy {self.name!r}: per_seed must be True or False, got "
                            f"{self.per_seed!r}")
        object.__setattr__(self, "kind", PolicyKind.of(self.kind))
        object.__setattr__(self, "env_kwargs",
                           MappingProxyType(_checked_env_kwargs(self.name, self.env_kwargs)))

    def build(self, env, scenario: Scenario, seeds: list[int]) -> list:
        """One ``predict`` object per seed (the same object unless ``per_seed``)."""
        if self.per_seed:
            return [self.factory(env, scenario, s) for s in seeds]
        return [self.factory(env, scenario)] * len(seeds)


def _check_name(name) -> None:
    if not isinstance(name, str) or not _NAME.match(name):
        raise ValueError(f"policy name {name!r} must be a non-empty string of letters, "
                         "digits and '_', '-', '.', '+' that starts with a letter or '_' "
                         "(no ':' and nothing that looks like a path)")


def _checked_env_kwargs(name: str, env_kwargs) -> dict:
    """A copy of ``env_kwargs`` after checking its keys are the env's arguments."""
    from tether_gym.envs import EnvConfig

    if not isinstance(env_kwargs, Mapping):
        raise TypeError(f"policy {name!r}: env_kwargs must be a dict of env arguments, got "
                        f"{type(env_kwargs).__name__} {env_kwargs!r}")
    valid = EnvConfig.names()
    unknown = [k for k in env_kwargs if k not in valid]
    if unknown:
        raise ValueError(f"policy {name!r}: env_kwargs {unknown} are not arguments of "
                         f"gym.make(tether_gym.ENV_ID, ...); valid: {valid}")
    return dict(env_kwargs)


def _zero(env, scenario: Scenario):
    return ZeroStateReel.for_env(env)


def _periodic(env, scenario: Scenario):
    return PeriodicReel.for_env(env)


def _random(env, scenario: Scenario, seed: int):
    return RandomPolicy(env, seed=seed)


_BUILT_IN = (
    PolicyEntry("smc", nominal.nominal_smc, env_kwargs=_rate_mode()),
    PolicyEntry("smc_filtered", nominal.filtered_smc, env_kwargs=_rate_mode()),
    PolicyEntry("zero", _zero, env_kwargs=_rate_mode()),
    PolicyEntry("periodic", _periodic, env_kwargs=_rate_mode()),
    # a generator per episode, seeded with its env seed: its actions do not depend on
    # the other episodes
    PolicyEntry("random", _random, env_kwargs=_rate_mode(), per_seed=True),
    # one-step predictive law and nonlinear MPC on the nominal model, both filtered; the
    # MPC keeps its last plan as a warm start: one object per episode
    PolicyEntry("predictive", nominal.nominal_predictive, env_kwargs=_rate_mode()),
    PolicyEntry("mpc", nominal.nominal_mpc, env_kwargs=_rate_mode(), per_seed=True),
)
BASELINES = tuple(e.name for e in _BUILT_IN)
"""The built-in baselines (``python evaluate.py`` benchmarks them by default, except
those in :data:`OPT_IN`)."""
OPT_IN = ("mpc",)
"""Built-in baselines that ``python evaluate.py`` runs only when named: ``mpc`` needs the
optional CasADi and takes minutes on the default suite (``evaluate.py mpc``)."""
_REGISTRY: dict[str, PolicyEntry] = {e.name: e for e in _BUILT_IN}
_PLUGINS_LOADED: list[bool] = []


def register_policy(name: str, factory: Callable, kind: PolicyKind | str = "baseline",
                    env_kwargs: Mapping | None = None, *, per_seed: bool = False,
                    overwrite: bool = False) -> PolicyEntry:
    """Register a policy so that ``evaluate.py NAME`` and ``evaluate([NAME])`` score it.

    Parameters
    ----------
    name : str
        Letters, digits, ``_``, ``-``, ``.``, ``+``; not already registered nor a
        shipped agent's name (unless ``overwrite``).
    factory : callable
        ``factory(env, scenario)`` -> an object with stable-baselines3's
        ``predict(obs, state=None, episode_start=None, deterministic=True)``; ``env`` is
        a TetherLibration env built with the scenario's and the policy's env arguments,
        ``scenario`` the :class:`~.scenarios.Scenario` (its ``nominal`` model under
        model mismatch). With ``per_seed``: ``factory(env, scenario, seed)``.
    kind : PolicyKind or str
        ``"baseline"`` (default), ``"rl"`` or ``"hybrid"``, as reported in results.json.
    env_kwargs : dict or None
        Env arguments the policy needs, e.g. ``{"action_mode": "rate"}`` for a policy
        that commands reel rates (None: the env's defaults).
    per_seed : bool
        One object per episode, given its seed (see :class:`PolicyEntry`).
    overwrite : bool
        Replace a registered policy of the same name (or shadow a shipped agent).

    Returns
    -------
    PolicyEntry
        The registered entry.

    Raises
    ------
    ValueError
        On a malformed or taken name, an unknown kind or env argument.
    TypeError
        When ``factory`` is not callable or ``env_kwargs`` is not a dict.
    """
    entry = PolicyEntry(name, factory, PolicyKind.of(kind),
                        {} if env_kwargs is None else env_kwargs, per_seed)
    if not isinstance(overwrite, bool):
        raise TypeError(f"overwrite must be True or False, got {overwrite!r}")
    if not overwrite:
        if name in _REGISTRY:
            raise ValueError(f"policy {name!r} is already registered (as "
                             f"{_REGISTRY[name].factory!r}); pass overwrite=True to "
                             "replace it")
        if name in pretrained_agents():
            raise ValueError(f"policy {name!r} is a shipped agent's name; pass "
                             "overwrite=True to shadow it")
    _REGISTRY[name] = entry
    return entry


def load_plugins() -> None:
    """Load the plugin packages' policies (entry-point group :data:`ENTRY_POINT_GROUP`), once.

    Each entry point names a callable that registers policies when called without
    arguments (or a module that registers them when imported). A plugin that fails is
    skipped with a RuntimeWarning that names it.
    """
    if _PLUGINS_LOADED:
        return
    _PLUGINS_LOADED.append(True)
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        try:
            hook = ep.load()
            if callable(hook):
                hook()
        except Exception as exc:  # a broken plugin must not break evaluate.py
            warnings.warn(f"policy plugin {ep.name!r} ({ep.value}) failed to load and is "
                          f"skipped: {exc!r}", RuntimeWarning, stacklevel=2)


# --------------------------------------------------------------------------- #
# trained agents
# --------------------------------------------------------------------------- #
@functools.cache  # a default config per key, not one per run of every agent
def _env_default(key: str):
    """The env's default of the ``gym.make`` argument ``key``."""
    from tether_gym.envs.config import FLAT_NAMES, EnvConfig

    part, attr = FLAT_NAMES[key]
    return getattr(getattr(EnvConfig.from_kwargs(), part), attr)


def _recorded(name: str, agents: list, keys: tuple[str, ...]) -> dict:
    """The runs' recorded env arguments among ``keys``; they must agree.

    An action or observation argument a run did not record is the env's default, which
    it was trained with (before, a run of the default increment mode evaluated with
    ``--env-kwargs action_mode=rate`` ran in the rate mode).
    """
    defaults = ACTION_KEYS + OBSERVATION_KEYS
    recorded = [{k: agent.env_kwargs[k] if k in agent.env_kwargs else _env_default(k)
                 for k in keys if k in agent.env_kwargs or k in defaults}
                for agent in agents]
    if any(r != recorded[0] for r in recorded):
        raise ValueError(f"policy {name!r}: its runs were trained with different "
                         f"action or observation settings {recorded}")
    return recorded[0]


def _alone(agent, env, scenario: Scenario):
    return agent


def _alone_env_kwargs(name: str, agents: list) -> dict:
    """A trained agent runs in the action mode it was trained in and sees what it saw."""
    return _recorded(name, agents, ACTION_KEYS + OBSERVATION_KEYS)


def _residual_env_kwargs(name: str, agents: list) -> dict:
    """A residual hybrid commands reel rates; its residual must have been trained so."""
    for agent in agents:
        with_rate_mode(agent.env_kwargs, f"policy {name!r}: the residual of run {agent.path}")
    return _rate_mode()


def _handover_env_kwargs(name: str, agents: list) -> dict:
    """A handover hybrid commands reel rates; its env gives its agent's observation."""
    return {**_rate_mode(), **_recorded(name, agents, OBSERVATION_KEYS)}


def _filtered_env_kwargs(name: str, agents: list) -> dict:
    """A filtered agent commands reel rates (trained so) and sees its own observation."""
    from tether_gym.envs import EnvConfig

    for agent in agents:
        mode = agent.env_kwargs.get("action_mode", EnvConfig.from_kwargs().action.mode)
        if mode != RATE_ENV_KWARGS["action_mode"]:
            raise ValueError(f"policy {name!r}: the safety filter corrects reel-rate commands, "
                             f"but run {agent.path} was trained with action_mode={mode!r}; "
                             "only an agent trained with action_mode='rate' can run filtered")
    return {**_rate_mode(), **_recorded(name, agents, OBSERVATION_KEYS)}


def _default_n_bodies() -> int:
    from tether_gym.envs import EnvConfig

    return EnvConfig.from_kwargs().n_bodies


def _recorded_by_agent(specs: list) -> dict[str, dict]:
    """``{policy name: {key: value}}`` of :data:`TRAINED_ON_KEYS` each agent recorded.

    A missing ``n_bodies`` is the env's default; the runs of one policy must agree.
    """
    n_default = _default_n_bodies()
    recorded = {}
    for spec in specs:
        if spec.form is None:
            continue
        spec.load()
        values = _recorded(spec.name, spec.agents, TRAINED_ON_KEYS)
        recorded[spec.name] = {"n_bodies": n_default, **values}
    return recorded


def check_given_env_kwargs(spec, given: Mapping) -> None:
    """Refuse env arguments the user gave that the policy replaces with its own.

    A policy's :attr:`PolicySpec.env_kwargs` (the baselines' reel-rate mode, a trained
    agent's action mode, gain and observation) win over ``--env-kwargs``; a given value
    that differs would be dropped without a word, so it is a ValueError naming both.
    """
    for key, value in given.items():
        own = spec.env_kwargs.get(key, value)
        if own != value:
            raise ValueError(f"--env-kwargs {key}={value!r}: policy {spec.name!r} runs with "
                             f"{key}={own!r} (what its actions and observations mean); "
                             f"leave {key} out of --env-kwargs")


def trained_on(specs: list, overrides: Mapping | None = None) -> dict:
    """The env arguments of :data:`TRAINED_ON_KEYS` the trained agents of ``specs`` share.

    An evaluation builds every scenario's env on top of them, so that an agent trained
    with ``--env-kwargs n_bodies=4 amplitude=0.3`` is evaluated, beside the baselines
    (which run on any N), on the chain and task it was trained on. A key given in
    ``overrides`` (``--env-kwargs``) is left out (what the user types wins).

    Raises
    ------
    ValueError
        When the agents were trained on different values of a key that ``overrides``
        does not set, or when an agent cannot run on the requested ``n_bodies`` (its
        network is sized for its own N); the message names the policy, the N it was
        trained on and the N asked for.
    """
    overrides = dict(overrides or {})
    recorded = _recorded_by_agent(specs)
    base: dict = {}
    for key in TRAINED_ON_KEYS:
        if key in overrides:
            continue
        values = {name: rec.get(key) for name, rec in recorded.items()}
        distinct = {repr(v) for v in values.values()}
        if len(distinct) > 1:
            given = ", ".join(f"{name!r} {'the default' if v is None else v}"
                              for name, v in values.items())
            fix = ("a network runs only on the chain it was trained on" if key == "n_bodies"
                   else f"or give --env-kwargs {key}=VALUE to run all of them on one")
            raise ValueError(f"the policies were trained on different {key}: {given}; "
                             f"evaluate them in separate calls ({fix})")
        if values and next(iter(values.values())) is not None:
            base[key] = next(iter(values.values()))
    n_bodies = overrides.get("n_bodies", base.get("n_bodies", _default_n_bodies()))
    for name, rec in recorded.items():
        if rec["n_bodies"] != n_bodies:
            raise ValueError(
                f"policy {name!r} was trained on n_bodies={rec['n_bodies']} "
                f"({rec['n_bodies'] - 1} tethers) and cannot run on n_bodies={n_bodies!r}: "
                "its network is sized for its own chain; leave n_bodies out of "
                f"--env-kwargs to evaluate it on n_bodies={rec['n_bodies']}, or train an "
                f"agent with train.py --env-kwargs n_bodies={n_bodies!r}")
    if base.get("n_bodies") == _default_n_bodies():
        del base["n_bodies"]
    return base


@dataclass(frozen=True)
class AgentForm:
    """How the runs of a trained agent act: alone, as a residual, or handing over.

    ``wrap(agent, env, scenario)`` gives the ``predict`` object of one run;
    ``env_kwargs(name, agents)`` the env arguments of the policy (:data:`ACTION_KEYS`
    and :data:`OBSERVATION_KEYS` as the form needs; the scenario sets the rest).
    """

    kind: PolicyKind
    residual: bool
    """Its agents record a ``hybrid`` (they act only inside a ResidualPolicy)."""
    wrap: Callable
    env_kwargs: Callable


ALONE = AgentForm(PolicyKind.RL, False, _alone, _alone_env_kwargs)
RESIDUAL = AgentForm(PolicyKind.HYBRID, True, nominal.residual, _residual_env_kwargs)
HANDOVER_FORM = AgentForm(PolicyKind.HYBRID, False, nominal.handover, _handover_env_kwargs)
FILTERED_FORM = AgentForm(PolicyKind.HYBRID, False, nominal.filtered, _filtered_env_kwargs)


@dataclass
class PolicySpec:
    """A policy to evaluate: its name, kind and training runs.

    Exactly one of ``entry`` (a registered policy, one "run": ``runs == [None]``) and
    ``form`` (a trained agent, one path per training run in ``runs``, loaded once by
    :meth:`load`) is set.
    """

    name: str
    kind: PolicyKind
    runs: list
    entry: PolicyEntry | None = None
    form: AgentForm | None = None
    agents: list = field(default_factory=list)
    allow_pickle: bool = False

    def __post_init__(self) -> None:
        if (self.entry is None) == (self.form is None):
            raise ValueError(f"policy {self.name!r}: give exactly one of entry (a registered "
                             f"policy) and form (a trained agent), got entry={self.entry!r}, "
                             f"form={self.form!r}")

    @property
    def handover(self) -> bool:
        """A :class:`~tether_gym_agents.hybrids.policies.HandoverPolicy` of its runs' agents."""
        return self.form is HANDOVER_FORM

    @property
    def env_kwargs(self) -> dict:
        """Env arguments the policy needs on every scenario (its action mode and observation)."""
        if self.entry is not None:
            return dict(self.entry.env_kwargs)
        self.load()
        return self._form().env_kwargs(self.name, self.agents)

    @property
    def n_runs(self) -> int:
        """Number of training runs (1 for a registered policy)."""
        return len(self.runs)

    def load(self) -> None:
        """Load every run's agent with ``TrainedAgent.load`` (no-op for registered ones)."""
        if self.form is None or self.agents:
            return
        self.agents = [TrainedAgent.load(path, allow_pickle=self.allow_pickle)
                       for path in self.runs]
        for agent in self.agents:
            if (agent.hybrid is not None) != self.form.residual:
                raise ValueError(f"policy {self.name!r} of kind {self.kind.value!r}: run "
                                 f"{agent.path} records hybrid={agent.hybrid!r}")

    def policies(self, run: int, env, scenario: Scenario, seeds: list[int]) -> list:
        """One ``predict`` object per seed for ``run`` on the env of ``scenario``.

        Deterministic policies are shared (the rollout batches the batch-invariant ones;
        a filter's counters then sum over the episodes, and the rollout records each
        episode's interventions); a ``per_seed`` entry such as ``random`` gets one per
        episode, built with the episode's seed.
        """
        if self.entry is not None:
            return self.entry.build(env, scenario, seeds)
        self.load()
        return [self._form().wrap(self.agents[run], env, scenario)] * len(seeds)

    def _form(self) -> AgentForm:
        if self.form is None:
            raise ValueError(f"policy {self.name!r} is a registered policy, not an agent's "
                             "files")
        return self.form


# --------------------------------------------------------------------------- #
# resolution
# --------------------------------------------------------------------------- #
def shipped_agents() -> dict[str, Path]:
    """Shipped agents: agent folders and folders of seed run folders in ``pretrained/``."""
    return pretrained_agents()


def default_policies() -> list[str]:
    """What ``python evaluate.py`` benchmarks by default.

    The built-in baselines but those of :data:`OPT_IN`, the shipped agents, the
    handover hybrid of each shipped agent in :data:`HANDOVER_OF` and each shipped agent
    of :data:`FILTERED_OF` behind the safety filter (not the policies registered by user
    code or plugins).
    """
    shipped = shipped_agents()
    return ([name for name in BASELINES if name not in OPT_IN] + list(shipped)
            + [HANDOVER + name for name in HANDOVER_OF if name in shipped]
            + [FILTERED + name for name in FILTERED_OF if name in shipped])


def resolve_policy(name: str, allow_pickle: bool = False) -> PolicySpec:
    """PolicySpec of a registered name, ``handover:AGENT``, a shipped agent or a path.

    ``allow_pickle`` lets a run folder without the safe agent files load
    stable-baselines3's pickled ones (which run code when loaded).
    Raises ValueError listing the valid names when ``name`` is none of these.
    """
    if not isinstance(name, str):
        raise TypeError(f"policy name must be a str, got {type(name).__name__} {name!r}")
    if name in _REGISTRY:
        return _registered_spec(name)
    if name.startswith(HANDOVER):
        return _wrapped_spec(name, HANDOVER, HANDOVER_FORM, "a handover hybrid", allow_pickle)
    if name.startswith(FILTERED):
        return _wrapped_spec(name, FILTERED, FILTERED_FORM, "a filtered agent", allow_pickle)
    path = _agent_path(name)
    if path is not None:
        return _agent_spec(name, path, allow_pickle)
    load_plugins()
    if name in _REGISTRY:
        return _registered_spec(name)
    raise ValueError(unknown_policy_message(name))


def _registered_spec(name: str) -> PolicySpec:
    entry = _REGISTRY[name]
    return PolicySpec(name, entry.kind, [None], entry=entry)


def _agent_path(name: str) -> Path | None:
    """The shipped agent called ``name``, or ``name`` as an existing path, else None."""
    path = shipped_agents().get(name)
    if path is None and name:
        try:
            path = Path(name) if Path(name).exists() else None
        except OSError:  # e.g. longer than a file name may be: no such agent
            path = None
    return path


def _wrapped_spec(name: str, prefix: str, form: AgentForm, what: str,
                  allow_pickle: bool) -> PolicySpec:
    inner = resolve_policy(name[len(prefix):], allow_pickle=allow_pickle)
    if inner.form is not ALONE:
        kind = "a registered policy" if inner.entry is not None else "a residual"
        raise ValueError(f"policy {name!r}: {what} needs a trained agent that acts alone, "
                         f"{inner.name!r} is {kind} of kind {inner.kind.value!r}")
    return PolicySpec(name, form.kind, inner.runs, form=form, allow_pickle=allow_pickle)


def _agent_spec(name: str, path: Path, allow_pickle: bool) -> PolicySpec:
    """A trained agent: one run, or a folder of seed runs that all act alike."""
    runs = seed_runs(path) or [path]
    hybrid = [hybrid_of(run) is not None for run in runs]
    if any(hybrid) and not all(hybrid):
        mixed = {str(r): "hybrid" if h else "rl" for r, h in zip(runs, hybrid, strict=True)}
        raise ValueError(f"policy {name!r} mixes residuals of a hybrid and plain agents "
                         f"{mixed}; evaluate them as separate policies")
    form = RESIDUAL if all(hybrid) else ALONE
    return PolicySpec(name, form.kind, runs, form=form, allow_pickle=allow_pickle)


def unknown_policy_message(name: str) -> str:
    """The error for a name that is none of the valid ones; lists them."""
    registered = list(_REGISTRY)
    shipped = list(shipped_agents())
    close = difflib.get_close_matches(name[:200], registered + shipped, n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    shown = repr(name) if len(name) <= 200 else f"{name[:60]!r}... ({len(name)} characters)"
    return (f"unknown policy {shown}{hint}; valid: a registered policy "
            f"{', '.join(registered)}; a shipped agent {', '.join(shipped) or '(none)'}; "
            f"{HANDOVER}<agent> or {FILTERED}<agent> (a shipped agent or a path); or a path "
            "to a trained agent (run folder, model file or folder of seed_K run folders)")


def make_policy(name: str, env, scenario: Scenario | None = None, seed: int = 0):
    """Policy object with ``predict`` for any policy name (a trained agent's first run).

    ``env`` is a TetherLibration env; ``scenario`` gives the nominal model of ``smc``
    (model mismatch); ``seed`` seeds ``random``.
    """
    spec = resolve_policy(name)
    spec.load()
    return spec.policies(0, env, scenario or Scenario("env", ""), [seed])[0]
