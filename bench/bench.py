"""Speed benchmark of tether_gym: ``python bench/bench.py [--quick]``.

Prints a markdown table of figures measured in this one run, each as a ratio to a
reference measured in the same run (Pendulum-v1 for throughput, N = 3 for the cost
against N), with the target and PASS/MISS beside it. Throughput figures are the
best of several interleaved rounds, so that load from other processes on a shared
machine disturbs the ratios as little as possible. ``--quick`` shrinks every budget
(a smoke run for CI: the figures are then rough).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time

import gymnasium as gym
import numpy as np

import tether_gym

ENV_ID = tether_gym.ENV_ID

# (label, target predicate, target text)
TARGETS = {
    "single": (lambda r: r >= 1.0, ">= 1.0x Pendulum"),
    "vec256": (lambda r: r >= 10.0, ">= 10x Pendulum"),
    "ppo_share": (lambda s: s <= 0.10, "<= 10 %"),
    "n8": (lambda r: r <= 4.0, "<= 4x N=3"),
    "startup": (lambda s: s < 3.0, "< 3 s"),
    "cold": (lambda s: s <= 8.0, "<= 8 s"),
}


def best_rates(runners: dict, rounds: int) -> dict:
    """Interleave the runners for ``rounds`` rounds; each returns (count, seconds)."""
    best = {name: 0.0 for name in runners}
    for _ in range(rounds):
        for name, run in runners.items():
            count, seconds = run()
            best[name] = max(best[name], count / seconds)
    return best


def single_runner(env_id: str, steps: int, **kwargs):
    """Steps of ``gym.make(env_id)`` with actions sampled in advance (resets included)."""
    env = gym.make(env_id, **kwargs)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(steps)]
    env.reset(seed=0)

    def run():
        t0 = time.perf_counter()
        for a in actions:
            _, _, terminated, truncated, _ = env.step(a)
            if terminated or truncated:
                env.reset()
        return steps, time.perf_counter() - t0

    run()  # warm-up (compiles / loads the kernels)
    return run


def vector_runner(num_envs: int, steps: int, zero_actions: bool = False,
                  mode: str = "vector_entry_point", **kwargs):
    """Env steps of ``gym.make_vec`` (num_envs per call of step); the native env by default."""
    env = gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode=mode, **kwargs)
    env.action_space.seed(0)
    if zero_actions:
        actions = [np.zeros(env.action_space.shape, dtype=np.float32)] * steps
    else:
        actions = [env.action_space.sample() for _ in range(steps)]
    env.reset(seed=0)

    def run():
        t0 = time.perf_counter()
        for a in actions:
            env.step(a)
        return num_envs * steps, time.perf_counter() - t0

    run()
    return run


def ppo_figures(num_envs: int, n_steps: int, timesteps: int) -> dict:
    """SB3 PPO (MlpPolicy) steps/s on the adapter and the share of time inside the env."""
    import torch
    from stable_baselines3 import PPO

    from tether_gym_agents.training.vec_env import make_sb3_vec_env

    torch.set_num_threads(1)
    venv = make_sb3_vec_env(num_envs, seed=0)
    spent = [0.0]

    def timed(method):
        def wrapper(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return method(*args, **kwargs)
            finally:
                spent[0] += time.perf_counter() - t0
        return wrapper

    venv.step_wait = timed(venv.step_wait)
    venv.reset = timed(venv.reset)
    model = PPO("MlpPolicy", venv, n_steps=n_steps, batch_size=64, seed=0, device="cpu",
                verbose=0)
    model.learn(num_envs * n_steps)  # warm-up: one rollout and one update
    spent[0] = 0.0
    start = model.num_timesteps
    t0 = time.perf_counter()
    model.learn(timesteps, reset_num_timesteps=False)
    wall = time.perf_counter() - t0
    return {"rate": (model.num_timesteps - start) / wall, "share": spent[0] / wall,
            "env_rate": (model.num_timesteps - start) / spent[0]}


_STARTUP = r"""
import json, sys, time
t0 = time.perf_counter()
import tether_gym
t1 = time.perf_counter()
import gymnasium as gym
env = gym.make(tether_gym.ENV_ID)
env.reset(seed=0)
env.step(env.action_space.sample())
t2 = time.perf_counter()
print(json.dumps({"import": t1 - t0, "first_call": t2 - t1}))
"""

_MEMORY = r"""
import json, resource, sys
import numpy as np, gymnasium as gym, tether_gym
num = int(sys.argv[1])
if num:
    env = gym.make_vec(tether_gym.ENV_ID, num_envs=num, vectorization_mode="vector_entry_point")
    env.reset(seed=0)
    for _ in range(5):
        obs, *_ = env.step(env.action_space.sample())
