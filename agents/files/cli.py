"""``python -m tether_gym_agents.files {convert,export}``: the command line of the files."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..common.yamlio import YamlFileError
from .export import convert_run, export_runs
from .folder_paths import FolderFileError
from .safe_format import AGENT_FILE, WEIGHTS_FILE, AgentLoadError

__all__ = ["main", "PROG"]

PROG = "python -m tether_gym_agents.files"


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG,
                                     description="Convert a stable-baselines3 run folder "
                                                 "(pickles; train.py's or rl_zoo3's) to a safe "
                                                 "agent folder, or export runs' safe files.")
    sub = parser.add_subparsers(dest="cmd", required=True)
    conv = sub.add_parser("convert", help="write agent.json + policy.safetensors from a run folder")
    conv.add_argument("run", type=Path, help="run folder or model .zip (train.py's, or "
                                             "rl_zoo3's logs/ALGO/ENV_NAME_N)")
    conv.add_argument("--out", type=Path, default=None,
                      help="agent folder (default: RUN itself for best_model.zip, else "
                           "RUN/final_agent; rl_zoo3 runs: RUN/final_agent from ENV_NAME.zip)")
    conv.add_argument("--allow-pickle", action="store_true",
                      help="required: the conversion unpickles the run's files once")
    exp = sub.add_parser("export", help="copy the safe files of a run, or of every seed_K "
                                        "run of a folder, to share or ship them")
    exp.add_argument("src", type=Path, help="run folder or folder of seed_K run folders (only "
                                            "regular files inside it are read)")
    exp.add_argument("dest", type=Path, help="destination folder")
    return parser


def main(argv=None) -> int:
    """Run ``convert`` or ``export`` (see ``--help``); returns the exit code."""
    args = _parser().parse_args(argv)
    try:
        if args.cmd == "export":
            written = export_runs(args.src, args.dest)
            print(f"exported {len(written)} run(s) to {args.dest}")
            return 0
        out = convert_run(args.run, args.out, allow_pickle=args.allow_pickle)
    except (AgentLoadError, FolderFileError, YamlFileError) as exc:
        print(f"agent_files: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {out / AGENT_FILE} and {out / WEIGHTS_FILE}")
    return 0
