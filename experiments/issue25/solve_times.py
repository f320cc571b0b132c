"""Wall time of every ``predict`` call of a policy over a whole suite, one thread.

``python experiments/issue25/solve_times.py mpc default OUT.json`` runs the policy on
every scenario and seed (0-9) of the suite through the benchmark's rollout loop, times
each call (a batched call is charged per row) and prints per scenario and overall the
median, p90, p99 and largest time per control step [ms]; OUT.json keeps every time and
the episodes' metrics.
"""

from __future__ import annotations

import json
import sys
import time

import gymnasium as gym
import numpy as np

import tether_gym
from tether_gym_agents.evaluation.metrics import episode_metrics
from tether_gym_agents.evaluation.registry import resolve_policy
from tether_gym_agents.evaluation.rollout import rollout
from tether_gym_agents.evaluation.scenarios import get_suite

SEEDS = list(range(10))


class Timed:
    """A policy whose ``predict`` calls are timed, per observation row."""

    def __init__(self, policy):
        self._policy = policy
        self.ms: list[float] = []

    def __getattr__(self, name):
        return getattr(self._policy, name)

    def predict(self, obs, *args, **kwargs):
        t0 = time.perf_counter()
        out = self._policy.predict(obs, *args, **kwargs)
        rows = 1 if np.ndim(obs) == 1 else np.shape(obs)[0]
        self.ms.extend([1e3 * (time.perf_counter() - t0) / rows] * rows)
        return out


def _summary(ms: np.ndarray) -> str:
    return (f"median {np.median(ms):.2f} p90 {np.percentile(ms, 90):.2f} "
            f"p99 {np.percentile(ms, 99):.2f} max {ms.max():.1f} ms")


def main(argv=None) -> int:
    name, suite, path = (sys.argv[1:] if argv is None else argv)[:3]
    spec = resolve_policy(name)
    out: dict = {"policy": name, "suite": suite, "episodes": [], "ms": []}
    t_all = time.perf_counter()
    for sc in get_suite(suite):
        resolved, kwargs = sc.resolved({}, {})
        kwargs = {**kwargs, **spec.env_kwargs}
        env = gym.make(tether_gym.ENV_ID, **kwargs)
        timed: dict[int, Timed] = {}
        wrapped = [timed.setdefault(id(p), Timed(p))
                   for p in spec.policies(0, env, resolved, SEEDS)]
        for seed, traj in zip(SEEDS, rollout(wrapped, SEEDS, kwargs), strict=True):
            out["episodes"].append({"scenario": sc.name, "seed": seed,
                                    **episode_metrics(traj)})
        ms = np.concatenate([np.asarray(t.ms) for t in timed.values()])
        out["ms"].extend(ms.tolist())
        print(f"{sc.name}: {_summary(ms)}", flush=True)
    ms = np.asarray(out["ms"])
    print(f"all {ms.size} steps ({time.perf_counter() - t_all:.0f} s): {_summary(ms)}")
    with open(path, "w") as fh:
        json.dump(out, fh)
    return 0


if __name__ == "__main__":
    sys.exit(main())
