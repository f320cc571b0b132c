"""Fixtures shared by the agents' tests."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def ray_session():
    """One local Ray instance per test module (the fan-out reuses it and leaves it up)."""
    ray = pytest.importorskip("ray")
    from tether_gym_agents.training.fanout import init_ray, shutdown_ray

    init_ray()
    yield ray
    shutdown_ray(ray)
