"""EnvConfig: validation of the environment's keyword arguments, derived sizes."""

from __future__ import annotations

import dataclasses
import math

import gymnasium as gym
import pytest

import tether_gym
from tether_gym.envs import EnvConfig
from tether_gym.envs.layout import OBSERVATION

from .conftest import ENV_ID

NAN = float("nan")

# (kwargs, exception, regex the message must match: it names the value)
BAD_KWARGS = [
    ({"eccentricity": 1.0}, ValueError, r"eccentricity=1\.0 is outside the valid range"),
    ({"eccentricity": -0.1}, ValueError, r"eccentricity=-0\.1"),
    ({"eccentricity": NAN}, ValueError, r"eccentricity=nan must be finite"),
    ({"eccentricity": "0.2"}, TypeError, r"eccentricity must be a real number.*'0\.2'"),
    ({"n_bodies": 1}, ValueError, r"n_bodies=1 must be in \[2, 20\]"),
    ({"n_bodies": 2.5}, TypeError, r"n_bodies must be an int.*2\.5"),
    ({"masses": (1.0, 2.0, 3.0)}, ValueError, r"masses=\(1\.0, 2\.0, 3\.0\) must have 2 entries"),
    ({"masses": (1.0, 0.0)}, ValueError, r"masses=\(1\.0, 0\.0\) must all be > 0"),
    ({"masses": (1.0, -2.0)}, ValueError, r"masses=\(1\.0, -2\.0\) must all be > 0"),
    ({"masses": (1.0, NAN)}, ValueError, r"masses=.*nan.* must be finite"),
    ({"masses": "12"}, TypeError, r"masses='12' must be a sequence of numbers, got str"),
    ({"initial_lengths": (0.5, NAN)}, ValueError, r"initial_lengths=.*nan.* must be finite"),
    ({"initial_theta": (1.6, 0.0)}, ValueError, r"initial_theta=\(1\.6, 0\.0\)"),
    ({"amplitude": NAN}, ValueError, r"amplitude=nan must be finite"),
    ({"physics_step": 0.01}, ValueError,
     r"control_step=0\.025 must be a whole multiple of physics_step=0\.01"),
    ({"physics_step": 0.05}, ValueError, r"physics_step=0\.05 is outside the valid range"),
    ({"gravity": "foo"}, ValueError, r"gravity='foo' is not one of 'gradient', 'full'"),
    ({"gravity": 3}, TypeError, r"gravity must be a str, got int 3"),
    ({"length_bounds": (1.5, 0.05)}, ValueError,
     r"length_bounds=\(1\.5, 0\.05\) must be \(low, high\) with 0 <= low < high"),
    ({"length_bounds": (0.05, 0.4)}, ValueError,
     r"initial_lengths=\(0\.5, 0\.5\) must lie inside length_bounds=\(0\.05, 0\.4\)"),
    ({"eccentricity_range": (0.3, 0.1)}, ValueError, r"eccentricity_range=\(0\.3, 0\.1\)"),
    ({"eccentricity_range": (0.1, 1.0)}, ValueError, r"eccentricity_range\[1\]=1\.0"),
    ({"mass_range": 1.0}, ValueError, r"mass_range=1\.0"),
    ({"reel_time_constant": 0.001}, ValueError, r"reel_time_constant=0\.001 must be >="),
    ({"reward_weights": {"sigmaa": 0.1}}, ValueError, r"unknown reward_weights keys \['sigmaa'\]"),
    # gym.make itself warns first that 'ansi' is not in metadata["render_modes"]
    pytest.param({"render_mode": "ansi"}, ValueError, r"render_mode='ansi' must be None",
                 marks=pytest.mark.filterwarnings("ignore:.*not in the possible render_modes")),
]


def _case_id(case):
    kwargs = case.values[0] if hasattr(case, "values") else case[0]
    (name, value), = kwargs.items()
    return f"{name}={value!r}"


@pytest.mark.parametrize(("kwargs", "exc", "match"), BAD_KWARGS,
                         ids=[_case_id(c) for c in BAD_KWARGS])