else:
    env = gym.make(tether_gym.ENV_ID)
    env.reset(seed=0)
    env.step(env.action_space.sample())
# ru_maxrss keeps the parent's high-water mark across fork + exec on Linux, so prefer
# the process's own VmHWM
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
try:
    with open("/proc/self/status") as status:
        peak = next(int(line.split()[1]) for line in status if line.startswith("VmHWM:"))
except (OSError, StopIteration):
    pass
print(json.dumps({"maxrss_kib": peak}))
"""


def subprocess_json(code: str, *args: str, env: dict | None = None) -> tuple[dict, float]:
    """Run ``python -c code`` and parse its last stdout line; also return the wall time."""
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                         env=env, check=True)
    wall = time.perf_counter() - t0
    return json.loads(out.stdout.strip().splitlines()[-1]), wall


def machine_info() -> list[str]:
    import numba

    lines = [
        f"command: `{' '.join([os.path.basename(sys.executable)] + sys.argv)}`",
        f"machine: {platform.machine()}, {os.cpu_count()} cores "
        f"(numba threads {numba.get_num_threads()}, layer "
        f"{numba.config.THREADING_LAYER}), load average "
        f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}",
        f"python {platform.python_version()}, numpy {np.__version__}, "
        f"numba {numba.__version__}, gymnasium {gym.__version__}, "
        f"tether_gym {tether_gym.__version__}",
    ]
    try:
        import stable_baselines3
        import torch

        lines[-1] += (f", stable-baselines3 {stable_baselines3.__version__}, "
                      f"torch {torch.__version__}")
    except ImportError:  # pragma: no cover - optional
        pass
    return lines


def row(what: str, value: str, ratio: str = "", target: str = "", ok: bool | None = None):
    verdict = "" if ok is None else ("PASS" if ok else "MISS")
    return f"| {what} | {value} | {ratio} | {target} | {verdict} |"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small budgets (CI smoke run)")
    args = parser.parse_args(argv)
    quick = args.quick
    rounds = 2 if quick else 5

    for line in machine_info():
        print(f"- {line}")
    print()
    rows = ["| Measure | Value | Ratio | Target | Result |", "|---|---|---|---|---|"]

    # ---- single env vs Pendulum ---------------------------------------- #
    steps = 1000 if quick else 5000
    rates = best_rates({"pendulum": single_runner("Pendulum-v1", steps),
                        "single": single_runner(ENV_ID, steps)}, rounds)
    pendulum = rates["pendulum"]
    rows.append(row("Pendulum-v1 single env (gym.make)", f"{pendulum:,.0f} steps/s", "1x"))
    ratio = rates["single"] / pendulum
    check, text = TARGETS["single"]
    rows.append(row("TetherLibration-v1 single env (gym.make)", f"{rates['single']:,.0f} steps/s",
                    f"{ratio:.2f}x Pendulum", text, check(ratio)))

    # ---- vector env ------------------------------------------------------ #
    budget = 20_000 if quick else 100_000  # env steps per round
    vec_runners = {}
    for num in (1, 16, 256, 1024):
        vec_runners[(num, "auto")] = vector_runner(num, max(3, budget // num))
    for num in (256, 1024):
        vec_runners[(num, False)] = vector_runner(num, max(3, budget // num), parallel=False)
    vec_runners[(256, "noisy")] = vector_runner(256, max(3, budget // 256),
                                                disturbance=0.1, obs_noise=1e-3)
    vec_runners[(16, "sync")] = vector_runner(16, max(3, budget // 16 // 4), mode="sync")
    vec_rates = best_rates(vec_runners, max(2, rounds - 2))
    for (num, parallel), rate in vec_rates.items():
        ratio = rate / pendulum
        ok = text = None
        if num == 256 and parallel == "auto":
            check, text = TARGETS["vec256"]
            ok = check(ratio)
        what = {"auto": f"vector env, {num} envs (default parallel='auto')",
                False: f"vector env, {num} envs (parallel=False, 1 thread)",
                "noisy": f"vector env, {num} envs, disturbance 0.1 + obs noise 1e-3",
                "sync": f"for reference: gymnasium SyncVectorEnv, {num} single envs"}[parallel]
        rows.append(row(what, f"{rate:,.0f} env-steps/s", f"{ratio:.2f}x Pendulum",
                        text or "", ok))

    # ---- PPO ------------------------------------------------------------- #
    try:
        ppo = ppo_figures(8, 64 if quick else 256, 1024 if quick else 8192)
    except ImportError as exc:  # pragma: no cover - optional
        rows.append(row("PPO training", f"skipped ({exc}); pip install \"tether_gym[train]\""))
    else:
        check, text = TARGETS["ppo_share"]
        rows.append(row("SB3 PPO MlpPolicy, 8 envs, n_steps "
                        f"{64 if quick else 256} (1 torch thread)",
                        f"{ppo['rate']:,.0f} steps/s", f"{ppo['rate'] / pendulum:.2f}x Pendulum"))
        rows.append(row("  share of PPO wall time in step_wait/reset",
                        f"{100 * ppo['share']:.1f} %", "", text, check(ppo["share"])))

    # ---- cost against N --------------------------------------------------- #
    n_steps = max(3, (5_000 if quick else 25_000) // 256)
    n_runners = {nb: vector_runner(256, n_steps, zero_actions=True, n_bodies=nb)
                 for nb in (2, 3, 5, 8)}
    n_rates = best_rates(n_runners, max(2, rounds - 2))
    check, text = TARGETS["n8"]
    for nb, rate in n_rates.items():
        cost = n_rates[3] / rate
        rows.append(row(f"cost per env step, N = {nb} (256 envs, zero action)",
                        f"{1e6 / rate:.1f} us", f"{cost:.2f}x N=3",
                        text if nb == 8 else "", check(cost) if nb == 8 else None))

    # ---- start-up -------------------------------------------------------- #
    warm = [subprocess_json(_STARTUP)[0] for _ in range(1 if quick else 3)]
    warm_best = min(warm, key=lambda d: d["import"] + d["first_call"])
    with tempfile.TemporaryDirectory() as cache:
        cold, _ = subprocess_json(_STARTUP, env={**os.environ, "NUMBA_CACHE_DIR": cache})
    check, text = TARGETS["startup"]
    total = warm_best["import"] + warm_best["first_call"]
    rows.append(row("`import tether_gym` (subprocess)", f"{warm_best['import']:.2f} s"))
    rows.append(row("import + gym.make + reset + step, warm numba cache",
                    f"{total:.2f} s", f"first call {warm_best['first_call']:.2f} s", text,
                    check(total)))
    check, text = TARGETS["cold"]
    cold_total = cold["import"] + cold["first_call"]
    rows.append(row("import + gym.make + reset + step, empty numba cache",
                    f"{cold_total:.1f} s", f"first call {cold['first_call']:.1f} s (compiles)",
                    text, check(cold_total)))

    # ---- memory ---------------------------------------------------------- #
    base, _ = subprocess_json(_MEMORY, "0")
    big, _ = subprocess_json(_MEMORY, "1024")
    rows.append(row("peak RSS, single env process", f"{base['maxrss_kib'] / 1024:.0f} MiB"))
    rows.append(row("peak RSS, 1024-env vector env process", f"{big['maxrss_kib'] / 1024:.0f} MiB",
                    f"+{(big['maxrss_kib'] - base['maxrss_kib']) / 1024:.0f} MiB"))

    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
