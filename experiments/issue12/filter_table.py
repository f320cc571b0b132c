"""Markdown tables of experiments/issue12/filter_episodes.json (see filter_eval.py)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

DATA = json.loads((Path(__file__).resolve().parent / "filter_episodes.json").read_text())
COLUMNS = (("success", "success"), ("tracking_rms", "tracking RMS after orbit 1 [rad]"),
           ("reel_excursion", "reel excursion [-]"), ("reel_effort", "reel effort [-]"),
           ("min_tension", "min T^ [-]"), ("filter_rate", "filter rate"))


def _mean(values):
    vals = [v for v in values if v is not None and not (isinstance(v, float) and math.isnan(v))]
    return float(np.mean(vals)) if vals else math.nan


def _row(eps):
    ok = [e for e in eps if e["success"] == 1.0]
    fails = {k: sum(e["failure"] == k for e in eps) for k in ("length", "slack", "tumble")}
    cells = [f"{sum(e['success'] for e in eps):.0f}/{len(eps)}"]
    for key, _ in COLUMNS[1:]:
        pool = eps if key in ("filter_rate", "min_tension") else ok
        v = _mean([e.get(key) for e in pool])
        cells.append("-" if math.isnan(v) else f"{v:.4f}")
    cells.append(", ".join(f"{k} {v}" for k, v in fails.items() if v) or "-")
    return cells


def main() -> None:
    eps = DATA["episodes"]
    head = ["policy", *(c for _, c in COLUMNS), "failures"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for pol in ("smc", "smc+filter"):
        print("| " + " | ".join([pol, *_row([e for e in eps if e["policy"] == pol])]) + " |")
    print()
    print("Paired, on the episodes both policies survive (same scenario and seed):")
    print()
    key = {(e["policy"], e["scenario"], e["seed"]): e for e in eps}
    both = [(key["smc", sc, sd], key["smc+filter", sc, sd]) for (p, sc, sd) in key
            if p == "smc" and key["smc", sc, sd]["success"] == 1.0
            and key["smc+filter", sc, sd]["success"] == 1.0]
    print("| metric | smc | smc+filter |")
    print("|---|---|---|")
    for k, label in COLUMNS[1:]:
        print(f"| {label} ({len(both)} episodes) | {_mean([a.get(k) for a, _ in both]):.4f} | "
              f"{_mean([b.get(k) for _, b in both]):.4f} |")
    print()
    head = ["scenario", "policy", *(c for _, c in COLUMNS), "failures"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for sc in dict.fromkeys(e["scenario"] for e in eps):
        for pol in ("smc", "smc+filter"):
            sel = [e for e in eps if e["policy"] == pol and e["scenario"] == sc]
            print("| " + " | ".join([sc, pol, *_row(sel)]) + " |")


if __name__ == "__main__":
    main()
