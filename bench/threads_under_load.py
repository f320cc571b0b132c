"""Vector env throughput alone and beside a second identical process, per threading mode.

    python bench/threads_under_load.py              # about 2 minutes
    python bench/threads_under_load.py --quick      # smoke run (rough figures)

For each mode (``serial``: ``parallel=False``; ``threads``: ``parallel=True``, forced;
``auto``: the default ``parallel="auto"``) the script runs a 256-env vector env in a
worker process, alone and then together with a second worker of the same mode started
at the same moment, and prints env-steps/s and ratios to the serial mode measured in
the same condition. Workers get ``NUMBA_NUM_THREADS`` = the number of cores (the pool a
user gets by default), random actions drawn in advance, autoresets included. Each cell
is the best of ``--rounds`` interleaved rounds (other processes can only slow a round
down); on a shared machine the figures are indicative only.

For a before/after comparison run the script once more with an older tree on
``PYTHONPATH`` (tether_gym 0.1.0 stepped its threads with numba's OpenMP ``prange``,
from 128 envs on by default). ``--layer`` and environment variables such as
``OMP_WAIT_POLICY`` (passed on to the workers) try other numba threading set-ups.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

MODES = ("serial", "threads", "auto")


def worker(mode: str, num_envs: int, seconds: float, start_at: float) -> dict:
    """Step a vector env from ``start_at`` (epoch s) for ``seconds``; return the rate."""
    import gymnasium as gym
    import numpy as np

    import tether_gym  # noqa: F401 - registers the env

    parallel = {"serial": False, "threads": True, "auto": "auto"}[mode]
    env = gym.make_vec(tether_gym.ENV_ID, num_envs=num_envs,
                       vectorization_mode="vector_entry_point", parallel=parallel)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (64, *env.action_space.shape))
    env.reset(seed=0)
    for i in range(200):  # compile / load the kernels, start the thread pool
        env.step(actions[i % 64])
    time.sleep(max(0.0, start_at - time.time()))
    steps = 0
    t0 = time.perf_counter()
    while True:
        for i in range(64):
            env.step(actions[i])
        steps += 64
        elapsed = time.perf_counter() - t0
        if elapsed >= seconds:
            break
    out = {"mode": mode, "env_steps_per_s": steps * num_envs / elapsed}
    chooser = getattr(env.unwrapped, "_threads", None)
    if chooser is not None and chooser.probes:
        out["chooser"] = chooser.summary()
    env.close()
    return out


def run_workers(mode: str, copies: int, args) -> list[dict]:
    """``copies`` workers of one mode started together; their results."""
    env = dict(os.environ)
    env["NUMBA_NUM_THREADS"] = str(args.threads)
    env.pop("OMP_NUM_THREADS", None)
    if args.layer:
        env["NUMBA_THREADING_LAYER"] = args.layer
    start_at = time.time() + args.startup
    cmd = [sys.executable, os.path.abspath(__file__), "--worker", mode,
           "--num-envs", str(args.num_envs), "--seconds", str(args.seconds),
           "--start-at", repr(start_at)]
    procs = [subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, text=True)
             for _ in range(copies)]
    results = []
    for p in procs:
        out, _ = p.communicate()
        if p.returncode != 0:
            raise RuntimeError(f"worker {mode} failed with exit code {p.returncode}")
        results.append(json.loads(out.strip().splitlines()[-1]))
    return results


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="1 round of 1 s (smoke run)")
    parser.add_argument("--num-envs", type=int, default=256)
    parser.add_argument("--seconds", type=float, default=3.0, help="measured time per worker")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 2,
                        help="NUMBA_NUM_THREADS of the workers (default: the core count)")
    parser.add_argument("--layer", default="", help="NUMBA_THREADING_LAYER of the workers")
    parser.add_argument("--modes", default=",".join(MODES))
    parser.add_argument("--startup", type=float, default=25.0,
                        help="seconds the workers get to import and warm up before timing")
    parser.add_argument("--worker", choices=MODES, help=argparse.SUPPRESS)
    parser.add_argument("--start-at", type=float, default=0.0, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.num_envs < 1:
        parser.error(f"--num-envs={args.num_envs} must be >= 1")
    if args.seconds <= 0 or args.rounds < 1 or args.threads < 1:
        parser.error("--seconds must be > 0, --rounds and --threads >= 1")
    modes = [m for m in args.modes.split(",") if m]
    bad = [m for m in modes if m not in MODES]
    if bad:
        parser.error(f"--modes has {bad}; valid: {', '.join(MODES)}")
    if args.worker:
        print(json.dumps(worker(args.worker, args.num_envs, args.seconds, args.start_at)))
        return 0
    if args.quick:
        args.seconds, args.rounds = 1.0, 1

    import numba

    print("command: python " + " ".join([os.path.relpath(__file__)] + sys.argv[1:]))
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}, "
          f"numba {numba.__version__}, workers NUMBA_NUM_THREADS={args.threads}, "
          f"layer {args.layer or 'default'}, {args.num_envs} envs, {args.seconds} s x "
          f"{args.rounds} rounds")
    best: dict[tuple[str, int], float] = {}
    notes: dict[tuple[str, int], str] = {}
    for _ in range(args.rounds):
        for copies in (1, 2):
            for mode in modes:
                results = run_workers(mode, copies, args)
                rate = sum(r["env_steps_per_s"] for r in results) / copies
                if rate > best.get((mode, copies), 0.0):
                    best[(mode, copies)] = rate
                    notes[(mode, copies)] = "; ".join(str(r["chooser"]) for r in results
                                                      if "chooser" in r)
    print()
    print("| mode | alone: env-steps/s | x serial | with a 2nd process: env-steps/s "
          "(per process) | x serial | loaded / alone |")
    print("|---|---|---|---|---|---|")
    for mode in modes:
        alone, loaded = best[(mode, 1)], best[(mode, 2)]
        s1, s2 = best.get(("serial", 1)), best.get(("serial", 2))
        r1 = f"{alone / s1:.2f}" if s1 else "-"
        r2 = f"{loaded / s2:.2f}" if s2 else "-"
        print(f"| {mode} | {alone:,.0f} | {r1} | {loaded:,.0f} | {r2} | "
              f"{loaded / alone:.2f} |")
    for key, note in notes.items():
        if note:
            print(f"chooser {key[0]}, {key[1]} process(es): {note}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
