"""Cost in the benchmark (issue 35): evaluate.py's cost/step and over-cost-limit columns
and results.json's cost keys, checked against a ``gym.make`` rollout of the same seeds.

A registered policy pulses the reels (+1, -1 reel rate in blocks of ``period`` steps) for
the first ``steps`` steps of an episode and then holds; the seed picks the pattern, so
one evaluation holds an episode that fails on slack, one that survives over the cost
limit, one that costs something but stays under it and one that costs nothing.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import re
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest
from scipy.stats import trim_mean

import tether_gym
from tether_gym.tasks.cost import COST_LIMIT
from tether_gym_agents.cli.evaluate import main
from tether_gym_agents.evaluation import registry
from tether_gym_agents.evaluation.results import build_results, markdown_tables
from tether_gym_agents.evaluation.stats import (
    BOOTSTRAP_SEED,
    N_BOOTSTRAP,
    run_scores,
    stratified_bootstrap_ci,
)
from tether_gym_agents.files.trained import pretrained_agents

NAME = "cost_pulse_test"
RATE = {"action_mode": "rate"}
PATTERNS = {  # seed: (period [steps], pulsing steps or None for all)
    0: (2, None),  # drives a tether slack: the episode fails
    1: (2, 96),    # a few steps of low tension, under the limit
    2: (4, None),  # survives, over the limit
    3: (None, 0),  # holds the lengths: no cost
}


class Pulse:
    """Reel rates +1/-1 in blocks of ``period`` steps for ``steps`` steps, then 0."""

    def __init__(self, n_act: int, period: int | None, steps: int | None):
        self.n_act, self.period, self.steps, self.k = n_act, period, steps, 0

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        on = self.period is not None and (self.steps is None or self.k < self.steps)
        value = (1.0 if (self.k // self.period) % 2 == 0 else -1.0) if on else 0.0
        self.k += 1
        return np.full((1, self.n_act), value, np.float32), None


def _pulse(env, scenario, seed):
    return Pulse(env.action_space.shape[0], *PATTERNS[seed])


def _by_hand(env_kwargs: dict, seed: int) -> dict:
    """The episode of ``seed`` on ``gym.make``: its per-step costs and how it ended."""
    env = gym.make(tether_gym.ENV_ID, **env_kwargs)
    policy = _pulse(env, None, seed)
    obs, info = env.reset(seed=seed)
    assert info["cost"] == 0.0
    costs = []
    while True:
        action, _ = policy.predict(obs[None])
        obs, _, terminated, truncated, info = env.step(action[0])
        costs.append([info[k] for k in ("cost", "cost_slack", "cost_length", "cost_tumble")])
        if terminated or truncated:
            env.close()
            return {"costs": np.array(costs), "failure": info.get("failure") if terminated
                    else None}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """evaluate.py NAME smc --suite paper --seeds 4: (exit code, stdout, results.json)."""
    registry.register_policy(NAME, _pulse, env_kwargs=RATE, per_seed=True, overwrite=True)
    out = tmp_path_factory.mktemp("cost_eval")
    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        code = main([NAME, "smc", "--suite", "paper", "--seeds", "4", "--out", str(out),
                     "--no-plots"])
    res = json.loads((out / "results.json").read_text())
    return code, buffer.getvalue(), res


def test_cost_per_step_is_the_mean_of_info_cost_over_the_steps_a_gym_make_rollout_takes(run):
    code, _, res = run
    assert code == 0
    assert res["cost_limit"] == COST_LIMIT
    kwargs = {**res["scenarios"]["paper"]["env_kwargs"], **RATE}
    episodes = {e["seed"]: e for e in res["episodes"] if e["policy"] == NAME}
    assert sorted(episodes) == [0, 1, 2, 3]
    for seed, ep in episodes.items():
        hand = _by_hand(kwargs, seed)
        costs = hand["costs"]
        steps = len(costs)
        assert ep["cost_per_step"] == pytest.approx(costs[:, 0].sum() / steps, rel=1e-12,
                                                    abs=0)
        for k, part in enumerate(("slack", "length", "tumble"), 1):
            assert ep[f"cost_{part}_per_step"] == pytest.approx(costs[:, k].sum() / steps,
                                                                rel=1e-12, abs=0)
        assert ep["over_limit"] == float(costs[:, 0].sum() / steps > COST_LIMIT)
        assert ep["success"] == float(hand["failure"] is None)
    # the episodes span the cases the test is about
    hand = {seed: _by_hand(kwargs, seed) for seed in (0, 1)}
    assert hand[0]["failure"] == "slack" and episodes[0]["slack"] == 1.0
    assert 0 < episodes[1]["cost_per_step"] <= COST_LIMIT and episodes[1]["over_limit"] == 0
    assert episodes[2]["success"] == 1 and episodes[2]["over_limit"] == 1
    assert episodes[3]["cost_per_step"] == 0 and episodes[3]["over_limit"] == 0


def test_a_failed_episode_counts_its_steps_up_to_and_including_the_failing_one(run):
    _, _, res = run
    kwargs = {**res["scenarios"]["paper"]["env_kwargs"], **RATE}
    costs = _by_hand(kwargs, 0)["costs"][:, 0]
    failed = next(e for e in res["episodes"] if e["policy"] == NAME and e["seed"] == 0)
    assert failed["success"] == 0 and costs[-1] >= 1  # the failing step costs
    assert failed["cost_per_step"] == pytest.approx(costs.sum() / len(costs), rel=1e-12)
    # neither without the failing step nor over a full episode's 754 steps
    assert failed["cost_per_step"] != pytest.approx(costs[:-1].sum() / (len(costs) - 1))
    assert failed["cost_per_step"] != pytest.approx(costs.sum() / 754)


def test_results_json_carries_cost_per_policy_and_scenario(run):
    _, _, res = run
    values = [e["cost_per_step"] for e in res["episodes"] if e["policy"] == NAME]
    over = [e["over_limit"] for e in res["episodes"] if e["policy"] == NAME]
    block = res["policies"][NAME]
    # one run, one scenario: the IQM is of the run's mean over its episodes
    assert block["cost_per_step"] == pytest.approx(np.mean(values), rel=1e-12)
    assert block["over_limit"] == sum(over) / len(over) == 0.5  # raw fraction, not an IQM
    assert block["over_limit_count"] == 2 and block["n_episodes"] == 4
    assert block["ci95"]["cost_per_step"] is None and block["ci95"]["over_limit"] is None
    for part in ("slack", "length", "tumble"):
        assert f"cost_{part}_per_step" in block
    per = res["per_scenario"]["paper"][NAME]
    assert per["cost_per_step"] == pytest.approx(np.mean(values), rel=1e-12)
    assert per["over_limit"] == 0.5 and per["over_limit_count"] == 2
    smc = [e for e in res["episodes"] if e["policy"] == "smc"]
    assert res["policies"]["smc"]["over_limit_count"] == sum(e["over_limit"] for e in smc)


def _row(text: str, policy: str) -> dict:
    """The main table's cells of ``policy``, keyed by the header."""
    lines = text.splitlines()
    header = next(line for line in lines if line.startswith("| policy |"))
    keys = [c.strip() for c in header.strip("|").split("|")]
    row = next(line for line in lines if line.startswith(f"| {policy} |"))
    return dict(zip(keys, [c.strip() for c in row.strip("|").split("|")], strict=True))


