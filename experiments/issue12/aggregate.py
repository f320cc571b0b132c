"""Aggregate the issue-12 ablation runs: tables (markdown + JSON) and learning curves.

    python experiments/issue12/aggregate.py

Reads runs/*/result.json and runs/*/curve.csv; writes summary.json, table.md and
curves_*.png beside this file. Per run: the mean over the suite's episodes of each
metric (tracking RMS over the episodes that survived). Per variant: median
[min, max] and IQM (scipy trim_mean 0.25; equal to the mean for n <= 3) over seeds.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from scipy.stats import trim_mean

HERE = Path(__file__).resolve().parent
RUNS = HERE / "runs"
ORDER = ["v0", "full", "full-R1", "full-R1+mix", "full-R2", "full-R3", "full-O1", "full-X1",
         "full+A1", "full+A1+mix", "full+A1-R1", "full+gSDE"]
COLS = [("default", "success", "success"),
        ("default", "tracking_rms_success", "RMS after orbit 1 [rad]"),
        ("default", "reel_excursion", "excursion [-]"), ("default", "reel_effort", "effort [-]"),
        ("default", "min_tension", "min T^ [-]"), ("gen", "success", "gen success"),
        ("gen", "tracking_rms_success", "gen RMS [rad]")]


def load():
    runs = {}
    for path in sorted(RUNS.glob("*/result.json")):
        r = json.loads(path.read_text())
        runs.setdefault(r["variant"], []).append(r)
    return runs


def fmt(x):
    if x is None or not math.isfinite(x):
        return "n/a"
    if abs(x) < 0.01 and x != 0:
        return f"{x:.2e}"
    return f"{x:.3f}" if abs(x) < 10 else f"{x:.1f}"


def stats(values):
    v = np.array([x for x in values if x is not None and math.isfinite(x)], dtype=float)
    if v.size == 0:
        return None
    return {"median": float(np.median(v)), "min": float(v.min()), "max": float(v.max()),
            "iqm": float(trim_mean(v, 0.25)), "values": [float(x) for x in values
                                                         if x is not None]}


def per_scenario(runs, suite):
    out = {}
    for r in runs:
        for e in r[f"episodes_{suite}"]:
            out.setdefault(e["scenario"], []).append(e)
    return {sc: {"success": float(np.mean([e["success"] for e in eps])),
                 "rms": (float(np.mean([e["tracking_rms"] for e in eps if e["success"]]))
                         if any(e["success"] for e in eps) else None),
                 "failures": sorted({str(e["failure"]) for e in eps if e["failure"]})}
            for sc, eps in out.items()}


def main():
    runs = load()
    variants = [v for v in ORDER if v in runs] + sorted(set(runs) - set(ORDER))
    summary = {}
    lines = ["| variant | n | " + " | ".join(c[2] for c in COLS) + " | train wall [s] |",
             "|---" * (len(COLS) + 3) + "|"]
    for v in variants:
        rs = sorted(runs[v], key=lambda r: r["seed"])
        entry = {"seeds": [r["seed"] for r in rs], "steps": [r["steps"] for r in rs],
                 "wall_train_s": [r["wall_train_s"] for r in rs],
                 "wall_eval_s": [r["wall_eval_s"] for r in rs]}
        cells = []
        for suite, key, _ in COLS:
            s = stats([r[suite][key] for r in rs])
            entry[f"{suite}.{key}"] = s
            cells.append("n/a" if s is None else
                         f"{fmt(s['median'])} [{fmt(s['min'])}, {fmt(s['max'])}]")
        entry["per_scenario_default"] = per_scenario(rs, "default")
        entry["per_scenario_gen"] = per_scenario(rs, "gen")
        summary[v] = entry
        walls = "/".join(f"{w:.0f}" for w in entry["wall_train_s"])
        lines.append(f"| {v} | {len(rs)} | " + " | ".join(cells) + f" | {walls} |")
    table = "\n".join(lines)
    # per-scenario success / RMS, pooled over seeds
    for suite in ("default", "gen"):
        scen = list(next(iter(summary.values()))[f"per_scenario_{suite}"]) if summary else []
        table += (f"\n\nPer scenario ({suite} suite), episodes pooled over seeds: "
                  "success / RMS after orbit 1 of survivors [rad]\n\n")
        table += "| variant | " + " | ".join(scen) + " |\n" + "|---" * (len(scen) + 1) + "|\n"
        for v in variants:
            ps = summary[v][f"per_scenario_{suite}"]
            table += f"| {v} | " + " | ".join(
                f"{ps[s]['success']:.2f} / {fmt(ps[s]['rms'])}" for s in scen) + " |\n"
    table += ("\nPer run (default suite; gen = own generalisation suite): wall times on "
              "the shared 2-core machine\n\n| run | steps | train wall [s] | steps/s "
              "| eval wall [s] | success | RMS [rad] | excursion | effort | min T^ "
              "| gen success | gen RMS [rad] |\n"
              + "|---" * 12 + "|\n")
    for v in variants:
        for r in sorted(runs[v], key=lambda r: r["seed"]):
            dd, g = r["default"], r["gen"]
            table += (f"| {v} s{r['seed']} | {r['steps']} | {r['wall_train_s']:.0f} | "
                      f"{r['steps_per_s']:.0f} | {r['wall_eval_s']:.0f} | {fmt(dd['success'])} | "
                      f"{fmt(dd['tracking_rms_success'])} | {fmt(dd['reel_excursion'])} | "
                      f"{fmt(dd['reel_effort'])} | {fmt(dd['min_tension'])} | "
                      f"{fmt(g['success'])} | {fmt(g['tracking_rms_success'])} |\n")
    (HERE / "table.md").write_text(table + "\n")
    (HERE / "summary.json").write_text(json.dumps(summary, indent=1, allow_nan=False))
    print(table)
    curves(runs, variants)


def curves(runs, variants):
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        print("matplotlib missing: no curves")
        return
    fig = Figure(figsize=(13, 8), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 2).ravel()
    colors = {}
    for v in variants:
        for r in runs[v]:
            path = RUNS / f"{v}_s{r['seed']}" / "curve.csv"
            if not path.is_file():
                continue
            data = np.genfromtxt(path, delimiter=",", names=True, dtype=None, encoding=None)
            if data.size < 5:
                continue
            step = data["step"].astype(float)
            bins = np.linspace(0, step.max(), 41)
            idx = np.digitize(step, bins)
            centers, succ, rms, exc, ret = [], [], [], [], []
            for b in range(1, len(bins)):
                m = idx == b
                if not m.any():
                    continue
                centers.append(bins[b])
                succ.append(data["success"][m].mean())
                rr = data["rms_after_orbit1"][m].astype(float)
                rr = rr[(data["success"][m] == 1) & np.isfinite(rr)]
                rms.append(np.median(rr) if rr.size else np.nan)
                exc.append(np.median(data["excursion"][m]))
                ret.append(np.mean(data["return_"][m]))
            kw = {"color": colors.setdefault(v, f"C{len(colors) % 10}"), "lw": 1, "alpha": 0.8,
                  "label": v if r["seed"] == min(x["seed"] for x in runs[v]) else None}
            axes[0].plot(centers, succ, **kw)
            axes[1].semilogy(centers, rms, **kw)
            axes[2].plot(centers, exc, **kw)
            axes[3].plot(centers, ret, **kw)
    for ax, t in zip(axes, ("training-episode success rate", "median RMS after orbit 1 "
                            "(successful training episodes) [rad]",
                            "median reel excursion [-]", "mean training return (own reward)"),
                     strict=True):
        ax.set_title(t, fontsize=9)
        ax.set_xlabel("env steps")
    axes[0].legend(fontsize=8)
    fig.savefig(HERE / "curves.png", dpi=90)
    print(f"wrote {HERE / 'curves.png'}")


if __name__ == "__main__":
    main()
