"""Markdown table of a PPO probe from evaluate.py's results of each variant.

A probe's table.py reads, in its folder, results_<variant>.json (the results.json of
``python evaluate.py RUNS --out OUT``, default suite) and beyond_<variant>.json (the same
with ``--suite beyond``), copied there after the runs (git does not track them: they are
raw per-episode outputs; the probe's table.md keeps the table), and calls
:func:`print_table` with the variants' labels. A variant may name another probe's files
by a relative path (``../observe_e/blind``).
"""

import json
from pathlib import Path


def cell(block: dict, metric: str, fmt: str) -> str:
    """``value [lo, hi]`` of one metric of a policy block."""
    value, ci = block[metric], block["ci95"][metric]
    text = fmt.format(value) if value is not None else "n/a"
    return text + ("" if ci is None else f" [{fmt.format(ci[0])}, {fmt.format(ci[1])}]")


def print_table(folder: Path, variants: dict, first: str = "variant") -> None:
    """One row per variant (``{file name part: label}``) with results in ``folder``."""
    print(f"| {first} | seeds | success | tracking RMS [rad] | RMS e = 0 | RMS e = 0.3 "
          "| reel excursion | reel effort | failed | beyond: success | beyond: failed |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name, label in variants.items():
        stem = folder / name
        path = stem.parent / f"results_{stem.name}.json"
        if not path.exists():
            continue
        res = json.loads(path.read_text())
        (pol, block), = res["policies"].items()
        per = res["per_scenario"]
        fails = sum(block["failures"].values())
        beyond = stem.parent / f"beyond_{stem.name}.json"
        bcells = "n/a | n/a"
        if beyond.exists():
            (bb,) = json.loads(beyond.read_text())["policies"].values()
            failed = sum(bb["failures"].values())
            bcells = f"{cell(bb, 'success', '{:.3f}')} | {failed}/{bb['n_episodes']}"
        print(f"| {label} | {block['n_runs']} | {cell(block, 'success', '{:.3f}')} | "
              f"{cell(block, 'tracking_rms', '{:.2e}')} | "
              f"{per['ecc_0.0'][pol]['tracking_rms']:.2e} | "
              f"{per['ecc_0.3'][pol]['tracking_rms']:.2e} | "
              f"{cell(block, 'reel_excursion', '{:.3f}')} | "
              f"{cell(block, 'reel_effort', '{:.3f}')} | {fails}/{block['n_episodes']} | "
              f"{bcells} |")
