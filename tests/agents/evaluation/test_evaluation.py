"""evaluate.py in-process with tiny settings: CLI, invariance, results.json, plots."""

from __future__ import annotations

import hashlib
import json
import math
import re
import shutil

import numpy as np
import pytest

from tether_gym_agents.cli.evaluate import main
from tether_gym_agents.evaluation import benchmark as evaluation
from tether_gym_agents.evaluation import registry
from tether_gym_agents.evaluation.metrics import METRICS
from tether_gym_agents.evaluation.rollout import Trajectory
from tether_gym_agents.evaluation.scenarios import SUITES, Scenario, get_suite
from tether_gym_agents.files.trained import pretrained_agents

SHORT = ["--suite", "paper", "--env-kwargs", "orbits_per_episode=0.2"]
SHORT_KWARGS = {"orbits_per_episode": 0.2}
needs_ppo = pytest.mark.skipif("ppo" not in pretrained_agents(), reason="no shipped PPO agent")


def _strict_load(text: str):
    def reject(token):
        raise ValueError(f"non-standard JSON token {token}")

    return json.loads(text, parse_constant=reject)


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("eval")
    code = main(["smc", "random", "--seeds", "2", *SHORT, "--out", str(out)])
    return code, out


def _episodes(results, policy):
    return {(e["scenario"], e["seed"], e["run"]): {m: e[m] for m in METRICS}
            for e in results["episodes"] if e["policy"] == policy}


def _same(a: dict, b: dict) -> bool:
    return all(a[k] == b[k] or (math.isnan(a[k]) and math.isnan(b[k])) for k in a)


# --------------------------------------------------------------------------- #
# results.json
# --------------------------------------------------------------------------- #
def test_results_json_is_strict_with_meta_and_episodes(short_run):
    code, out = short_run
    assert code == 0
    text = (out / "results.json").read_text()
    assert not re.search(r"[:\[,]\s*-?(NaN|Infinity)\b", text)  # no bare tokens
    res = _strict_load(text)
    meta = res["meta"]
    assert meta["versions"]["tether_gym"] and meta["versions"]["numpy"]
    assert meta["command"].startswith("evaluate.py smc random --seeds 2")
    assert "git_commit" in meta and meta["threads"]["numba"] >= 1
    assert set(res["policies"]) == {"smc", "random"}
    for block in res["policies"].values():
        assert block["kind"] == "baseline" and block["n_runs"] == 1
        assert set(METRICS) <= set(block) and set(block["ci95"]) == set(METRICS)
        assert set(block["probability_of_improvement"]) == set(METRICS)
        # 0.2-orbit episodes never reach orbit 1: the RMS after it is undefined -> null
        assert block["tracking_rms"] is None
    assert res["policies"]["smc"]["probability_of_improvement"]["success"] == 0.5
    # one record per (policy, run, scenario, seed) with every metric
    assert len(res["episodes"]) == 2 * 1 * 1 * 2
    for ep in res["episodes"]:
        assert {"policy", "run", "scenario", "seed"} | set(METRICS) <= set(ep)
    # success is the raw surviving fraction of all episodes, with its worst scenario
    for name, block in res["policies"].items():
        succ = [e["success"] for e in res["episodes"] if e["policy"] == name]
        assert block["success"] == block["success_rate"] == sum(succ) / len(succ)
        assert block["survived"] == sum(succ) and block["n_episodes"] == len(succ)
        assert block["worst_scenario"] == "paper"  # the only scenario
        assert block["worst_scenario_success"] == block["success_rate"]
        # compute per control step: one timed episode, median <= p99, both > 0 ms
        assert 0 < block["compute_ms_per_step"] <= block["compute_ms_per_step_p99"]
    assert (out / "trajectories.png").is_file() and (out / "metrics.png").is_file()