def test_the_printed_table_shows_cost_per_step_and_the_fraction_over_the_limit(run):
    _, out, res = run
    row = _row(out, NAME)
    assert row["over cost limit"] == "0.500 (2/4)"
    assert row["cost/step [-]"] == f"{res['policies'][NAME]['cost_per_step']:.3f}"
    assert row["success rate"] == "0.750 (3/4)"  # every existing column is kept
    smc = _row(out, "smc")
    count = res["policies"]["smc"]["over_limit_count"]
    assert re.fullmatch(rf"\d\.\d{{3}} \({count}/4\)", smc["over cost limit"])
    assert f"mean cost per step > {COST_LIMIT:g}" in out
    per_scenario = out[out.index("Per scenario: cost/step"):]
    assert "| paper |" in per_scenario


def _fmt(x: float) -> str:
    """A table number: 3 decimals in [0.01, 1e4) and for 0, else 2 significant digits."""
    return f"{x:.3f}" if x == 0 or 0.01 <= abs(x) < 1e4 else f"{x:.2g}"


def _fake_results(cost: np.ndarray, over: np.ndarray) -> dict:
    """build_results of one policy with 3 runs x 2 scenarios x 2 seeds; min_tension and
    success carry the same numbers as cost_per_step and over_limit."""
    runs, scens, seeds = cost.shape
    episodes = []
    for r in range(runs):
        for j in range(scens):
            for s in range(seeds):
                c, o = float(cost[r, j, s]), float(over[r, j, s])
                ep = {"policy": "p", "run": r, "scenario": f"s{j}", "seed": s,
                      "cost_per_step": c, "min_tension": c, "over_limit": o, "success": o}
                for m in ("tracking_rms", "final_error", "converge_orbits", "reel_effort",
                          "reel_excursion", "chattering", "return",
                          "cost_slack_per_step", "cost_length_per_step",
                          "cost_tumble_per_step", "slack", "tumble", "length"):
                    ep.setdefault(m, 0.0)
                episodes.append(ep)
    spec = SimpleNamespace(name="p", n_runs=runs, kind=registry.PolicyKind.RL,
                           runs=[None] * runs, env_kwargs={})
    settings = [SimpleNamespace(scenario=SimpleNamespace(name=f"s{j}", description="",
                                                         nominal=None), env_kwargs={})
                for j in range(scens)]
    return build_results([spec], settings, list(range(seeds)), episodes, env_kwargs={},
                         suite="x")


