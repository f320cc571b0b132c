"""Issue 12: SMC alone vs FilteredPolicy(SMC) on the default suite (7 scenarios x 10 seeds).

Runs the benchmark's own path (evaluation.PolicySpec for the SMC with each scenario's
nominal model, rollout.rollout, metrics.episode_metrics) and writes the episodes to
experiments/issue12/filter_episodes.json. The filter predicts with the same nominal
model the SMC designs on (the scenario's ``nominal`` under model mismatch), with the
default margins of SafetyFilter.for_env (T_safe = 0.5, one step of full-rate travel).

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 python experiments/issue12/filter_eval.py
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import gymnasium as gym

import tether_gym
from tether_gym.safety import SafetyFilter
from tether_gym_agents.evaluation.benchmark import PolicyKind, PolicySpec
from tether_gym_agents.evaluation.metrics import episode_metrics
from tether_gym_agents.evaluation.rollout import rollout
from tether_gym_agents.evaluation.scenarios import get_suite
from tether_gym_agents.hybrids.policies import FilteredPolicy

OUT = Path(__file__).resolve().parent / "filter_episodes.json"
SEEDS = list(range(10))


def main() -> None:
    smc_spec = PolicySpec("smc", PolicyKind.BASELINE, [None])
    episodes = []
    timing = {}
    for sc in get_suite("default"):
        kwargs = sc.env_kwargs
        env = gym.make(tether_gym.ENV_ID, **kwargs)
        smc = smc_spec.policies(0, env, sc, SEEDS)[0]
        nominal = sc.nominal or {}
        flt = SafetyFilter.for_env(env, eccentricity=nominal.get("eccentricity"),
                                   masses=nominal.get("masses"))
        filtered = FilteredPolicy.for_env(smc, env)
        filtered.safety_filter = flt
        for name, policy in (("smc", smc), ("smc+filter", filtered)):
            t0 = time.perf_counter()
            trajs = rollout(policy, SEEDS, kwargs)
            timing[f"{sc.name}/{name}"] = time.perf_counter() - t0
            for seed, traj in zip(SEEDS, trajs, strict=True):
                m = episode_metrics(traj)
                m["failure"] = traj.failure
                m["duration_orbits"] = traj.duration
                episodes.append({"policy": name, "scenario": sc.name, "seed": seed, **m})
            print(sc.name, name, [t.failure for t in trajs],
                  f"{timing[f'{sc.name}/{name}']:.1f} s", flush=True)
        env.close()
    OUT.write_text(json.dumps({"episodes": episodes, "seconds": timing}, indent=1,
                              default=lambda x: None if x is None else float(x)))


if __name__ == "__main__":
    main()