def test_seed_folder_is_one_policy_with_several_runs(tmp_path):
    shipped = pretrained_agents()
    if "ppo" not in shipped:
        pytest.skip("no shipped PPO agent")
    folder = tmp_path / "ppo_runs"
    for k in (0, 1):  # the first shipped run, twice
        shutil.copytree(registry.resolve_policy("ppo").runs[0], folder / f"seed_{k}")
    res = evaluation.evaluate(["smc", str(folder)], "paper", 2, out=tmp_path / "o", plots=False,
                              log=None, env_kwargs=SHORT_KWARGS)
    block = res["policies"][str(folder)]
    assert block["kind"] == "rl" and block["n_runs"] == 2
    runs = _episodes(res, str(folder))
    assert {key[2] for key in runs} == {0, 1}
    # the two runs are the same agent: identical episodes, an interval of zero width
    for (sc, seed, run), metrics in runs.items():
        if run == 0:
            assert _same(metrics, runs[(sc, seed, 1)])
    lo, hi = block["ci95"]["min_tension"]
    assert lo == hi == pytest.approx(block["min_tension"])
    per = res["per_scenario"]["paper"][str(folder)]
    assert per["ci95"]["min_tension"] == [per["min_tension"]] * 2 or \
        tuple(per["ci95"]["min_tension"]) == (per["min_tension"],) * 2
    assert res["per_scenario"]["paper"]["smc"]["ci95"]["min_tension"] is None  # one run
    files = res["meta"]["agents"][str(folder)][1]["files"]
    for name, digest in files.items():
        data = (folder / "seed_1" / name).read_bytes()
        assert hashlib.sha256(data).hexdigest() == digest


# --------------------------------------------------------------------------- #
# evaluation that does not move (issue 13)
# --------------------------------------------------------------------------- #
@needs_ppo
def test_episodes_do_not_depend_on_seed_count_threads_or_order():
    kwargs = dict(out=None, log=None, env_kwargs={"orbits_per_episode": 0.3})
    names = ["smc", "smc_filtered", "random", "ppo", "handover:ppo"]
    two = evaluation.evaluate(names, "paper", 2, **kwargs)
    five = evaluation.evaluate(names[::-1], "paper", 5, torch_threads=2, **kwargs)
    try:
        for policy in names:
            a, b = _episodes(two, policy), _episodes(five, policy)
            assert set(a) <= set(b)
            for key in a:
                assert _same(a[key], b[key]), (policy, key)
    finally:
        import torch

        torch.set_num_threads(1)


