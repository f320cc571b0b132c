"""What the safety filter does to rough policies, and why it cannot guard tumbling.

Two measurements behind the SafetyFilter docstring and the README's "Safety filter as
a wrapper" paragraph:

1. **Outcomes.** Three rate-mode policies, 30 episodes each (reset seeds 0-29, default
   env), with and without ``SafetyFilterWrapper``: uniform random commands, bang-bang
   ``sign(theta)`` and full reel-in. Each episode's end is counted by
   ``info["failure"]`` (slack / tumble / length) or as survived, with the filter's
   infeasible steps.
2. **One-step authority.** At every state of the unfiltered random episodes, the
   spread of the predicted theta(k+1) and theta'(k+1) over the corners of the command
   box (``tether_gym.physics.transition``, the filter's own predictor), beside the
   drift |theta'| * control_step of one step.

Run: ``python experiments/issue24/filter_outcomes.py`` (about a minute on one core).
"""

from __future__ import annotations

import itertools
import sys
import time
import warnings
from collections import Counter

import gymnasium as gym
import numpy as np

import tether_gym  # noqa: F401  (registers the env)
from tether_gym.physics import transition
from tether_gym.safety import SafetyFilter
from tether_gym.wrappers import SafetyFilterWrapper, state_of

ENV = "tether_gym/TetherLibration-v1"
SEEDS = range(30)


def random_policy(rng, n, info):
    return rng.uniform(-1.0, 1.0, n)


def bang_bang(rng, n, info):
    return np.sign(np.asarray(info["theta"], dtype=float)) + 0.0


def reel_in(rng, n, info):
    return -np.ones(n)


POLICIES = {"random": random_policy, "bang-bang sign(theta)": bang_bang,
            "full reel-in": reel_in}


def episode(policy, seed, filtered, authority=None):
    env = gym.make(ENV, action_mode="rate")
    if filtered:
        env = SafetyFilterWrapper(env)
    sf = SafetyFilter.for_env(env)
    n = sf.n
    corners = np.array(list(itertools.product((-1.0, 1.0), repeat=n)))
    rng = np.random.default_rng(seed)
    _, info = env.reset(seed=seed)
    infeasible = 0
    while True:
        if authority is not None:
            nu, y = state_of(info)
            out = transition(nu, np.repeat(y[None], len(corners), 0),
                             corners * sf.max_reel_rate, sf.par[0], sf.physics_step,
                             sf.substeps)
            authority["theta"].append(np.ptp(out.state[:, :n], axis=0).max())
            authority["dtheta"].append(np.ptp(out.state[:, n:2 * n], axis=0).max())
            authority["drift"].append(np.abs(y[n:2 * n]).max() * sf.physics_step
                                      * sf.substeps)
        _, _, term, trunc, info = env.step(policy(rng, n, info))
        infeasible += int(not info.get("filter_feasible", True))
        if term or trunc:
            return (info["failure"] or "survived"), infeasible


def main(argv=None) -> int:
    t0 = time.perf_counter()
    warnings.simplefilter("ignore", UserWarning)
    print("| policy | filter | slack | tumble | length | survived | infeasible steps |")
    print("|---|---|---|---|---|---|---|")
    authority = {"theta": [], "dtheta": [], "drift": []}
    for name, policy in POLICIES.items():
        for filtered in (False, True):
            ends, bad = Counter(), 0
            for seed in SEEDS:
                use = authority if (name == "random" and not filtered) else None
                end, infeasible = episode(policy, seed, filtered, use)
                ends[end] += 1
                bad += infeasible
            print(f"| {name} | {'yes' if filtered else 'no'} | {ends['slack']} | "
                  f"{ends['tumble']} | {ends['length']} | {ends['survived']} | "
                  f"{bad if filtered else '-'} |")
    th, dth, drift = (np.asarray(authority[k]) for k in ("theta", "dtheta", "drift"))
    print(f"\nOne-step authority over {th.size} states of the unfiltered random episodes:")
    print(f"  spread of theta(k+1) over the command box: median {np.median(th):.2e}, "
          f"max {th.max():.2e} [rad]")
    print(f"  spread of theta'(k+1): median {np.median(dth):.2e}, max {dth.max():.2e} "
          f"[rad/rad]")
    print(f"  drift |theta'| * control_step: median {np.median(drift):.2e} [rad]")
    print(f"wall time {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
