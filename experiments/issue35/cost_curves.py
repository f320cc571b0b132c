"""Return and cost against env steps for the ppo_lag seed runs (issue 35).

Reads each seed run's training record: ``eval/evaluations.npz`` (the training's own
evaluation return, 5 episodes every 200k steps) and the TensorBoard scalars that
PPOLagrangian logs once per rollout of 4096 steps (``train/cost_rate``: the rollout's
mean cost per step J_c; ``train/lagrange_multiplier``). Writes ``cost_curves.json``
(per seed, every 50th rollout and the last), ``cost_curves.md`` (median and range over
seeds at 0.5M-step marks) and ``cost_curves.png``.

    python experiments/issue35/cost_curves.py runs/ppo_lag --out docs/curves/ppo_lag
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from tether_gym.tasks.cost import COST_LIMIT


def _scalars(tb_dir: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    out: dict[str, tuple[list, list]] = {}
    for events in sorted(tb_dir.rglob("events.out.tfevents.*")):
        acc = EventAccumulator(str(events), size_guidance={"scalars": 0})
        acc.Reload()
        for tag in ("train/cost_rate", "train/lagrange_multiplier"):
            if tag in acc.Tags()["scalars"]:
                steps, values = out.setdefault(tag, ([], []))
                for e in acc.Scalars(tag):
                    steps.append(e.step)
                    values.append(e.value)
    return {tag: (np.array(s), np.array(v)) for tag, (s, v) in out.items()}


def seed_curves(run: Path) -> dict:
    with np.load(run / "eval" / "evaluations.npz", allow_pickle=False) as data:
        ret_steps, returns = data["timesteps"], data["results"].mean(axis=1)
    scalars = _scalars(run / "tb")
    steps, cost = scalars["train/cost_rate"]
    _, lam = scalars["train/lagrange_multiplier"]
    order = np.argsort(steps, kind="stable")
    steps, cost, lam = steps[order], cost[order], lam[order]
    return {"return_steps": ret_steps.tolist(), "return": returns.tolist(),
            "rollout_steps": steps.tolist(), "cost_rate": cost.tolist(),
            "lagrange_multiplier": lam.tolist()}


def _at(steps, values, mark, window=500_000):
    """Mean of the values logged in (mark - window, mark]."""
    steps, values = np.asarray(steps), np.asarray(values)
    sel = (steps > mark - window) & (steps <= mark)
    return float(values[sel].mean()) if sel.any() else float("nan")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("root", type=Path)
    p.add_argument("--out", type=Path, required=True)
    args = p.parse_args()
    runs = sorted(args.root.glob("seed_*"), key=lambda d: int(d.name.split("_")[1]))
    curves = {run.name: seed_curves(run) for run in runs}
    args.out.mkdir(parents=True, exist_ok=True)
    keep = {}
    for name, c in curves.items():
        idx = sorted(set(range(0, len(c["rollout_steps"]), 50)) | {len(c["rollout_steps"]) - 1})
        keep[name] = {**{k: c[k] for k in ("return_steps", "return")},
                      **{k: [c[k][i] for i in idx] for k in
                         ("rollout_steps", "cost_rate", "lagrange_multiplier")}}
    (args.out / "cost_curves.json").write_text(json.dumps(
        {"cost_limit": COST_LIMIT, "seeds": keep}, indent=1))
    marks = list(range(500_000, 5_500_001, 500_000))
    lines = [f"ppo_lag, {len(runs)} seeds: the training's evaluation return (5 episodes) "
             "and, per rollout, the mean cost per step J_c and lambda, each averaged over "
             "the 0.5M steps up to the mark; median [min, max] over seeds. Cost limit "
             f"{COST_LIMIT}.", "",
             "| env steps | eval return | J_c (training) | lambda |", "|---|---|---|---|"]
    for mark in marks:
        cells = []
        for key, steps_key in (("return", "return_steps"), ("cost_rate", "rollout_steps"),
                               ("lagrange_multiplier", "rollout_steps")):
            vals = [_at(c[steps_key], c[key], mark) for c in curves.values()]
            cells.append(f"{np.nanmedian(vals):.4g} [{np.nanmin(vals):.3g}, "
                         f"{np.nanmax(vals):.3g}]")
        lines.append(f"| {mark / 1e6:.1f}M | " + " | ".join(cells) + " |")
    (args.out / "cost_curves.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 3.8))
    for name, c in curves.items():
        axes[0].plot(np.array(c["return_steps"]) / 1e6, c["return"], label=name)
        k = 25  # a moving mean over 25 rollouts (100k steps)
        rate = np.convolve(c["cost_rate"], np.ones(k) / k, mode="valid")
        axes[1].plot(np.array(c["rollout_steps"][k - 1:]) / 1e6, rate, label=name)
        axes[2].plot(np.array(c["rollout_steps"]) / 1e6, c["lagrange_multiplier"], label=name)
    axes[1].axhline(COST_LIMIT, color="k", ls="--", lw=1, label="cost limit")
    axes[1].set_yscale("symlog", linthresh=1e-3)
    for ax, title in zip(axes, ("training eval return (5 episodes)",
                                "mean cost per step J_c (training, 100k-step mean)",
                                "Lagrange multiplier lambda"), strict=True):
        ax.set_xlabel("env steps [M]")
        ax.set_title(title, fontsize=9)
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(args.out / "cost_curves.png", dpi=110)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
