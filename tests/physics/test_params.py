"""Validation of parameters and inputs (tether_gym.params, TetherChain, Scales).

Invalid values raise ValueError naming the offending value; wrong types raise
TypeError. Valid inputs are normalised (floats, tuples, the Gravity enum) and the
parameter objects are immutable.
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from tether_gym.params import ChainParams, Gravity, OrbitParams, ReelParams
from tether_gym.physics import Scales, TetherChain

GOOD_STATE = dict(nu=0.3, theta=[0.1, -0.1], dtheta=[0.2, 0.0], length=[0.5, 0.5],
                  dlength=[0.01, 0.0], ddlength=[0.0, 0.0])


def _call(chain, **overrides):
    state = {**GOOD_STATE, **overrides}
    return chain.accelerations(state["nu"], state["theta"], state["dtheta"], state["length"],
                               state["dlength"], state["ddlength"])


# --------------------------------------------------------------------------- #
# TetherChain construction
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("masses, pattern", [
    ((), r"masses=\(\)"),
    ([], r"masses=(\(\)|\[\])"),
    ((1.0, -2.0), r"masses=.*-2\.0"),
    ((1.0, 0.0), r"masses=\(1\.0, 0\.0\)"),
    ((1.0, float("nan")), r"masses=.*nan"),
    ((1.0, float("inf")), r"masses=.*inf"),
    (np.ones((2, 2)), r"(?s)masses=.*shape \(2, 2\)"),
])
def test_chain_rejects_bad_masses(masses, pattern):
    with pytest.raises(ValueError, match=pattern):
        TetherChain(masses, 0.2)


@pytest.mark.parametrize("e, pattern", [
    (1.0, r"eccentricity=1\.0"),
    (-0.1, r"eccentricity=-0\.1"),
    (1.5, r"eccentricity=1\.5"),
    (float("nan"), r"eccentricity=nan"),
    (float("inf"), r"eccentricity=inf"),
    (np.float64(-0.2), r"eccentricity=.*-0\.2"),
])
def test_chain_rejects_bad_eccentricity(e, pattern):
    with pytest.raises(ValueError, match=pattern):
        TetherChain((1.0, 2.0), e)


def test_chain_gravity_model_arguments():
    with pytest.raises(ValueError, match=r"gravity='newton'"):
        TetherChain((1.0, 2.0), 0.2, gravity="newton")
    with pytest.raises(ValueError, match=r"length_ratio.*None"):
        TetherChain((1.0, 2.0), 0.2, gravity="full")
    for bad, text in ((0.0, r"length_ratio=0\.0"), (-1e-3, r"length_ratio=-0\.001"),
                      (1.0, r"length_ratio=1\.0"), (math.nan, r"length_ratio=nan")):
        with pytest.raises(ValueError, match=text):
            TetherChain((1.0, 2.0), 0.2, gravity="full", length_ratio=bad)
    with pytest.raises(ValueError, match=r"length_ratio=2\.0"):
        TetherChain((1.0, 2.0), 0.2, gravity="gradient", length_ratio=2.0)
    # accepted spellings
    assert TetherChain((1.0,), 0.2, gravity="FULL", length_ratio=1e-3).gravity is Gravity.FULL
    assert TetherChain((1.0,), 0.2, gravity=Gravity.GRADIENT).gravity is Gravity.GRADIENT


@pytest.mark.parametrize("kwargs", [
    dict(masses="12", eccentricity=0.2),
    dict(masses=3.0, eccentricity=0.2),
    dict(masses=None, eccentricity=0.2),
    dict(masses=(1.0, 2.0), eccentricity="0.2"),
    dict(masses=(1.0, 2.0), eccentricity=None),
    dict(masses=(1.0, 2.0), eccentricity=True),
    dict(masses=(1.0, 2.0), eccentricity=[0.2]),
    dict(masses=(1.0, 2.0), eccentricity=0.2, gravity=1),
    dict(masses=(1.0, 2.0), eccentricity=0.2, gravity="full", length_ratio="0.002"),
])
def test_chain_rejects_wrong_types(kwargs):
    with pytest.raises(TypeError):
        TetherChain(**kwargs)


def test_chain_normalises_masses():
    chain = TetherChain([2, 6, 2], 0)
    np.testing.assert_allclose(chain.mass_fractions, [0.2, 0.6, 0.2], rtol=1e-15)
    np.testing.assert_allclose(chain.tail_masses, [1.0, 0.8, 0.2], rtol=1e-15)
    assert chain.n_tethers == 3
    assert isinstance(chain.eccentricity, float)


# --------------------------------------------------------------------------- #
# TetherChain state arguments
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("name, value, pattern", [
    ("theta", [0.1, 0.2, 0.3], r"theta.*\(3,\)"),
    ("theta", 0.1, r"theta.*\(\)"),
    ("dtheta", [[0.1], [0.2]], r"dtheta.*\(2, 1\)"),
    ("length", [0.5], r"length.*\(1,\)"),
    ("ddlength", np.zeros((3, 4)), r"ddlength.*\(3, 4\)"),
])
def test_state_with_wrong_last_dimension(name, value, pattern):
    chain = TetherChain((1.0, 2.0), 0.2)
    with pytest.raises(ValueError, match=pattern):
        _call(chain, **{name: value})


def test_state_with_incompatible_leading_shapes():
    chain = TetherChain((1.0, 2.0), 0.2)
    with pytest.raises(ValueError):
        _call(chain, theta=np.zeros((4, 2)), dtheta=np.zeros((3, 2)))
    with pytest.raises(ValueError):
        _call(chain, nu=np.zeros(5), theta=np.zeros((4, 2)))


@pytest.mark.parametrize("name, value, pattern", [
    ("nu", math.inf, r"nu=.*inf"),
    ("nu", [0.1, math.nan], r"nu=.*nan"),
    ("theta", [math.nan, 0.0], r"theta=.*nan"),
    ("dtheta", [0.0, -math.inf], r"dtheta=.*-inf"),
    ("length", [0.5, math.inf], r"length=.*inf"),
    ("dlength", [math.nan, 0.0], r"dlength=.*nan"),
    ("ddlength", [0.0, math.inf], r"ddlength=.*inf"),
    ("length", [0.5, -0.1], r"length=.*-0\.1"),
    ("length", [0.0, 0.5], r"length=.*must lie in \[1e-06, 1e\+06\]"),
])
def test_state_with_bad_values(name, value, pattern):
    chain = TetherChain((1.0, 2.0), 0.2)
    with pytest.raises(ValueError, match=pattern):
        _call(chain, **{name: value})


def test_control_affine_validates_too():
    chain = TetherChain((1.0, 2.0), 0.2)
    with pytest.raises(ValueError, match=r"length=.*-0\.5"):
        chain.control_affine(0.0, [0.0, 0.0], [0.0, 0.0], [0.5, -0.5])
    with pytest.raises(ValueError, match=r"theta.*\(3,\)"):
        chain.control_affine(0.0, [0.0, 0.0, 0.0], [0.0, 0.0], [0.5, 0.5])
    with pytest.raises(ValueError, match=r"dtheta=.*nan"):
        chain.control_affine(0.0, [0.0, 0.0], [math.nan, 0.0], [0.5, 0.5])


# --------------------------------------------------------------------------- #
# parameter dataclasses
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("kwargs, pattern", [
    (dict(eccentricity=1.0), r"eccentricity=1\.0"),
    (dict(eccentricity=-0.1), r"eccentricity=-0\.1"),
    (dict(eccentricity=math.nan), r"eccentricity=nan"),
    (dict(semi_latus_rectum=0.0), r"semi_latus_rectum=0\.0"),
    (dict(semi_latus_rectum=-8.52e6), r"semi_latus_rectum=-8520000\.0"),
    (dict(mu=-1.0), r"mu=-1\.0"),
    (dict(mu=math.inf), r"mu=inf"),
])
def test_orbit_params_reject_bad_values(kwargs, pattern):
    with pytest.raises(ValueError, match=pattern):
        OrbitParams(**kwargs)


@pytest.mark.parametrize("kwargs, pattern", [
    (dict(masses=()), r"masses=\(\)"),
    (dict(masses=(1.0, -1.0)), r"masses=\(1\.0, -1\.0\)"),
    (dict(masses=(1.0, math.nan)), r"masses=.*nan"),
    (dict(initial_lengths=(0.5, 0.0)), r"initial_lengths=\(0\.5, 0\.0\)"),
    (dict(initial_lengths=(0.5, -0.5)), r"initial_lengths=\(0\.5, -0\.5\)"),
    (dict(initial_lengths=(0.5, math.inf)), r"initial_lengths=.*inf"),
    (dict(initial_lengths=(0.5, 0.3, 0.2)), r"initial_lengths=.*2 entries, got 3"),
    (dict(total_tether_length=0.0), r"total_tether_length=0\.0"),
    (dict(total_tether_length=-2e4), r"total_tether_length=-20000\.0"),
    (dict(gravity="exact"), r"gravity='exact'"),
])
def test_chain_params_reject_bad_values(kwargs, pattern):
    with pytest.raises(ValueError, match=pattern):
        ChainParams(**kwargs)


@pytest.mark.parametrize("kwargs, pattern", [
    (dict(accel_limit=0.0), r"accel_limit=0\.0"),
    (dict(accel_limit=-0.01), r"accel_limit=-0\.01"),
    (dict(accel_limit=math.nan), r"accel_limit=nan"),
    (dict(speed_limit=-1.0), r"speed_limit=-1\.0"),
    (dict(time_constant=0.0), r"time_constant=0\.0"),
    (dict(time_constant=math.inf), r"time_constant=inf"),
])
def test_reel_params_reject_bad_values(kwargs, pattern):
    with pytest.raises(ValueError, match=pattern):
        ReelParams(**kwargs)


@pytest.mark.parametrize("factory", [
    lambda: OrbitParams(eccentricity="0.2"),
    lambda: OrbitParams(semi_latus_rectum=None),
    lambda: OrbitParams(mu=True),
    lambda: ChainParams(masses="12"),
    lambda: ChainParams(masses=2.0),
    lambda: ChainParams(initial_lengths=0.5),
    lambda: ChainParams(total_tether_length="20 km"),
    lambda: ChainParams(gravity=0),
    lambda: ReelParams(accel_limit="0.01"),
    lambda: ReelParams(time_constant=None),
    lambda: Scales(OrbitParams(), "2e4"),
])
def test_params_reject_wrong_types(factory):
    with pytest.raises(TypeError):
        factory()


def test_scales_reject_bad_length():
    for bad in (0.0, -1.0, math.nan):
        with pytest.raises(ValueError, match=re.escape(f"total_tether_length={bad!r}")):
            Scales(OrbitParams(), bad)


def test_params_are_normalised_and_frozen():
    chain = ChainParams(masses=[1, 2, 3], initial_lengths=np.array([0.2, 0.3, 0.5]),
                        gravity="Full")
    assert chain.masses == (1.0, 2.0, 3.0)
    assert all(type(m) is float for m in chain.masses + chain.initial_lengths)
    assert chain.initial_lengths == (0.2, 0.3, 0.5)
    assert chain.gravity is Gravity.FULL
    assert chain.n_bodies == 4 and chain.n_tethers == 3
    for obj, field in ((chain, "masses"), (OrbitParams(), "eccentricity"),
                       (ReelParams(), "accel_limit")):
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(obj, field, 0.3)
    assert ReelParams(accel_limit=None, speed_limit=None).accel_limit is None