def test_bad_kwargs_raise_with_the_value(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        EnvConfig.from_kwargs(**kwargs)
    # the same through gym.make (what users call)
    with pytest.raises(exc, match=match):
        gym.make(ENV_ID, **kwargs)


def test_unknown_kwarg_lists_valid_names_and_suggests():
    with pytest.raises(ValueError, match=r"'eccentricty' \(did you mean 'eccentricity'\?\)") as err:
        gym.make(ENV_ID, eccentricty=0.3)
    message = str(err.value)
    for name in EnvConfig.names():
        assert name in message
    # no suggestion when nothing is close, but still the list
    with pytest.raises(ValueError, match=r"unknown argument\(s\) 'zzz'; valid arguments: n_bodies"):
        EnvConfig.from_kwargs(zzz=1)


def test_every_field_is_a_documented_argument():
    """Each EnvConfig field appears in the env docstring's Arguments table."""
    from tether_gym.envs import TetherLibrationEnv

    doc = TetherLibrationEnv.__doc__
    table = doc[doc.index("## Arguments"):doc.index("## Version History")]
    for name in EnvConfig.names():
        assert name in table, name


def test_defaults_match_registration_and_paper_case():
    cfg = EnvConfig.from_kwargs()
    assert cfg.max_episode_steps == tether_gym.DEFAULT_MAX_EPISODE_STEPS == 754
    assert cfg.max_episode_steps == math.ceil(3 * 2 * math.pi / 0.025)
    # no registered step limit: the env truncates itself, whatever its configuration
    assert gym.spec(ENV_ID).max_episode_steps is None
    assert cfg.n_substeps == 2  # 0.025 rad control step, 0.0125 rad RK4 step
    assert cfg.masses == (1.0, 2.0) and cfg.initial_lengths == (0.5, 0.5)
    assert cfg.initial_theta == (0.1, 0.0)


@pytest.mark.parametrize(("n_bodies", "randomised", "dim"),
                         [(2, False, 12), (3, False, 20), (4, False, 28), (3, True, 23),
                          (4, True, 32)])
def test_obs_dim_formula(n_bodies, randomised, dim):
    extra = {"mass_range": 0.1} if randomised else {}
    cfg = EnvConfig.from_kwargs(n_bodies=n_bodies, **extra)
    assert cfg.randomised is randomised
    assert cfg.obs_dim == dim  # 8(N-1) + 4 (+ N when randomised)


@pytest.mark.parametrize(("observe", "dim", "observed"),
                         [(None, 23, (True, True)), (True, 23, (True, True)),
                          (False, 20, (False, False)), ("eccentricity", 21, (True, False))])
def test_observe_params_switches_the_optional_groups(observe, dim, observed):
    cfg = EnvConfig.from_kwargs(eccentricity_range=(0.0, 0.3), observe_params=observe)
    assert cfg.obs_dim == dim  # 8(N-1) + 4, + 1 for e, + N-1 for the mass fractions
    assert (cfg.observed["eccentricity"], cfg.observed["masses"]) == observed


@pytest.mark.parametrize(("value", "exc"), [("ecc", ValueError), ("masses", ValueError),
                                            (1, TypeError), (0.5, TypeError)])
def test_bad_observe_params_raises_naming_the_value(value, exc):
    with pytest.raises(exc, match=f"observe_params.*{value!r}"):
        EnvConfig.from_kwargs(observe_params=value)


def test_defaults_for_other_chain_sizes():
    cfg = EnvConfig.from_kwargs(n_bodies=4)
    assert cfg.masses == (1.0, 1.0, 1.0)
    assert cfg.initial_lengths == pytest.approx((1 / 3,) * 3, abs=1e-15)
    assert cfg.initial_theta == (0.1, 0.0, 0.0)


def test_config_is_frozen_and_normalised():
    cfg = EnvConfig.from_kwargs(masses=[1, 2], length_bounds=[0.1, 1.0], gravity="FULL")
    assert cfg.masses == (1.0, 2.0) and isinstance(cfg.masses, tuple)
    assert cfg.length_bounds == (0.1, 1.0)
    assert cfg.gravity == "full"
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.eccentricity = 0.5


def test_episode_steps_follow_orbits_per_episode():
    steps = EnvConfig.from_kwargs(orbits_per_episode=0.1).max_episode_steps
    assert steps == math.ceil(0.1 * 2 * math.pi / 0.025) == 26
    assert EnvConfig.from_kwargs(orbits_per_episode=1.0, control_step=0.05,
                     physics_step=0.01).max_episode_steps == math.ceil(2 * math.pi / 0.05)


def _observed_combinations() -> set[tuple[tuple[str, bool], ...]]:
    """Every switch combination EnvConfig.observed produces (any observe_params, either way
    randomised)."""
    seen = set()
    for observe in (None, True, False, "eccentricity"):
        for extra in ({}, {"eccentricity_range": (0.0, 0.3)}, {"mass_range": 0.1}):
            cfg = EnvConfig.from_kwargs(observe_params=observe, **extra)
            seen.add(tuple(sorted(cfg.observed.items())))
    return seen


@pytest.mark.parametrize("n_bodies", [2, 3, 6])
def test_every_observed_combination_keeps_every_field_inside_the_row(n_bodies):
    """The kernel writes at OBSERVATION's static offsets: each field must lie in the row."""
    n = n_bodies - 1
    combinations = _observed_combinations()
    assert len(combinations) > 1  # today: neither, e alone, both
    for combination in combinations:
        switches = dict(combination)
        size = OBSERVATION.size(n, **switches)
        covered = sorted((sl.start, sl.stop)
                         for sl in OBSERVATION.slices(n, **switches).values())
        assert covered[0][0] == 0 and covered[-1][1] == size, switches
        assert all(a[1] == b[0] for a, b in zip(covered[:-1], covered[1:], strict=True)), switches


def test_a_switch_combination_the_offsets_cannot_hold_is_rejected():
    """Mass fractions without e: their static offset counts e, one past the row's end."""
    with pytest.raises(ValueError, match=r"'masses' is on but \['eccentricity'\]"):
        OBSERVATION.slices(2, eccentricity=False, masses=True)
    for mask in range(2 ** len(OBSERVATION.groups)):
        switches = {g: bool(mask >> k & 1) for k, g in enumerate(OBSERVATION.groups)}
        try:
            slices = OBSERVATION.slices(2, **switches)
        except ValueError:
            continue
        assert max(sl.stop for sl in slices.values()) <= OBSERVATION.size(2, **switches)


# for every gym.make argument a value out of its range (issue 24: reel_time_constant=0
# answered with the internal name time_constant); test_every_argument_has_a_bad_value
# keeps this list complete
OUT_OF_RANGE = {
    "n_bodies": 0, "masses": (1.0, -2.0), "initial_lengths": (0.5, -0.5),
    "initial_theta": (2.0, 0.0), "initial_nu": NAN, "eccentricity": 1.5,
    "semi_latus_rectum": -1.0, "mu": 0.0, "total_tether_length": -1.0, "gravity": "moon",
    "amplitude": 2.0, "frequency": -1.0, "control_step": 0.0, "physics_step": 0.0,
    "max_reel_rate": 0.0, "action_mode": "speed", "increment_gain": 3.0, "accel_limit": 0.0,
    "speed_limit": -1.0, "reel_time_constant": 0, "length_bounds": (1.0, 0.0),
    "orbits_per_episode": 0.0, "init_theta_range": -1.0, "init_dtheta_range": -1.0,
    "init_length_range": -1.0, "obs_noise": -1.0, "obs_bias": 0.7, "disturbance": -1.0,
    "eccentricity_range": (0.5, 0.1), "mass_range": 1.0, "observe_params": "masses",
    "reward_weights": {"effort": -1.0}, "cost_thresholds": {"tumble_fraction": 1.5},
    "render_mode": "x",
}


def test_every_argument_has_a_bad_value():
    assert sorted(OUT_OF_RANGE) == sorted(EnvConfig.names())


@pytest.mark.filterwarnings("ignore:.*not in the possible render_modes")
@pytest.mark.parametrize("name", sorted(OUT_OF_RANGE))
@pytest.mark.parametrize("kind", ["out of range", "wrong type"])
def test_a_bad_value_of_any_argument_names_the_argument_and_the_value(name, kind):
    """The message names the gym.make argument (not a field of an internal part), the
    value given and what is allowed."""
    value = OUT_OF_RANGE[name] if kind == "out of range" else "abc"
    with pytest.raises((TypeError, ValueError)) as err:
        gym.make(ENV_ID, **{name: value})
    # (gymnasium adds the kwargs to a TypeError: the message must name the value without it)
    message = str(err.value).split(" was raised from the environment creator")[0]
    assert message.startswith(name), message
    shown = repr(next(iter(value.values()))) if isinstance(value, dict) else repr(value)
    assert shown in message, message
    assert any(word in message for word in ("must", "valid range", "not one of")), message
