"""Vector-env throughput of an older checkout and of this tree, in alternating processes.

    python bench/ab.py --old OLD_TREE [--pairs 4] [--envs 256] [--modes serial threads auto]

On a machine whose speed drifts (a shared host), two benchmark runs made minutes apart
disagree by more than most changes are worth. This script alternates: for each pair it
runs one subprocess on the old tree, then one on this tree, each stepping a vector env
(random actions drawn in advance, autoresets included) and reporting the best of 5
rounds of 200 steps, and prints every pair and the mean per side. Run it on an otherwise
idle machine.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

_WORKER = r"""
import sys, time
import numpy as np, gymnasium as gym, tether_gym
num, parallel = int(sys.argv[1]), {"serial": False, "threads": True, "auto": "auto"}[sys.argv[2]]
env = gym.make_vec(tether_gym.ENV_ID, num_envs=num, vectorization_mode="vector_entry_point",
                   parallel=parallel)
env.reset(seed=0)
rng = np.random.default_rng(0)
actions = [rng.uniform(-1, 1, (num, env.single_action_space.shape[0])).astype(np.float32)
           for _ in range(64)]
for a in actions:
    env.step(a)
best = 0.0
for _ in range(5):
    t0 = time.perf_counter()
    for k in range(200):
        env.step(actions[k % 64])
    best = max(best, 200 * num / (time.perf_counter() - t0))
print(int(best))
"""


def rate(pythonpath: str | None, envs: int, mode: str) -> int:
    """env-steps/s of one worker process (``pythonpath`` first on its path, if given)."""
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    out = subprocess.run([sys.executable, "-c", _WORKER, str(envs), mode], env=env,
                         capture_output=True, text=True, check=True,
                         cwd=tempfile.gettempdir()).stdout
    return int(out.strip().splitlines()[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", type=Path, required=True,
                        help="checkout of the older version (holds tether_gym/)")
    parser.add_argument("--pairs", type=int, default=4, help="old/new pairs per mode")
    parser.add_argument("--envs", type=int, default=256, help="sub-envs of the vector env")
    parser.add_argument("--modes", nargs="+", default=["serial", "threads", "auto"],
                        choices=["serial", "threads", "auto"])
    args = parser.parse_args(argv)
    old = args.old.resolve()
    if not (old / "tether_gym").is_dir():
        parser.error(f"--old {old}: needs a tether_gym/ folder")
    if args.pairs < 1 or args.envs < 1:
        parser.error("--pairs and --envs must be >= 1")
    print(f"{args.envs} envs, random actions; env-steps/s, best of 5 x 200 steps per process")
    with tempfile.TemporaryDirectory() as shim:
        os.symlink(old / "tether_gym", Path(shim) / "tether_gym")
        for mode in args.modes:
            pairs = [(rate(shim, args.envs, mode), rate(None, args.envs, mode))
                     for _ in range(args.pairs)]
            listed = ", ".join(f"{o:,} / {n:,}" for o, n in pairs)
            mean_old = sum(o for o, _ in pairs) / len(pairs)
            mean_new = sum(n for _, n in pairs) / len(pairs)
            print(f"{mode}: old / new per pair: {listed}; mean {mean_old:,.0f} -> "
                  f"{mean_new:,.0f} ({mean_new / mean_old:.2f}x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
