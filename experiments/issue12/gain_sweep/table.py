"""Markdown table of the increment-gain sweep: ``python table.py [FOLDER]``.

FOLDER (default: this folder) holds ``results_g<gain>.json``, the ``results.json`` of
``python evaluate.py runs/gain/g<gain> --out ...`` for each gain (not tracked by git).
"""

import json
import sys
from pathlib import Path

HERE = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parent


def cell(block: dict, metric: str, fmt: str) -> str:
    """``value [lo, hi]`` of one metric of a policy block."""
    value, ci = block[metric], block["ci95"][metric]
    text = fmt.format(value) if value is not None else "n/a"
    return text + ("" if ci is None else f" [{fmt.format(ci[0])}, {fmt.format(ci[1])}]")


print("| increment gain | seeds | success | tracking RMS [rad] | reel excursion | reel effort "
      "| failed episodes |")
print("|---|---|---|---|---|---|---|")
for gain in ("0.1", "0.25", "0.5"):
    path = HERE / f"results_g{gain}.json"
    if not path.is_file():
        raise SystemExit(f"{path} missing: copy there the results.json of "
                         f"`python evaluate.py runs/gain/g{gain} --out ...`")
    results = json.loads(path.read_text())
    (block,) = results["policies"].values()
    fails = sum(block["failures"].values())
    print(f"| {gain} | {block['n_runs']} | {cell(block, 'success', '{:.3f}')} | "
          f"{cell(block, 'tracking_rms', '{:.2e}')} | {cell(block, 'reel_excursion', '{:.3f}')} | "
          f"{cell(block, 'reel_effort', '{:.3f}')} | {fails}/{block['n_episodes']} |")
