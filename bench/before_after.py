"""Run ``bench/bench.py`` on an older checkout and on this one, and print one table.

``python bench/before_after.py --old DIR`` runs this tree's ``bench/bench.py`` twice in
subprocesses, first importing ``tether_gym`` and ``tether_gym_agents`` from the checkout
DIR (its ``tether_gym/`` and ``agents/`` folders), then from this tree, and prints the
two runs' rows side by side. Every figure is still a ratio measured within its own run
(against Pendulum-v1 or N = 3), so the two columns compare like with like. Run it on an
otherwise idle machine.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_bench(pythonpath: str | None, quick: bool) -> tuple[list[str], dict[str, list[str]]]:
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    cmd = [sys.executable, str(ROOT / "bench" / "bench.py")] + (["--quick"] if quick else [])
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, check=True,
                         cwd=tempfile.gettempdir()).stdout
    header = [line for line in out.splitlines() if line.startswith("- ")]
    rows = {}
    for line in out.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and len(cells) == 5 and cells[0] not in ("Measure", "---"):
            rows[cells[0]] = cells[1:]
    return header, rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", type=Path, required=True,
                        help="checkout of the older version (holds tether_gym/ and agents/)")
    parser.add_argument("--quick", action="store_true", help="small budgets (rough figures)")
    args = parser.parse_args(argv)
    old = args.old.resolve()
    if not (old / "tether_gym").is_dir() or not (old / "agents").is_dir():
        parser.error(f"--old {old}: needs tether_gym/ and agents/ folders")
    with tempfile.TemporaryDirectory() as shim:
        os.symlink(old / "tether_gym", Path(shim) / "tether_gym")
        os.symlink(old / "agents", Path(shim) / "tether_gym_agents")
        old_header, before = run_bench(shim, args.quick)
    new_header, after = run_bench(None, args.quick)
    print("before:", *old_header, sep="\n")
    print("after:", *new_header, sep="\n")
    print()
    print("| Measure | Before | Before ratio | After | After ratio | Target | After result |")
    print("|---|---|---|---|---|---|---|")
    for name in dict.fromkeys(list(after) + list(before)):
        b = before.get(name, ["", "", "", ""])
        a = after.get(name, ["", "", "", ""])
        print(f"| {name} | {b[0]} | {b[1]} | {a[0]} | {a[1]} | {a[2] or b[2]} | {a[3]} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
