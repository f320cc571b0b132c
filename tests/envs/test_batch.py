"""Tests of ChainBatch (tether_gym.envs.batch): batched resets and parameter rows.

The vector-env tests compare whole trajectories with single envs; these pin the two
batched pieces on their own: resetting several rows in one call gives, bit for bit,
what resetting them one at a time gives, and the vectorised parameter rows equal
rows packed one by one from independently computed tail mass fractions.
"""

from __future__ import annotations

import numpy as np
import pytest

from tether_gym.envs import EnvConfig
from tether_gym.envs.batch import ChainBatch
from tether_gym.physics import PARAMS

RANDOMISED = dict(n_bodies=4, eccentricity_range=(0.05, 0.25), mass_range=0.3,
                  init_theta_range=0.1, init_dtheta_range=0.05, init_length_range=0.1,
                  obs_noise=1e-3)

def _arrays(batch):
    """Every per-row array of a batch, by name."""
    return batch.rows._asdict()


@pytest.mark.parametrize("kwargs", [{}, RANDOMISED, dict(RANDOMISED, mass_range=None),
                                    dict(RANDOMISED, eccentricity_range=None)])
@pytest.mark.parametrize("options", [None, {"nu": 0.4, "theta": [0.1, -0.05, 0.02]}])
def test_batched_reset_equals_row_by_row_resets(kwargs, options):
    config = EnvConfig.from_kwargs(**{"n_bodies": 4, **kwargs})
    rows = [5, 0, 3]
    together, alone = ChainBatch(config, 6), ChainBatch(config, 6)
    rngs_t = [np.random.default_rng(100 + b) for b in range(6)]
    rngs_a = [np.random.default_rng(100 + b) for b in range(6)]
    together.reset_rows(rows, rngs_t, options)
    for b in rows:
        alone.reset_rows([b], rngs_a, options)
    for name, value in _arrays(together).items():
        assert np.array_equal(value, _arrays(alone)[name]), name
    # every row drew from its own generator and nothing else: the streams agree after
    assert [r.random() for r in rngs_t] == [r.random() for r in rngs_a]
    # rows that were not listed keep their (zero) state
    assert not together.y[[1, 2, 4]].any() and not together.obs[[1, 2, 4]].any()
    if config.randomised:  # the draws differ between rows
        assert len({tuple(together.par[b]) for b in rows}) == 3


def test_param_rows_pack_independent_tail_fractions():
    config = EnvConfig.from_kwargs(n_bodies=5, eccentricity_range=(0.0, 0.3), mass_range=0.5)
    rng = np.random.default_rng(0)
    ecc = rng.uniform(0.0, 0.3, 7)
    masses = rng.uniform(0.5, 3.0, (7, 4))
    rows = config.param_rows(ecc, masses)
    a_bound = config.accel_limit / (config.total_tether_length * config.orbit.rate_scale**2)
    sl = PARAMS.slices(4)
    for b in range(7):
        tail = [masses[b, j:].sum() / masses[b].sum() for j in range(4)]
        np.testing.assert_allclose(rows[b, sl["tail_mass"]], tail, rtol=1e-15, atol=0.0)
        expected = {"eccentricity": ecc[b], "gravity": 0.0, "accel_bound": a_bound,
                    "length_ratio": config.total_tether_length / config.semi_latus_rectum,
                    "speed_bound": np.inf, "time_constant": config.reel_time_constant}
        for name, value in expected.items():
            assert rows[b, sl[name]] == pytest.approx(value, rel=1e-15), name
        assert np.array_equal(config.param_rows(ecc[b], masses[b]), rows[b])
    # masses of shape (n,) are shared by every row
    shared = config.param_rows(ecc, masses[0])
    for b in range(7):
        assert np.array_equal(shared[b], config.param_rows(ecc[b], masses[0]))


@pytest.mark.parametrize("rows", [None, [4, 1]])
def test_step_draws_are_each_rows_uniform_then_normal(rows):
    """Per step, row b's disturbance and noise are rngs[b].uniform(-d, d, n) and then
    rngs[b].normal(0, sigma, 4n), from copies of the generators taken before the step."""
    config = EnvConfig.from_kwargs(n_bodies=4, disturbance=0.1, obs_noise=1e-3)
    batch = ChainBatch(config, 6)
    rngs = [np.random.default_rng(7 + b) for b in range(6)]
    batch.reset_rows(range(6), rngs)
    before_dist, before_noise = batch.rows.disturbance.copy(), batch.rows.noise.copy()
    copies = [np.random.Generator(np.random.PCG64()) for _ in range(6)]
    for copy, rng in zip(copies, rngs, strict=True):
        copy.bit_generator.state = rng.bit_generator.state
    batch.step(np.zeros((6, 3)), rngs, None if rows is None else np.array(rows))
    stepped = range(6) if rows is None else rows
    for b in range(6):
        if b in stepped:
            assert np.array_equal(batch.rows.disturbance[b], copies[b].uniform(-0.1, 0.1, 3))
            assert np.array_equal(batch.rows.noise[b], copies[b].normal(0.0, 1e-3, 12))
            assert copies[b].random() == rngs[b].random()
        else:  # rows not stepped draw nothing
            assert np.array_equal(batch.rows.disturbance[b], before_dist[b])
            assert np.array_equal(batch.rows.noise[b], before_noise[b])