def test_with_several_runs_cost_cells_get_the_intervals_of_the_other_metrics():
    rng = np.random.default_rng(5)
    cost = rng.uniform(0.0, 0.03, size=(3, 2, 2))
    over = (cost > COST_LIMIT).astype(float)
    res = _fake_results(cost, over)
    block = res["policies"]["p"]
    # the same numbers under another metric's name get the same IQM and interval
    assert block["cost_per_step"] == block["min_tension"]
    assert block["ci95"]["cost_per_step"] == block["ci95"]["min_tension"]
    scores = run_scores(res["episodes"], "cost_per_step", [0, 1, 2], ["s0", "s1"])
    assert block["ci95"]["cost_per_step"] == stratified_bootstrap_ci(scores)
    lo, hi = block["ci95"]["cost_per_step"]
    assert lo < hi
    # over the limit: a raw fraction of all episodes with success's interval over runs
    assert block["over_limit"] == block["success"] == over.mean()
    assert block["over_limit_count"] == int(over.sum())
    assert block["ci95"]["over_limit"] == block["ci95"]["success"] is not None
    for j in range(2):
        per = res["per_scenario"][f"s{j}"]["p"]
        assert per["over_limit"] == over[:, j].mean()
        assert per["ci95"]["over_limit"] == per["ci95"]["success"]
        assert per["ci95"]["cost_per_step"] == per["ci95"]["min_tension"]
    row = _row(markdown_tables(res), "p")
    olo, ohi = block["ci95"]["over_limit"]
    assert row["over cost limit"] == (f"{_fmt(over.mean())} ({int(over.sum())}/12) "
                                      f"[{_fmt(olo)}, {_fmt(ohi)}]")
    assert row["cost/step [-]"] == (f"{_fmt(block['cost_per_step'])} "
                                    f"[{_fmt(lo)}, {_fmt(hi)}]")
    assert not math.isnan(block["cost_per_step"])


@pytest.mark.skipif("ppo" not in pretrained_agents(), reason="no shipped PPO agent")
def test_ten_shipped_runs_get_cost_intervals_over_runs(tmp_path):
    """evaluate.py ppo on the robust suite: 10 training runs x 5 scenarios x 2 seeds."""
    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        code = main(["ppo", "--suite", "robust", "--seeds", "2", "--env-kwargs",
                     "orbits_per_episode=0.5", "--out", str(tmp_path), "--no-plots"])
    assert code == 0
    res = json.loads((tmp_path / "results.json").read_text())
    eps = res["episodes"]
    block = res["policies"]["ppo"]
    runs, scens = sorted({e["run"] for e in eps}), list(res["scenarios"])
    assert len(runs) == 10 and len(eps) == 10 * len(scens) * 2
    assert any(e["cost_per_step"] > 0 for e in eps)  # something to aggregate
    # IQM of the (run, scenario) means, by hand
    cells = np.array([[np.mean([e["cost_per_step"] for e in eps
                                if e["run"] == r and e["scenario"] == s]) for s in scens]
                      for r in runs])
    assert block["cost_per_step"] == pytest.approx(trim_mean(cells.ravel(), 0.25), rel=1e-12)
    assert block["ci95"]["cost_per_step"] == pytest.approx(stratified_bootstrap_ci(cells))
    # over the limit: the raw fraction of all episodes, resampled over runs per scenario
    over = np.array([[sum(e["over_limit"] for e in eps if e["run"] == r and e["scenario"] == s)
                      for s in scens] for r in runs])
    assert block["over_limit"] == over.sum() / len(eps)
    assert block["over_limit_count"] == over.sum()
    idx = np.random.default_rng(BOOTSTRAP_SEED).integers(0, 10, size=(N_BOOTSTRAP, 10,
                                                                     len(scens)))
    boot = over[idx, np.arange(len(scens))].sum(axis=(1, 2)) / len(eps)
    assert block["ci95"]["over_limit"] == pytest.approx(list(np.percentile(boot, [2.5, 97.5])))
    row = _row(buffer.getvalue(), "ppo")
    lo, hi = block["ci95"]["cost_per_step"]
    assert row["cost/step [-]"] == f"{_fmt(block['cost_per_step'])} [{_fmt(lo)}, {_fmt(hi)}]"
    olo, ohi = block["ci95"]["over_limit"]
    assert row["over cost limit"] == (f"{_fmt(block['over_limit'])} ({int(over.sum())}/{len(eps)})"
                                      f" [{_fmt(olo)}, {_fmt(ohi)}]")
