"""Compute per control step of the ``mpc`` baseline: ``python bench/mpc_step.py``.

Runs whole episodes of ``mpc`` as ``evaluate.py`` builds it (the registry's policy: the
nonlinear MPC behind its safety filter, on the scenario's nominal model) on one pinned
core (``--cpu``; numba gets one thread) and times every ``predict`` call, one
observation per call, with ``time.perf_counter``: the figure ``evaluate.py`` reports as
ms/step (``benchmark.compute_cost``), over more episodes. The law's own planning time
per step (``solve_times``, without the filter and the SB3 wrapper) is shown beside it.
It prints one markdown table: per scenario and over all steps, the median, p90, p99 and
largest time per control step, and the time to build the controller's CasADi functions
(once per process and model structure, the first episode's ``make_policy``).

Defaults: the default suite's ``paper``, ``random_init`` and ``ecc_0.1``, env seed 0,
whole episodes (754 control steps each). ``--steps N`` cuts each episode; ``--quick``
is ``--steps 100`` on ``paper`` alone (a smoke run). Run it on an idle machine: the
figures of a run beside another job are provisional.

Only the package's public evaluation API is used, so the same script times an older
checkout: ``PYTHONPATH=DIR python bench/mpc_step.py`` with ``DIR`` holding links
``tether_gym`` and ``tether_gym_agents`` to that checkout's ``tether_gym`` and
``agents`` folders.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

# one thread for every library, before any of them is imported
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402


class Timed:
    """A policy whose ``predict`` calls are timed (wall clock)."""

    def __init__(self, policy):
        self.policy = policy
        self.seconds: list[float] = []

    def predict(self, *args, **kwargs):
        t0 = time.perf_counter()
        out = self.policy.predict(*args, **kwargs)
        self.seconds.append(time.perf_counter() - t0)
        return out


def run(scenario, seed: int, steps: int | None) -> dict:
    """One episode of ``mpc`` on ``scenario``: its times per step [ms] and the build time."""
    import gymnasium as gym

    import tether_gym
    from tether_gym_agents.evaluation.registry import make_policy
    from tether_gym_agents.evaluation.rollout import rollout

    kwargs = {**scenario.env_kwargs, "action_mode": "rate"}
    env = gym.make(tether_gym.ENV_ID, **kwargs)
    t0 = time.perf_counter()
    policy = make_policy("mpc", env, scenario, seed)
    build = time.perf_counter() - t0
    timed = Timed(policy)
    if steps is not None:
        kwargs["max_episode_steps"] = steps
    traj = rollout([timed], [seed], kwargs)[0]
    law = getattr(policy, "policy", policy)
    return {"scenario": scenario.name, "steps": traj.steps, "build": build,
            "predict": 1e3 * np.asarray(timed.seconds),
            "law": 1e3 * np.asarray(getattr(law, "solve_times", []))}


def quantiles(ms: np.ndarray) -> str:
    """``median | p90 | p99 | max`` of times [ms]."""
    if ms.size == 0:
        return "n/a | n/a | n/a | n/a"
    q = np.percentile(ms, [50, 90, 99])
    return f"{q[0]:.1f} | {q[1]:.1f} | {q[2]:.1f} | {ms.max():.1f}"


def machine_lines(cpu: int | None) -> list[str]:
    """The command, the machine, its load and the versions."""
    import casadi

    import tether_gym

    return [f"command: `{' '.join([os.path.basename(sys.executable)] + sys.argv)}`",
            f"machine: {platform.machine()} {platform.processor() or ''}, {os.cpu_count()} "
            f"cores, pinned to CPU {cpu if cpu is not None else 'none'}, load average "
            f"{' '.join(f'{x:.2f}' for x in os.getloadavg())} (at the start)",
            f"python {platform.python_version()}, numpy {np.__version__}, casadi "
            f"{casadi.__version__}, tether_gym {tether_gym.__version__} "
            f"({tether_gym.__file__})"]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", nargs="+", default=["paper", "random_init", "ecc_0.1"],
                        help="scenarios of --suite (default: paper random_init ecc_0.1)")
    parser.add_argument("--suite", default="default", help="suite of the scenarios")
    parser.add_argument("--seed", type=int, default=0, help="env seed of every episode")
    parser.add_argument("--steps", type=int, default=None,
                        help="cut each episode to this many control steps")
    parser.add_argument("--quick", action="store_true", help="--steps 100 on paper alone")
    parser.add_argument("--cpu", type=int, default=None,
                        help="CPU to pin to (default: the last one this process may use; "
                             "-1: no pinning)")
    args = parser.parse_args(argv)
    from tether_gym_agents.evaluation.scenarios import get_suite

    suite = {s.name: s for s in get_suite(args.suite)}
    names = ["paper"] if args.quick else args.scenarios
    steps = 100 if args.quick else args.steps
    unknown = [n for n in names if n not in suite]
    if unknown:
        parser.error(f"scenarios {unknown} are not in suite {args.suite!r}: {list(suite)}")
    cpu = None
    if args.cpu != -1 and hasattr(os, "sched_setaffinity"):
        cpu = args.cpu if args.cpu is not None else max(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpu})
    for line in machine_lines(cpu):
        print(f"- {line}")
    print()
    results = []
    for name in names:
        print(f"  {name}: one episode of mpc, env seed {args.seed} ...", file=sys.stderr,
              flush=True)
        results.append(run(suite[name], args.seed, steps))
    print("| scenario | steps | predict: median | p90 | p99 | max [ms] | law alone: median "
          "| p90 | p99 | max [ms] | build [s] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in results:
        print(f"| {r['scenario']} | {r['steps']} | {quantiles(r['predict'])} | "
              f"{quantiles(r['law'])} | {r['build']:.1f} |")
    every = np.concatenate([r["predict"] for r in results])
    law = np.concatenate([r["law"] for r in results])
    print(f"| all | {every.size} | {quantiles(every)} | {quantiles(law)} | |")
    print(f"\nload average at the end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