@pytest.mark.parametrize("kwargs", [{}, RANDOMISED])
def test_a_reset_at_the_configured_nu0_equals_a_reset_without_options(kwargs):
    # options={"nu": the configured nu(0)} go through the option handling (Eq. 10 and
    # theta_d' at an explicit nu(0)) but fix nothing: the same draws, the same start
    config = EnvConfig.from_kwargs(**{"n_bodies": 4, **kwargs})
    fast, general = ChainBatch(config, 4), ChainBatch(config, 4)
    fast.reset_rows([0, 2, 3], [np.random.default_rng(7 + b) for b in range(4)])
    general.reset_rows([0, 2, 3], [np.random.default_rng(7 + b) for b in range(4)],
                       {"nu": float(config.initial_nu)})
    for name, value in _arrays(fast).items():
        assert np.array_equal(value, _arrays(general)[name]), name


def test_failed_start_is_each_bound_with_its_own_strictness():
    config = EnvConfig.from_kwargs(n_bodies=3)
    lo, hi = config.episode.length_bounds
    half = 0.5 * np.pi
    below = np.nextafter
    # (theta, theta', l, l', T^) of tether 0; tether 1 stays nominal; True: failed
    cases = [((0.1, 0.0, 1.0, 0.0, 1.0), False),
             ((below(half, 0.0), 0.0, 1.0, 0.0, 1.0), False),
             ((half, 0.0, 1.0, 0.0, 1.0), True),
             ((-half, 0.0, 1.0, 0.0, 1.0), True),
             ((0.1, 0.0, lo, 0.0, 1.0), False),
             ((0.1, 0.0, hi, 0.0, 1.0), False),
             ((0.1, 0.0, below(lo, -np.inf), 0.0, 1.0), True),
             ((0.1, 0.0, below(hi, np.inf), 0.0, 1.0), True),
             ((0.1, np.nan, 1.0, 0.0, 1.0), True),
             ((0.1, 0.0, 1.0, np.inf, 1.0), True),
             ((0.1, -np.inf, 1.0, 0.0, 1.0), True),
             ((0.1, 0.0, 1.0, 0.0, 0.0), True),
             ((0.1, 0.0, 1.0, 0.0, np.inf), True),
             ((0.1, 0.0, 1.0, 0.0, 1e-300), False)]
    batch = ChainBatch(config, len(cases))
    for b, ((theta, dtheta, length, dlength, tension), _) in enumerate(cases):
        # STATE order: theta_0, theta_1, theta'_0, theta'_1, l_0, l_1, l'_0, l'_1
        batch.rows.y[b] = [theta, 0.0, dtheta, 0.0, length, 1.0, dlength, 0.0]
        batch.rows.tension[b] = [tension, 1.0]
    failed = batch._failed_at_start(np.arange(len(cases)))
    assert failed.tolist() == [want for _, want in cases]


def test_start_plan_fields_hold_the_configs_values():
    """StartPlan is built by keyword: each named field holds the config value of its name
    (distinct values, so a field filled from its neighbour would show)."""
    from tether_gym.envs.batch import StartPlan

    config = EnvConfig.from_kwargs(n_bodies=3, eccentricity=0.15, masses=(1.0, 3.0),
                                   mass_range=0.2, obs_noise=2e-3, init_theta_range=0.07,
                                   init_dtheta_range=0.03, init_length_range=0.11)
    plan = StartPlan.of(config)
    rnd = config.randomisation
    assert plan.eccentricity == config.eccentricity
    assert np.array_equal(plan.masses, np.asarray(config.masses, dtype=float))
    assert plan.randomised is config.randomised
    assert plan.eccentricity_range == rnd.eccentricity_range
    assert plan.mass_range == rnd.mass_range == 0.2
    assert plan.obs_noise == rnd.obs_noise == 2e-3
    assert plan.init_dtheta_range == rnd.init_dtheta_range == 0.03
    assert (plan.amplitude, plan.frequency) == (config.amplitude, config.frequency)
    assert plan.nu0 == float(config.initial_nu)
    assert plan.episode_length == config.episode_length
    n = config.n_tethers
    ones = np.ones(n)
    assert np.array_equal(plan.start_spread, np.concatenate(
        [0.07 * ones, 0.03 * ones, 0.11 * ones]))
    assert np.array_equal(plan.start_base[:n], np.asarray(config.initial_theta, dtype=float))
    assert np.array_equal(plan.start_base[n:2 * n], plan.dref * ones)
    assert np.array_equal(plan.start_base[2 * n:],
                          np.asarray(config.initial_lengths, dtype=float))
    assert np.all(plan.state_low < plan.state_high) and plan.state_low.size == 4 * n
    assert plan.eq10 is not None and len(plan.eq10) == 2
