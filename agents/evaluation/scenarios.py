"""Scenario suites for benchmarking policies, described as data.

A scenario is env keyword arguments plus, optionally, the nominal model that
model-based controllers design on (model mismatch). Every scenario is run with the
same fixed seeds for every policy.

Besides the built-in suites (:data:`SUITES`), a suite can be a YAML file::

    scenarios:
      - name: ecc_0.5
        description: random initial libration, e = 0.5
        env_kwargs: {eccentricity: 0.5, initial_theta: [0.0, 0.0], init_theta_range: 0.15}
      - name: mismatch
        env_kwargs: {masses: [1.2, 1.6]}
        nominal: {masses: [1.0, 2.0], eccentricity: 0.2}

read with :func:`~tether_gym_agents.common.yamlio.load_yaml_file` (no code is executed;
no anchors or aliases; at most 256 KiB; lists become tuples). The ``nominal`` values are
checked as the env checks them (masses > 0, one per tether of the chain the scenario
is written for, 0 <= e < 1, reel_time_constant and accel_limit > 0) when the file is
read.

**Any number of bodies.** Scenarios are written for the env's default chain (the
paper's, :data:`WRITTEN_FOR` = 3 bodies, 2 tethers); :meth:`Scenario.for_bodies` gives
the same scenario for any N by one rule per kind of per-tether value (:func:`per_tether`):

* ``masses`` (the env's and the nominal model's): each tether's mass as a factor of
  the env's default masses for the written N, the factors cycled over the N-1 tethers and
  applied to the default masses for N. The ``mismatch`` scenario's true masses
  (1.2, 1.6) = (1.2, 0.8) x the default (1, 2) become (1.2, 0.8, 1.2) x (1, 1, 1) at
  N = 4, its nominal (1, 2) the default (1, 1, 1);
* any other per-tether tuple (``initial_theta``) whose entries are all equal: the same
  entry on every tether; an unequal one written for another N is a ValueError naming
  the scenario, the key and N.

A value already of N-1 entries is kept, so at N = 3 every built-in scenario is exactly
the one written above.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["Scenario", "SUITES", "ROBUST_SUITE", "NOMINAL_KEYS", "get_suite",
           "load_suite_file", "describe_suites", "RANDOM_INIT", "PAPER_SCENARIO",
           "WRITTEN_FOR", "per_tether", "default_masses"]

WRITTEN_FOR = 3
"""The number of bodies the built-in scenarios are written for (the env's default)."""

RANDOM_INIT = {"initial_theta": (0.0, 0.0), "init_theta_range": 0.15, "init_dtheta_range": 0.1}
"""theta_i(0) uniform in +-0.15 rad, theta_i'(0) within +-0.1 of the reference rate."""


NOMINAL_KEYS = ("masses", "eccentricity", "reel_time_constant", "accel_limit")

PER_TETHER_KEYS = ("initial_theta", "masses")
"""Scenario arguments with one entry per tether (see :func:`per_tether`)."""


def default_masses(n_bodies: int) -> tuple[float, ...]:
    """The env's default subsatellite masses for ``n_bodies`` bodies (one per tether)."""
    from tether_gym.envs import EnvConfig

    return tuple(EnvConfig.from_kwargs(n_bodies=n_bodies).chain.masses)


def per_tether(key: str, value, n_bodies: int, where: str = "scenario"):
    """``value`` of the per-tether argument ``key`` for a chain of ``n_bodies`` bodies.

    A tuple of ``n_bodies - 1`` entries (or anything that is not a non-empty tuple) is
    returned as it is. ``masses`` written for ``len(value) + 1`` bodies keep each
    tether's factor over the env's default masses for that N, cycled over the tethers
    and applied to the default masses for ``n_bodies``; other tuples must have equal
    entries, which every tether then gets.

    Raises
    ------
    ValueError
        For an unequal tuple (not ``masses``) written for another N; the message names
        ``where``, ``key``, the value and ``n_bodies``.
    """
    n = n_bodies - 1
    if not isinstance(value, tuple) or not value or len(value) == n:
        return value
    if key == "masses":
        written = default_masses(len(value) + 1)
        factors = [float(v) / w for v, w in zip(value, written, strict=True)]
        target = default_masses(n_bodies)
        return tuple(target[i] * factors[i % len(factors)] for i in range(n))
    if all(v == value[0] for v in value):
        return (value[0],) * n
    raise ValueError(f"{where}: {key}={value!r} has {len(value)} entries with different "
                     f"values, written for {len(value) + 1} bodies; it has no rule for "
                     f"n_bodies={n_bodies} ({n} tethers): give {key} with {n} entries in "
                     "--env-kwargs or the suite file")


def _n_bodies(kwargs: dict) -> int | None:
    """``kwargs['n_bodies']`` when it is a valid int (the env checks it otherwise), else None."""
    n = kwargs.get("n_bodies", WRITTEN_FOR)
    if isinstance(n, int) and not isinstance(n, bool) and n >= 2:
        return n
    return None


def _written_tethers(env_kwargs: dict) -> int:
    """The number of tethers a scenario's ``env_kwargs`` are written for.

    Its ``n_bodies`` - 1 when it gives a valid one, else the length of its ``masses``
    when it gives them, else the default chain's (:data:`WRITTEN_FOR` - 1).
    """
    n_bodies = _n_bodies(env_kwargs) if "n_bodies" in env_kwargs else None
    if n_bodies is not None:
        return n_bodies - 1
    masses = env_kwargs.get("masses")
    if isinstance(masses, (list, tuple)) and masses:
        return len(masses)
    return WRITTEN_FOR - 1


def _check_nominal(nominal: dict, where: str, env_kwargs: dict | None = None) -> None:
    """Raise ValueError unless the nominal model's values are ones the env accepts.

    With ``env_kwargs`` (a suite file's scenario as written), its ``masses`` must have
    one entry per tether of the chain they are written for (:func:`_written_tethers`);
    without (a :class:`Scenario` made in code, or by :meth:`Scenario.for_bodies` for a
    chain its ``env_kwargs`` do not name), any number of entries.
    """
    from tether_gym.envs import EnvConfig
    from tether_gym.params import check_masses

    try:
        if "masses" in nominal:
            n = None if env_kwargs is None else _written_tethers(env_kwargs)
            check_masses(nominal["masses"], n)
        EnvConfig.from_kwargs(**{k: v for k, v in nominal.items() if k != "masses"})
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: nominal {exc}") from None


@dataclass(frozen=True)
class Scenario:
    """One benchmark scenario.

    Parameters
    ----------
    name : str
        Short identifier used in tables and results.json.
    description : str
        One line for the README and the printed table.
    env_kwargs : dict
        Arguments of ``gym.make("tether_gym/TetherLibration-v1", ...)``.
    nominal : dict
        The model that model-based controllers design on, where it differs from the
        env's (model mismatch): any of ``masses``, ``eccentricity``,
        ``reel_time_constant`` and ``accel_limit`` (:data:`NOMINAL_KEYS`, the env
        arguments of those names); the others are the env's.
    """

    name: str
    description: str
    env_kwargs: dict = field(default_factory=dict)
    nominal: dict | None = None

    def __post_init__(self) -> None:
        """A nominal model's keys and values are checked as the env checks them."""
        if self.nominal is None:
            return
        if not isinstance(self.nominal, dict) or not set(self.nominal) <= set(NOMINAL_KEYS):
            raise ValueError(f"scenario {self.name!r}: nominal must be a mapping of one or "
                             f"more of the keys {list(NOMINAL_KEYS)}, got {self.nominal!r}")
        _check_nominal(self.nominal, f"scenario {self.name!r}")

    def env_kwargs_with(self, overrides: dict | None = None, base: dict | None = None) -> dict:
        """The scenario's env arguments with ``overrides`` (``--env-kwargs``) on top.

        ``base`` (the env the evaluated agents were trained on, such as their
        ``n_bodies``) lies under the scenario's own arguments. The scenario's per-tether
        tuples follow the resulting ``n_bodies`` (:func:`per_tether`); the overrides are
        never changed.
        """
        overrides = dict(overrides or {})
        merged = {**(base or {}), **self.env_kwargs, **overrides}
        n_bodies = _n_bodies(merged)
        if n_bodies is not None:
            for key in PER_TETHER_KEYS:
                if key in merged and key not in overrides:
                    merged[key] = per_tether(key, merged[key], n_bodies,
                                             f"scenario {self.name!r}")
        return merged

    def for_bodies(self, n_bodies: int | None) -> Scenario:
        """The same scenario for a chain of ``n_bodies`` bodies (itself when nothing changes).

        Its per-tether env arguments and its nominal model's masses follow
        :func:`per_tether`; None (an invalid N, which the env then reports) keeps it.
        """
        if n_bodies is None:
            return self
        where = f"scenario {self.name!r}"
        env_kwargs = {key: per_tether(key, value, n_bodies, where) if key in PER_TETHER_KEYS
                      else value for key, value in self.env_kwargs.items()}
        nominal = self.nominal
        if nominal is not None and "masses" in nominal:
            nominal = {**nominal, "masses": per_tether("masses", tuple(nominal["masses"]),
                                                       n_bodies, f"{where}, nominal")}
        if env_kwargs == self.env_kwargs and nominal == self.nominal:
            return self
        return Scenario(self.name, self.description, env_kwargs, nominal)

    def resolved(self, overrides: dict | None = None,
                 base: dict | None = None) -> tuple[Scenario, dict]:
        """The scenario for the N its env gets, and that env's arguments.

        ``overrides`` and ``base`` as in :meth:`env_kwargs_with`.
        """
        kwargs = self.env_kwargs_with(overrides, base)
        return self.for_bodies(_n_bodies(kwargs)), kwargs


PAPER_SCENARIO = Scenario("paper",
                          "Sec. 4.3 case: theta(0) = (0.1, 0), theta'(0) = 0.2, e = 0.2")
"""The paper's case (the env's defaults): the whole ``paper`` suite, and a scenario of the
default suite (named, so that the paper suite never depends on a position)."""

DEFAULT_SUITE = (
    PAPER_SCENARIO,
    Scenario("random_init", "theta_i(0) in +-0.15 rad, theta_i'(0) in 0.2 +- 0.1",
             dict(RANDOM_INIT)),
    Scenario("ecc_0.0", "random initial libration, circular orbit",
             {**RANDOM_INIT, "eccentricity": 0.0}),
    Scenario("ecc_0.1", "random initial libration, e = 0.1", {**RANDOM_INIT, "eccentricity": 0.1}),
    Scenario("ecc_0.3", "random initial libration, e = 0.3", {**RANDOM_INIT, "eccentricity": 0.3}),
    Scenario("mismatch", "true m1 +20 %, m2 -20 %, e = 0.22; SMC designs on (1, 2), e = 0.2",
             {**RANDOM_INIT, "masses": (1.2, 1.6), "eccentricity": 0.22},
             nominal={"masses": (1.0, 2.0), "eccentricity": 0.2}),
    Scenario("disturbed", "random init, |d_i| <= 0.1 on theta'' (Eq. 20), obs noise 1e-3",
             {**RANDOM_INIT, "disturbance": 0.1, "obs_noise": 1e-3}),
)

BEYOND_SUITE = (
    Scenario("amp_0.1", "random init, reference amplitude A = 0.1",
             {**RANDOM_INIT, "amplitude": 0.1}),
    Scenario("amp_0.3", "random init, reference amplitude A = 0.3",
             {**RANDOM_INIT, "amplitude": 0.3}),
    Scenario("ecc_0.05", "random init, e = 0.05", {**RANDOM_INIT, "eccentricity": 0.05}),
    Scenario("ecc_0.4", "random init, e = 0.4 (beyond the training range)",
             {**RANDOM_INIT, "eccentricity": 0.4}),
    Scenario("init_0.25", "theta_i(0) in +-0.25 rad", {**RANDOM_INIT, "init_theta_range": 0.25}),
    Scenario("accel_0.005", "random init, reel acceleration limit 0.005 m/s^2",
             {**RANDOM_INIT, "accel_limit": 0.005}),
    Scenario("orbits_4", "random init, 4-orbit episodes", {**RANDOM_INIT, "orbits_per_episode": 4}),
    Scenario("gravity_full", "random init, exact inverse-square gravity",
             {**RANDOM_INIT, "gravity": "full"}),
)
"""Variations the shipped agents were not trained on, within the env's documented ranges
(the generalisation check of docs/task_design.md; not used to choose any design)."""

ROBUST_SUITE = (
    Scenario("mass_+30/-30", "true m1 +30 %, m2 -30 %; designed on (1, 2)",
             {**RANDOM_INIT, "masses": (1.3, 1.4)}, nominal={"masses": (1.0, 2.0)}),
    Scenario("mass_-25/+25", "true m1 -25 %, m2 +25 %; designed on (1, 2)",
             {**RANDOM_INIT, "masses": (0.75, 2.5)}, nominal={"masses": (1.0, 2.0)}),
    Scenario("ecc_+0.05", "true e = 0.25; designed on e = 0.2",
             {**RANDOM_INIT, "eccentricity": 0.25}, nominal={"eccentricity": 0.2}),
    Scenario("ecc_-0.05", "true e = 0.15; designed on e = 0.2",
             {**RANDOM_INIT, "eccentricity": 0.15}, nominal={"eccentricity": 0.2}),
    Scenario("reel_lag_x2", "true reel lag 0.025 rad; designed on 0.0125",
             {**RANDOM_INIT, "reel_time_constant": 0.025},
             nominal={"reel_time_constant": 0.0125}),
    Scenario("accel_x0.5", "true reel acceleration limit 0.005 m/s^2; designed on 0.01",
             {**RANDOM_INIT, "accel_limit": 0.005}, nominal={"accel_limit": 0.01}),
    Scenario("obs_noise_bias", "obs noise 3e-3 on theta, theta', l, l'; theta read 5e-3 "
             "rad high", {**RANDOM_INIT, "obs_noise": 3e-3, "obs_bias": 5e-3}),
    Scenario("disturbed_0.3", "|d_i| <= 0.3 on theta'' (Eq. 20; 0.3 of the SMC bound k = "
             "1), obs noise 1e-3", {**RANDOM_INIT, "disturbance": 0.3, "obs_noise": 1e-3}),
)
"""What the controllers know differs from the plant, N = 3. Model-based controllers
design on ``nominal`` (the paper's masses, e = 0.2, the default reels); learned agents
see only their observation. The levels were fixed before any policy ran on them:
masses 25-30 % off, e known to 0.05, reel lag twice and acceleration limit half the
modelled ones, noise three and disturbance bound three times the default suite's, and
a sensor offset of 5e-3 rad."""

SUITES = {"default": DEFAULT_SUITE, "paper": (PAPER_SCENARIO,), "beyond": BEYOND_SUITE,
          "robust": ROBUST_SUITE}


SCENARIO_KEYS = ("name", "description", "env_kwargs", "nominal")


def get_suite(name: str) -> tuple[Scenario, ...]:
    """The named suite, or the suite of a YAML file (``*.yml``/``*.yaml``).

    Raises ValueError naming the valid suites, or what is wrong in the file.
    """
    name = str(name)
    if name in SUITES:
        return SUITES[name]
    if name.endswith((".yml", ".yaml")):
        return load_suite_file(name)
    raise ValueError(f"unknown suite {name!r}; give one of {sorted(SUITES)} or a suite file "
                     "ending in .yml/.yaml")


def _tuples(value):
    if isinstance(value, list):
        return tuple(_tuples(v) for v in value)
    if isinstance(value, dict):
        return {k: _tuples(v) for k, v in value.items()}
    return value


def load_suite_file(path) -> tuple[Scenario, ...]:
    """Scenarios of a YAML suite file (format in the module docstring)."""
    from ..common.yamlio import load_yaml_file

    path = Path(path)
    data = load_yaml_file(path, what="suite file")  # a YamlFileError (ValueError)
    if isinstance(data, dict):
        unknown = sorted(set(data) - {"scenarios"})
        if unknown:
            raise ValueError(f"suite file {path}: unknown top-level keys {unknown}; "
                             "valid: ['scenarios']")
        data = data.get("scenarios")
    if not isinstance(data, list) or not data:
        raise ValueError(f"suite file {path}: needs a non-empty list 'scenarios:' of "
                         f"scenarios with keys {list(SCENARIO_KEYS)}")
    out, seen = [], set()
    for k, item in enumerate(data):
        where = f"suite file {path}, scenario {k}"
        if not isinstance(item, dict):
            raise ValueError(f"{where}: must be a mapping with keys {list(SCENARIO_KEYS)}, "
                             f"got {item!r}")
        unknown = sorted(set(item) - set(SCENARIO_KEYS))
        if unknown:
            raise ValueError(f"{where}: unknown keys {unknown}; valid: {list(SCENARIO_KEYS)}")
        name = item.get("name")
        if not isinstance(name, str) or not name:
            raise ValueError(f"{where}: 'name' must be a non-empty string, got {name!r}")
        if name in seen:
            raise ValueError(f"{where}: duplicate scenario name {name!r}")
        seen.add(name)
        if not isinstance(item.get("description", ""), str):
            raise ValueError(f"{where} ({name}): 'description' must be a string, got "
                             f"{type(item['description']).__name__}")
        env_kwargs = item.get("env_kwargs") or {}
        if not isinstance(env_kwargs, dict) or not all(isinstance(key, str)
                                                       for key in env_kwargs):
            raise ValueError(f"{where} ({name}): 'env_kwargs' must be a mapping of argument "
                             f"names to values, got {env_kwargs!r}")
        nominal = item.get("nominal")
        if nominal is not None and (not isinstance(nominal, dict) or not nominal
                                    or not set(nominal) <= set(NOMINAL_KEYS)):
            raise ValueError(f"{where} ({name}): 'nominal' must be a mapping of one or "
                             f"more of the keys {list(NOMINAL_KEYS)}, got {nominal!r}")
        if nominal is not None:
            _check_nominal(nominal, f"{where} ({name})", env_kwargs)
        out.append(Scenario(name, str(item.get("description", "")), _tuples(env_kwargs),
                            _tuples(nominal)))
    return tuple(out)


def describe_suites() -> str:
    """One paragraph per built-in suite: its scenarios and what they contain (for --help)."""
    lines = []
    for suite, scenarios in SUITES.items():
        lines.append(f"suite {suite!r} ({len(scenarios)} scenario"
                     f"{'s' if len(scenarios) > 1 else ''}):")
        lines += [f"  {sc.name}: {sc.description}" for sc in scenarios]
    return "\n".join(lines)
