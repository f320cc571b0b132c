"""Microseconds per SafetyFilter.project call, B = 1 and 8, safe and unsafe commands.

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 python experiments/issue12/filter_timing.py
"""

from __future__ import annotations

import time

import gymnasium as gym
import numpy as np

import tether_gym
from tether_gym.safety import SafetyFilter

env = gym.make(tether_gym.ENV_ID)
flt = SafetyFilter.for_env(env)
rng = np.random.default_rng(12)
count = 400
y = np.empty((count, 8))
y[:, 0:2] = rng.uniform(-0.5, 0.5, (count, 2))
y[:, 2:4] = rng.uniform(-0.8, 1.2, (count, 2))
y[:, 4:6] = rng.uniform(0.07, 1.2, (count, 2))
y[:, 6:8] = rng.uniform(-0.5, 0.5, (count, 2))
nu = rng.uniform(0.0, 2.0 * np.pi, count)
desired = rng.uniform(-1.0, 1.0, (count, 2))
res = flt.project(nu, y, desired)
groups = {"safe (inactive)": np.flatnonzero(~res.active),
          "unsafe, feasible": np.flatnonzero(res.active & res.feasible),
          "unsafe, infeasible": np.flatnonzero(~res.feasible)}
for label, idx in groups.items():
    for b in (1, 8):
        if idx.size < b:
            continue
        calls = [idx[i:i + b] for i in range(0, idx.size - b + 1, b)][:40]
        t0 = time.perf_counter()
        reps = 5
        for _ in range(reps):
            for rows in calls:
                flt.project(nu[rows], y[rows], desired[rows])
        us = (time.perf_counter() - t0) / (reps * len(calls)) * 1e6
        print(f"{label:20s} B={b}: {us:8.0f} us per call ({len(calls)} batches)")
