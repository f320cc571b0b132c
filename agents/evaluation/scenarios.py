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

read with ``yaml.safe_load`` (no code is executed; lists become tuples).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["Scenario", "SUITES", "get_suite", "load_suite_file", "describe_suites",
           "RANDOM_INIT", "PAPER_SCENARIO"]

RANDOM_INIT = {"initial_theta": (0.0, 0.0), "init_theta_range": 0.15, "init_dtheta_range": 0.1}
"""theta_i(0) uniform in +-0.15 rad, theta_i'(0) within +-0.1 of the reference rate."""


PER_TETHER_KEYS = ("initial_theta",)
"""Scenario arguments with one entry per tether (see :meth:`Scenario.env_kwargs_with`)."""


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
        ``{"masses": ..., "eccentricity": ...}`` of the model that model-based
        controllers design on, when it differs from the env's (model mismatch).
    """

    name: str
    description: str
    env_kwargs: dict = field(default_factory=dict)
    nominal: dict | None = None

    def env_kwargs_with(self, overrides: dict | None = None) -> dict:
        """The scenario's env arguments with ``overrides`` (``--env-kwargs``) on top.

        When ``overrides`` sets ``n_bodies``, a per-tether tuple of the scenario whose
        entries are all equal (such as ``initial_theta=(0.0, 0.0)``) is resized to the
        new number of tethers, so that the suites work for any N.
        """
        overrides = dict(overrides or {})
        merged = {**self.env_kwargs, **overrides}
        n_bodies = overrides.get("n_bodies")
        if isinstance(n_bodies, int) and not isinstance(n_bodies, bool) and n_bodies >= 2:
            for key in PER_TETHER_KEYS:
                value = merged.get(key)
                if (key not in overrides and isinstance(value, tuple) and value
                        and all(v == value[0] for v in value)):
                    merged[key] = (value[0],) * (n_bodies - 1)
        return merged


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

SUITES = {"default": DEFAULT_SUITE, "paper": (PAPER_SCENARIO,), "beyond": BEYOND_SUITE}


SCENARIO_KEYS = ("name", "description", "env_kwargs", "nominal")
NOMINAL_KEYS = ("masses", "eccentricity")


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
    import yaml

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"suite file {str(path)!r} does not exist")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ValueError(f"suite file {path}: not valid YAML: {exc}") from None
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
        env_kwargs = item.get("env_kwargs") or {}
        if not isinstance(env_kwargs, dict) or not all(isinstance(key, str)
                                                       for key in env_kwargs):
            raise ValueError(f"{where} ({name}): 'env_kwargs' must be a mapping of argument "
                             f"names to values, got {env_kwargs!r}")
        nominal = item.get("nominal")
        if nominal is not None and (not isinstance(nominal, dict)
                                    or sorted(nominal) != sorted(NOMINAL_KEYS)):
            raise ValueError(f"{where} ({name}): 'nominal' must have exactly the keys "
                             f"{list(NOMINAL_KEYS)}, got {nominal!r}")
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
