"""The SAC ablation of issue 26: train every cell over three seeds, score it, print the table.

Each cell is a hyperparameter file of ``cfg/`` (one change against ``capsA0g995``, the
best single-seed probe of the first round). Every seed is a ``train.py`` run (``--algo
sac`` trains CapsSAC, which reads the ``caps_*`` keys; the ``tqc`` cell is ``--algo
tqc``, sb3-contrib's TQC with the same smoothness terms); a cell is scored as one policy
with several runs by ``evaluate.py`` on the default suite (raw success over all
episodes; RMS, effort and chattering are IQMs over runs x scenarios, with the 95 %
bootstrap interval over runs for the RMS).

    python experiments/issue26/sac/ablation.py train  [CELL ...]   # runs/sacabl/CELL/seed_K
    python experiments/issue26/sac/ablation.py table  [CELL ...]   # writes ablation.md

``train`` runs the seeds one after another in this process's interpreter (start one
process per core, each with its own cells, ``OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1``);
a finished seed (its ``train_info.json`` says ``finished``) is skipped, an unfinished one
starts over.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[2]
RUNS = ROOT / "runs" / "sacabl"
SEEDS = (0, 1, 2)
STEPS = 300_000

# cell -> what it changes against capsA0g995 (the files in cfg/ say it in full)
CELLS = {
    "capsA0g995": "base: 16 envs, 2 gradient steps per 16 env steps, [64, 64], gamma "
                  "0.995, ent_coef auto_0.005, CAPS temporal 1 / spatial 1 / magnitude 1",
    "sym": "+ symlog error features (scale 0.01), as ppo_symlog",
    "H10": "target entropy -10 (per action entry -5) instead of -6",
    "gs4": "4 gradient steps per 16 env steps",
    "gain025": "increment gain 0.25 (the env default) instead of 0.5",
    "mag20": "CAPS magnitude weight 20 (Q is of the order of 50-200 by 300k steps)",
    "sde8": "gSDE, noise held for 8 vector steps (train_freq 8, 16 gradient steps)",
    "qf256": "critics [256, 256], actor [64, 64]",
    "tqc": "TQC (sb3-contrib): 2 critics x 25 quantiles, top 2 per critic dropped",
}
ALGO = {"tqc": "tqc"}
"""The cells not trained by ``--algo sac``."""


def _finished(run: Path) -> bool:
    info = run / "train_info.json"
    return info.is_file() and json.loads(info.read_text()).get("status") == "finished"


def train(cells: list[str]) -> None:
    for seed in SEEDS:
        for cell in cells:
            run = RUNS / cell / f"seed_{seed}"
            if _finished(run):
                continue
            shutil.rmtree(run, ignore_errors=True)  # an unfinished seed starts over
            subprocess.run([sys.executable, str(ROOT / "train.py"),
                            "--algo", ALGO.get(cell, "sac"),
                            "--config", str(HERE / "cfg" / f"{cell}.yml"), "--seed", str(seed),
                            "--timesteps", str(STEPS), "--out", str(run), "--no-progress"],
                           check=True, cwd=ROOT)


def _score(path: Path, out: Path) -> dict:
    """``evaluate.py``'s results for the policy at ``path`` (a run, or a cell of runs),
    read from ``out`` when an earlier call wrote them there."""
    if not (out / "results.json").is_file():
        subprocess.run([sys.executable, str(ROOT / "evaluate.py"), str(path), "--out", str(out),
                        "--no-plots"], check=True, cwd=ROOT)
    (policy,) = json.loads((out / "results.json").read_text())["policies"].values()
    return policy


def table(cells: list[str]) -> str:
    lines = ["| cell | change vs base | seeds | success | worst scenario | RMS [rad] (95 % CI) "
             "| per seed RMS | effort | chattering | wall per seed [s] |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for cell in cells:
        runs = [RUNS / cell / f"seed_{s}" for s in SEEDS if _finished(RUNS / cell / f"seed_{s}")]
        if len(runs) < len(SEEDS):
            lines.append(f"| {cell} | {CELLS[cell]} | {len(runs)} of {len(SEEDS)} finished "
                         "| | | | | | | |")
            continue
        p = _score(RUNS / cell, RUNS / cell / "eval")
        lo, hi = p["ci95"]["tracking_rms"]
        walls = [json.loads((r / "train_info.json").read_text())["wall_time_s"] for r in runs]
        per_seed = [f"{_score(r, r / 'evalres')['tracking_rms']:.2g}" for r in runs]
        lines.append(
            f"| {cell} | {CELLS[cell]} | {len(runs)} | {p['survived']}/{p['n_episodes']} "
            f"| {p['worst_scenario']} ({p['worst_scenario_success']:.2f}) "
            f"| {p['tracking_rms']:.2g} ({lo:.2g}, {hi:.2g}) | {', '.join(per_seed)} "
            f"| {p['reel_effort']:.2f} | {p['chattering']:.1f} "
            f"| {min(walls):.0f}-{max(walls):.0f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in ("train", "table"):
        print(__doc__)
        return 2
    cells = argv[1:] or list(CELLS)
    unknown = sorted(set(cells) - set(CELLS))
    if unknown:
        print(f"unknown cell(s) {unknown}; valid: {list(CELLS)}", file=sys.stderr)
        return 2
    if argv[0] == "train":
        train(cells)
    else:
        text = table(cells)
        print(text)
        (HERE / "ablation.md").write_text(
            "# SAC ablation (issue 26): default suite, 3 seeds per cell, 300k env steps\n\n"
            f"Made by `python experiments/issue26/sac/ablation.py table`.\n\n{text}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
