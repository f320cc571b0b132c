"""Benchmark any mix of policies on a scenario suite through one evaluation path.

``python evaluate.py`` evaluates the shipped PPO and SAC agents beside the
sliding-mode and open-loop baselines on the default suite and prints a markdown
table; ``python evaluate.py --paper --out DIR`` reproduces the paper's figures
instead (:mod:`tether_gym_agents.paper`).

Every policy, baseline or trained, is run by stable-baselines3's
``evaluate_policy`` on the same vectorised environment (one sub-env per seed,
seeded ``seed + i``), and every episode's per-step ``info`` is turned into the
metrics of :mod:`tether_gym_agents.metrics`.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import tether_gym
from tether_gym.physics import TetherChain

from .metrics import aggregate, episode_metrics
from .scenarios import Scenario, get_suite

__all__ = ["main", "evaluate", "make_policy", "BASELINES"]

BASELINES = ("smc", "zero", "periodic", "random")
TABLE_COLUMNS = (
    ("success", "success_rate"),
    ("tracking_rms", "tracking RMS [rad]"),
    ("final_error", "last-orbit max err [rad]"),
    ("converge_orbits", "converge [orbits]"),
    ("min_tension", "min T^ [-]"),
    ("reel_effort", "reel effort [-]"),
    ("reel_excursion", "reel excursion [-]"),
    ("chattering", "chattering [-]"),
)
FAILURES = ("slack", "tumble", "length")


def make_policy(name: str, env, scenario: Scenario | None = None, seed: int = 0):
    """Policy object with ``predict`` for a baseline name or a trained-agent path."""
    from .open_loop import PeriodicReel, RandomPolicy, ZeroStateReel
    from .smc import SlidingModeController
    from .trained import TrainedAgent, pretrained_agents

    if name == "smc":
        nominal = None
        if scenario is not None and scenario.nominal is not None:
            cfg = env.unwrapped.config
            nominal = TetherChain(scenario.nominal["masses"], scenario.nominal["eccentricity"],
                                  cfg.gravity, cfg.total_tether_length / cfg.semi_latus_rectum)
        return SlidingModeController.for_env(env, nominal=nominal)
    if name == "zero":
        return ZeroStateReel.for_env(env)
    if name == "periodic":
        return PeriodicReel.for_env(env)
    if name == "random":
        return RandomPolicy(env, seed=seed)
    shipped = pretrained_agents()
    if name in shipped:
        return TrainedAgent.load(shipped[name])
    if Path(name).exists():
        return TrainedAgent.load(name)
    valid = list(BASELINES) + sorted(shipped)
    raise ValueError(f"unknown policy {name!r}: give one of {valid} or a path to a trained "
                     "agent (run folder or .zip)")


def _run_scenario(policy_name: str, scenario: Scenario, seeds: list[int], record: bool):
    """Episodes of one policy on one scenario: (list of metric dicts, infos of seed 0)."""
    from stable_baselines3.common.evaluation import evaluate_policy

    from .vec_env import make_sb3_vec_env

    env_kwargs = dict(scenario.env_kwargs)
    probe = gym.make(tether_gym.ENV_ID, **env_kwargs)
    policy = make_policy(policy_name, probe, scenario, seed=seeds[0])
    cfg = probe.unwrapped.config
    probe.close()
    venv = make_sb3_vec_env(len(seeds), seed=None, env_kwargs=env_kwargs)
    venv.seed(seeds[0])
    num = len(seeds)
    infos = [[] for _ in range(num)]
    rewards = [[] for _ in range(num)]
    finished = [None] * num
    nu0 = [None] * num

    def callback(local_vars, _globals):
        i = local_vars["i"]
        info = local_vars["info"]
        if finished[i] is not None:
            return
        if nu0[i] is None:
            nu0[i] = info["nu"] - cfg.control_step
        infos[i].append(info)
        rewards[i].append(float(local_vars["reward"]))
        if local_vars["done"]:
            finished[i] = bool(info.get("TimeLimit.truncated", False))

    evaluate_policy(policy, venv, n_eval_episodes=num, deterministic=True, callback=callback,
                    warn=False)
    venv.close()
    episodes = [episode_metrics(infos[i], rewards[i], nu0[i], cfg.control_step, finished[i])
                for i in range(num)]
    return episodes, (infos[0] if record else None)


def evaluate(policies: list[str], suite: str = "default", n_seeds: int = 10, seed: int = 0,
             out: Path | None = None, plots: bool = True, log=print) -> dict:
    """Evaluate ``policies`` on every scenario of ``suite``; return the results dict."""
    scenarios = get_suite(suite)
    seeds = [seed + i for i in range(n_seeds)]
    results = {"suite": suite, "seeds": seeds, "policies": {}, "scenarios": {},
               "scenario_descriptions": {s.name: s.description for s in scenarios}}
    trajectories = {}
    for name in policies:
        t0 = time.perf_counter()
        all_eps = []
        for sc in scenarios:
            episodes, traj = _run_scenario(name, sc, seeds, record=(sc.name == scenarios[0].name))
            all_eps.extend(episodes)
            results["scenarios"].setdefault(sc.name, {})[name] = aggregate(episodes)
            if traj is not None:
                trajectories[name] = traj
        agg = aggregate(all_eps)
        agg["success_rate"] = agg["success"]
        results["policies"][name] = agg
        log(f"  evaluated {name:>10s} on {len(scenarios)} scenarios x {n_seeds} seeds "
            f"in {time.perf_counter() - t0:.1f} s")
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        with open(out / "results.json", "w") as fh:
            json.dump(results, fh, indent=2, default=float)
        if plots:
            _plots(results, trajectories, out, log)
    return results


def _fmt(mean: float, half: float, n: int) -> str:
    if not math.isfinite(mean):
        return "n/a"
    digits = 3 if abs(mean) >= 0.01 or mean == 0 else 2
    fmt = f"{{:.{digits}g}}" if abs(mean) < 0.01 and mean != 0 else "{:.3f}"
    text = fmt.format(mean)
    if n > 1 and math.isfinite(half):
        text += " +- " + fmt.format(half)
    return text


def markdown_table(results: dict) -> str:
    """Overall table (policy x metric, mean +- 95 % CI) and a per-scenario breakdown."""
    lines = ["| policy | " + " | ".join(title for _, title in TABLE_COLUMNS)
             + " | failures slack/tumble/length |",
             "|---" * (len(TABLE_COLUMNS) + 2) + "|"]
    for name, agg in results["policies"].items():
        cells = [_fmt(agg[k], agg[f"{k}_ci95"], agg[f"{k}_n"]) for k, _ in TABLE_COLUMNS]
        counts = "/".join(str(round(agg[f] * agg[f"{f}_n"])) for f in FAILURES)
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {counts} |")
    names = list(results["policies"])
    lines += ["", "Per scenario: success rate / tracking RMS after orbit 1 [rad]", "",
              "| scenario | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
    for sc, per in results["scenarios"].items():
        cells = [f"{per[p]['success']:.2f} / " + (f"{per[p]['tracking_rms']:.2e}"
                                                  if math.isfinite(per[p]["tracking_rms"])
                                                  else "n/a") for p in names]
        lines.append(f"| {sc} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _plots(results: dict, trajectories: dict, out: Path, log) -> None:
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        log('  (plots skipped: matplotlib is missing; pip install "tether_gym[plot]")')
        return
    fig = Figure(figsize=(10, 6.5), layout="constrained")
    FigureCanvasAgg(fig)
    ax_err, ax_len = fig.subplots(2, 1, sharex=True)
    for name, infos in trajectories.items():
        nu = np.array([i["nu"] for i in infos]) / (2 * np.pi)
        err = np.array([np.abs(i["theta"] - i["theta_ref"]).max() for i in infos])
        total = np.array([i["length"].sum() for i in infos])
        ax_err.semilogy(nu, np.maximum(err, 1e-7), label=name)
        ax_len.plot(nu, total, label=name)
    ax_err.set_ylabel("max |theta - theta_d| [rad]")
    ax_err.set_title("paper case (Sec. 4.3), seed 0")
    ax_err.legend(ncol=3, fontsize=8)
    ax_len.set_ylabel("l1 + ... + l_n [-]")
    ax_len.set_xlabel("true anomaly [orbits]")
    fig.savefig(out / "trajectories.png", dpi=100)
    fig = Figure(figsize=(12, 6), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 4).ravel()
    names = list(results["policies"])
    for ax, (key, title) in zip(axes, TABLE_COLUMNS, strict=True):
        means = [results["policies"][p][key] for p in names]
        halves = [results["policies"][p][f"{key}_ci95"] for p in names]
        ax.bar(range(len(names)), np.nan_to_num(means), yerr=np.nan_to_num(halves), capsize=3)
        ax.set_xticks(range(len(names)), names, rotation=45, fontsize=8)
        ax.set_title(title, fontsize=9)
        if key in ("tracking_rms", "final_error", "chattering") and max(np.nan_to_num(means)) > 0:
            ax.set_yscale("log")
    fig.savefig(out / "metrics.png", dpi=100)
    log(f"  wrote {out / 'trajectories.png'} and {out / 'metrics.png'}")


def main(argv=None) -> int:
    """Command line of ``evaluate.py``; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--paper" in argv:
        from .paper import main as paper_main

        argv.remove("--paper")
        return paper_main(argv)
    from .trained import pretrained_agents

    parser = argparse.ArgumentParser(
        prog="evaluate.py",
        description="Benchmark policies on a tether_gym scenario suite (or --paper to "
                    "reproduce the paper's figures).")
    parser.add_argument("policies", nargs="*",
                        help="smc, zero, periodic, random, ppo, sac (shipped agents) or paths "
                             "to trained agents; default: all baselines and shipped agents")
    parser.add_argument("--suite", default="default", help="scenario suite (default: default)")
    parser.add_argument("--seeds", type=int, default=10, help="seeds per scenario (default 10)")
    parser.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    parser.add_argument("--out", type=Path, default=Path("runs/eval"),
                        help="folder for results.json and plots (default runs/eval)")
    parser.add_argument("--no-plots", action="store_true", help="skip the plots")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error(f"--seeds must be >= 1, got {args.seeds}")
    policies = args.policies or list(BASELINES) + sorted(pretrained_agents())
    try:
        get_suite(args.suite)
        t0 = time.perf_counter()
        print(f"tether_gym {tether_gym.__version__}: {len(policies)} policies on suite "
              f"{args.suite!r}, {args.seeds} seeds per scenario")
        results = evaluate(policies, args.suite, args.seeds, args.seed, args.out,
                           plots=not args.no_plots)
    except ValueError as exc:
        print(f"evaluate.py: error: {exc}", file=sys.stderr)
        return 2
    print()
    print(markdown_table(results))
    print(f"\nresults: {args.out / 'results.json'} ({time.perf_counter() - t0:.0f} s)")
    return 0