# --------------------------------------------------------------------------- #
# command line
# --------------------------------------------------------------------------- #
def test_help_lists_the_suites_and_their_scenarios(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    for suite, scenarios in SUITES.items():
        assert f"suite {suite!r}" in text
        for sc in scenarios:
            assert sc.name in text and sc.description in text
    assert "--env-kwargs" in text and "paper --out" in text


@pytest.mark.parametrize("argv", [["paper", "--help"], ["--paper", "--help"]])
def test_paper_is_a_subcommand(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 0
    assert "--orbits" in capsys.readouterr().out


@pytest.mark.parametrize("argv, flag", [
    (["--env-kwargs", "masses=(1,2"], "--env-kwargs"),
    (["--env-kwargs", "masses"], "--env-kwargs"),
    (["--env-kwargs", "eccentricity=2.0"], "eccentricity"),
    (["--seeds", "0"], "--seeds"),
    (["--seeds", "1001"], "--seeds"),
    (["--seeds", "1000000000"], "--seeds"),
    (["--seed", "-1"], "--seed"),
    (["--torch-threads", "0"], "--torch-threads"),
    (["--suite", "nope"], "nope"),
    (["no_such_policy"], "no_such_policy"),
])
def test_bad_arguments_fail_with_one_line(argv, flag, tmp_path, capsys):
    code = main(["smc", *argv, "--out", str(tmp_path / "o")])
    captured = capsys.readouterr()
    assert code == 2
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("evaluate.py: error:") and flag in lines[0]
    assert "Traceback" not in captured.err
    assert "[1/" not in captured.out  # nothing was evaluated
    assert not (tmp_path / "o" / "results.json").exists()


def test_out_that_is_a_file_or_unwritable_fails_before_evaluating(tmp_path, capsys):
    target = tmp_path / "file.txt"
    target.write_text("x")
    for out, words in ((target, "is a file"), (target / "sub", "not a writable folder")):
        code = main(["smc", *SHORT, "--seeds", "1", "--out", str(out)])
        captured = capsys.readouterr()
        assert code == 2 and "--out" in captured.err and words in captured.err
        assert "building" not in captured.out and "[1/" not in captured.out


def test_every_agent_is_checked_before_anything_runs(tmp_path, capsys):
    if "ppo" not in pretrained_agents():
        pytest.skip("no shipped PPO agent")
    code = main(["smc", "ppo", *SHORT, "n_bodies=4", "--seeds", "1",
                            "--out", str(tmp_path)])
    captured = capsys.readouterr()
    assert code == 2
    # which agent, the N it was trained on and the N asked for
    assert "'ppo'" in captured.err and "n_bodies=3" in captured.err
    assert "n_bodies=4" in captured.err
    assert "[1/" not in captured.out  # smc did not run first
    assert not (tmp_path / "results.json").exists()


def test_env_kwargs_apply_to_every_scenario(tmp_path, capsys):
    code = main(["smc", "zero", *SHORT, "n_bodies=4", "--seeds", "1",
                            "--out", str(tmp_path), "--no-plots"])
    assert code == 0
    res = json.loads((tmp_path / "results.json").read_text())
    assert res["env_kwargs"] == {"orbits_per_episode": 0.2, "n_bodies": 4}
    assert res["scenarios"]["paper"]["env_kwargs"]["n_bodies"] == 4
    assert res["policies"]["smc"]["success"] == 1.0
    out = capsys.readouterr().out
    # progress: one line before the first env is built, one per policy and scenario
    assert out.index("building") < out.index("[1/2] smc: scenario 1/1 paper")
    assert "[2/2] zero: scenario 1/1 paper" in out


def test_scenario_tuples_follow_n_bodies():
    sc = get_suite("default")[1]
    assert sc.env_kwargs["initial_theta"] == (0.0, 0.0)
    assert sc.env_kwargs_with({"n_bodies": 4})["initial_theta"] == (0.0, 0.0, 0.0)
    assert sc.env_kwargs_with({"n_bodies": 4, "initial_theta": (0.1, 0, 0)})[
        "initial_theta"] == (0.1, 0, 0)


def test_suite_file(tmp_path):
    path = tmp_path / "suite.yml"
    path.write_text("scenarios:\n"
                    "  - name: circular\n"
                    "    description: circular orbit, short\n"
                    "    env_kwargs: {eccentricity: 0.0, orbits_per_episode: 0.1}\n"
                    "  - name: mismatch\n"
                    "    env_kwargs: {masses: [1.2, 1.6], orbits_per_episode: 0.1}\n"
                    "    nominal: {masses: [1.0, 2.0], eccentricity: 0.2}\n")
    res = evaluation.evaluate(["smc"], str(path), 1, out=None, log=None)
    assert list(res["scenarios"]) == ["circular", "mismatch"]
    assert res["scenarios"]["mismatch"]["env_kwargs"]["masses"] == (1.2, 1.6)
    bad = tmp_path / "bad.yml"
    bad.write_text("scenarios:\n  - name: x\n    env_kwarg: {}\n")
    with pytest.raises(ValueError, match="unknown keys \\['env_kwarg'\\]"):
        get_suite(str(bad))


# --------------------------------------------------------------------------- #
# plots
# --------------------------------------------------------------------------- #
def _fake_trajectory(failure):
    k = np.arange(11)
    nu = 0.025 * k
    two = np.zeros((11, 2))
    return Trajectory(nu=nu, theta=two + 0.01, dtheta=two, length=two + 0.5, dlength=two,
                      tension=two + 1, tension_min=two + 1, theta_ref=np.zeros(11),
                      reel_accel=two, action=two[1:], command=two[1:], reward=np.zeros(10),
                      failure=failure, truncated=failure is None, seed=3,
                      settings={"control_step": 0.025})


def test_plots_mark_failures_title_the_scenario_and_skip_undefined(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    from matplotlib.figure import Figure

    from tether_gym_agents.evaluation.plots import plot_results

    saved = []
    monkeypatch.setattr(Figure, "savefig", lambda self, path, **kw: saved.append(self))
    block = {m: 0.5 for m in METRICS} | {"converge_orbits": math.nan}
    block["ci95"] = {m: (0.4, 0.6) for m in METRICS} | {"converge_orbits": None}
    results = {"suite": "x", "policies": {"a": block, "b": dict(block)}, "episodes": []}
    scenario = Scenario("windy", "a scenario with a name")
    plot_results(results, {"a": _fake_trajectory("slack"), "b": _fake_trajectory(None)},
                 scenario, tmp_path, log=None)
    _, traj_fig, metrics_fig = saved
    ax_err = traj_fig.axes[0]
    assert "windy" in ax_err.get_title() and "a scenario with a name" in ax_err.get_title()
    markers = [line for line in ax_err.get_lines() if line.get_marker() == "x"]
    assert len(markers) == 1  # only the failed episode, at its last sample
    assert markers[0].get_xdata()[0] == pytest.approx(0.25 / (2 * math.pi))
    assert any(t.get_text() == "slack" for t in ax_err.texts)
    ax_conv = next(ax for ax in metrics_fig.axes if ax.get_title() == "converge [orbits]")
    assert not ax_conv.patches and not ax_conv.get_lines()  # nothing drawn for NaN
    assert [t.get_text() for t in ax_conv.texts] == ["n/a", "n/a"]
    ax_succ = next(ax for ax in metrics_fig.axes if ax.get_title() == "success rate")
    assert len(ax_succ.get_lines()) == 4  # interval + point per policy


def test_env_kwargs_are_literals_never_code():
    from tether_gym_agents.common.env_kwargs import parse_env_kwargs

    parsed = parse_env_kwargs(["masses=(1,2.5)", "gravity=full", "obs_noise=1e-3",
                               "init_theta_range=None", "parallel=false"])
    assert parsed == {"masses": (1, 2.5), "gravity": "full", "obs_noise": 1e-3,
                      "init_theta_range": None, "parallel": False}
    for bad, words in (("x=__import__('os').system('true')", "not a Python literal"),
                       ("masses=(1,2", "not a Python literal"), ("1x=2", "not a valid"),
                       ("novalue", "key=value")):
        with pytest.raises(ValueError, match=words) as exc:
            parse_env_kwargs([bad])
        assert str(exc.value).startswith("--env-kwargs")
    with pytest.raises(ValueError, match="given twice"):
        parse_env_kwargs(["a=1", "a=2"])


@needs_ppo
def test_handover_names_a_hybrid_of_a_trained_agent():
    spec = registry.resolve_policy("handover:ppo")
    assert spec.kind is registry.PolicyKind.HYBRID and spec.handover
    assert spec.runs == registry.resolve_policy("ppo").runs
    # reel rates, and the observation its agent was trained on
    assert spec.env_kwargs == {"action_mode": "rate", "observe_params": False}
    assert registry.resolve_policy("ppo").env_kwargs == {  # the default mode made explicit
        "action_mode": "increment", "increment_gain": 0.5, "observe_params": False}
    assert "handover:ppo" in registry.default_policies()
    with pytest.raises(ValueError, match="acts alone"):
        registry.resolve_policy("handover:smc")
    with pytest.raises(ValueError, match="unknown policy"):
        registry.resolve_policy("handover:nothing")


def test_an_agent_is_evaluated_with_the_observation_it_was_trained_on(tmp_path):
    """An agent trained seeing e (observe_params="eccentricity") gets e on every
    scenario, alone and inside its handover hybrid, whose law still designs on its
    own model."""
    from tether_gym_agents.cli.train import main as train_main

    run = tmp_path / "seeing_e"
    assert train_main(["--out", str(run), "--timesteps", "256", "--n-envs", "2",
                       "--no-progress", "--eval-episodes", "1", "--env-kwargs",
                       "orbits_per_episode=0.05", "observe_params=eccentricity"]) == 0
    spec = registry.resolve_policy(str(run))
    assert spec.env_kwargs["observe_params"] == "eccentricity"
    hybrid = registry.resolve_policy("handover:" + str(run))
    assert hybrid.env_kwargs == {"action_mode": "rate", "observe_params": "eccentricity"}
    res = evaluation.evaluate([str(run), "handover:" + str(run)], "paper", 1,
                              out=tmp_path / "o", plots=False, log=None,
                              env_kwargs=SHORT_KWARGS)
    for name in (str(run), "handover:" + str(run)):
        assert res["policies"][name]["n_episodes"] == 1


def test_outputs_replace_a_link_or_fifo_in_out_instead_of_writing_through(tmp_path, capsys):
    """Before: a results.json symlinked to a file outside --out had that file overwritten
    with the results, and a FIFO named results.json made evaluate.py wait for ever (seen:
    killed by a 60 s timeout)."""
    import os
    import threading

    precious = tmp_path / "precious.txt"
    precious.write_text("keep")
    out = tmp_path / "out"
    out.mkdir()
    (out / "results.json").symlink_to(precious)
    (out / "profile.png").symlink_to(precious)
    os.mkfifo(out / "metrics.png")
    done = threading.Event()

    def run():
        assert main(["smc", "--suite", "paper", "--seeds", "1", "--env-kwargs",
                     "orbits_per_episode=0.05", "--out", str(out)]) == 0
        done.set()

    worker = threading.Thread(target=run, daemon=True)  # a blocked write must not hang
    worker.start()
    worker.join(120)
    assert done.is_set(), "evaluate.py did not finish (blocked on a FIFO?)"
    assert precious.read_text() == "keep"
    for name in ("results.json", "profile.png", "metrics.png"):
        assert (out / name).is_file() and not (out / name).is_symlink(), name
    assert json.loads((out / "results.json").read_text())["suite"] == "paper"
