"""``python evaluate.py`` (the main job) reproduces the shipped ``docs/eval/results.json``.

The README says what equals what: every episode's success and failure flags exactly,
every other per-episode metric to a relative :data:`RTOL`. This test re-runs two
baselines that need neither torch nor a trained agent (``smc``, and ``predictive``,
the one whose figures moved in the trailing digits on another machine) on three of the
default suite's scenarios, through the library call ``evaluate.py`` makes, and compares
each episode with its shipped record; the rows of issue 36 (the distilled students,
their PPO fine-tunes, the fine-tunes behind the safety filter and the residual SAC) and
issue 34's ``ppo_accel`` (trained by ``train.py gpu``) are re-run on one scenario, two
episodes per training run. ``ms/step`` is a wall time and is not compared.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from tether_gym_agents import evaluate
from tether_gym_agents.evaluation.scenarios import get_suite

SHIPPED = Path(__file__).resolve().parents[1] / "docs" / "eval" / "results.json"
POLICIES = ("smc", "predictive")
SCENARIOS = ("paper", "ecc_0.3", "mismatch")
EXACT = ("success", "slack", "tumble", "length")
RTOL = 1e-6
"""Relative tolerance of the real-valued metrics (the README quotes it)."""


def _suite_file(folder: Path, scenarios=SCENARIOS) -> Path:
    chosen = [s for s in get_suite("default") if s.name in scenarios]
    suite = {"scenarios": [{"name": s.name, "description": s.description,
                            "env_kwargs": s.env_kwargs,
                            **({"nominal": s.nominal} if s.nominal else {})} for s in chosen]}
    path = folder / "suite.yml"
    path.write_text(json.dumps(suite))  # JSON is YAML
    return path


def _compare(want: dict, episodes: dict) -> int:
    """Assert each shipped episode's record equal to the re-run's; the real values compared."""
    compared = 0
    for k, record in want.items():
        for name, value in record.items():
            mine = episodes[k][name]
            if value is None:  # results.json writes NaN as null
                assert mine is None or math.isnan(mine), f"{k}: {name} {mine!r}, shipped null"
            elif name in EXACT or not isinstance(value, float):
                assert mine == value, f"{k}: {name} {mine!r}, shipped {value!r}"
            else:
                assert mine == pytest.approx(value, rel=RTOL), \
                    f"{k}: {name} {mine!r}, shipped {value!r} (relative {RTOL})"
                compared += 1
    return compared


def test_shipped_episodes_of_the_main_job_reproduce(tmp_path):
    shipped = json.loads(SHIPPED.read_text())
    assert shipped["meta"]["command"] == "evaluate.py --out docs/eval"
    got = evaluate(list(POLICIES), suite=str(_suite_file(tmp_path)), n_seeds=10,
                   plots=False, log=None)
    key = ("policy", "run", "scenario", "seed")
    want = {tuple(e[k] for k in key): e for e in shipped["episodes"]
            if e["policy"] in POLICIES and e["scenario"] in SCENARIOS}
    episodes = {tuple(e[k] for k in key): e for e in got["episodes"]}
    assert set(episodes) == set(want) and len(want) == len(POLICIES) * len(SCENARIOS) * 10
    assert _compare(want, episodes) > 400


LEARNED = ("distill_bc", "distill_ppo", "sac_residual", "filtered:distill_ppo", "ppo_accel")
"""The rows of issue 36 and issue 34's `ppo_accel`; each is re-run on one scenario, two
episodes per training run."""


@pytest.mark.parametrize("policy", LEARNED)
def test_shipped_episodes_of_the_learned_rows_reproduce(tmp_path, policy):
    shipped = json.loads(SHIPPED.read_text())
    scenario = "ecc_0.1"
    got = evaluate([policy], suite=str(_suite_file(tmp_path, (scenario,))), n_seeds=2,
                   plots=False, log=None)
    key = ("policy", "run", "scenario", "seed")
    want = {tuple(e[k] for k in key): e for e in shipped["episodes"]
            if e["policy"] == policy and e["scenario"] == scenario and e["seed"] < 2}
    episodes = {tuple(e[k] for k in key): e for e in got["episodes"]}
    assert set(episodes) == set(want) and len(want) >= 10  # >= 5 runs x 2 seeds
    assert _compare(want, episodes) > 0
