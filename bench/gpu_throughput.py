"""Env throughput of the torch path (TorchTetherVecEnv) beside the numba vector env.

    python bench/gpu_throughput.py --device cuda --envs 4096 65536 262144 1048576 --out F.json
    python bench/gpu_throughput.py --device cuda --envs 65536 1048576 --backend torch numba-cuda
    python bench/gpu_throughput.py --device cpu --envs 256 4096 --numba      # the CPU ratio
    python bench/gpu_throughput.py --device cpu --envs 256 4096 --numba --backend torch numba
    python bench/gpu_throughput.py --device cuda --envs 65536 --backend numba-cuda --graphed 16

For each batch size: env steps per second of ``TorchTetherVecEnv.step`` (N = 3,
float64, the ppo training distribution's env kwargs, zero actions, autoreset on), after
warm-up steps, timed over whole steps with the device synchronised. ``--numba`` times
the native vector env (``gym.make_vec``, one thread) at the same sizes in the same run;
``--backend torch numba numba-cuda`` times those backends of the env (``reset_s``: construction
and first reset, which includes numba-cuda's compile of the step kernel on a cold cache).
``--graphed K`` also times each backend's step as a learner on the device runs it: the
sync-free autoreset (``"same_step_sync_free"``), the step's parts without ``step``'s
copies, ``K`` steps captured as one CUDA graph and replayed (the step's own draws
inside it), where the backend allows one graph (``whole_step_graph``: the torch port,
numba-cuda; not the CPU's numba backend). On the CPU the graph is
``RecordingCapture``'s stand-in, a check of the wiring, not a speed.
Prints one line per measurement and writes them as JSON. (Whether numba-cuda compiles
the numba env's step at all, with its registers and spills, is ``bench/numba_cuda_ptx.py``,
which needs no GPU.)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import numpy as np

ENV_KWARGS = {"increment_gain": 0.5, "initial_theta": [0.0, 0.0], "init_theta_range": 0.15,
              "init_dtheta_range": 0.1, "eccentricity_range": [0.0, 0.35], "mass_range": 0.25,
              "observe_params": False, "disturbance": 0.1, "obs_noise": 0.001}


def _sync(device):
    import torch

    if device.type == "cuda":
        torch.cuda.synchronize(device)


def torch_rate(num, device, steps, warmup=3, mode="same_step", backend="torch"):
    import torch

    from tether_gym_agents.accel.vec_env import TorchTetherVecEnv

    t = time.perf_counter()
    env = TorchTetherVecEnv(num, device=device, seed=0, autoreset_mode=mode,
                            check_actions=False, backend=backend, **ENV_KWARGS)
    env.reset()
    _sync(env.device)
    start = time.perf_counter() - t
    a = torch.zeros((num, env.n), dtype=torch.float64, device=env.device)
    for _ in range(warmup):
        env.step(a)
    _sync(env.device)
    t = time.perf_counter()
    for _ in range(steps):
        env.step(a)
    _sync(env.device)
    dt = (time.perf_counter() - t) / steps
    return {"what": f"TorchTetherVecEnv backend={backend}", "device": str(env.device),
            "envs": num, "reset_s": start, "ms_per_step": dt * 1e3, "env_steps_per_s": num / dt}


def graphed_env(num, device, backend="torch", per_graph=16):
    """A reset sync-free env on zero actions and ``per_graph`` of its steps as a graph.

    Returns ``(env, graph)``, ``graph`` a :class:`~tether_gym_agents.accel.graphs.GraphedCall`
    of the steps' parts (CUDA's capture on a CUDA device, ``RecordingCapture`` else), or
    ``None`` where one graph cannot hold a step (``whole_step_graph`` False).
    """
    from tether_gym_agents.accel.graphs import CudaCapture, GraphedCall, RecordingCapture
    from tether_gym_agents.accel.vec_env import TorchTetherVecEnv

    env = TorchTetherVecEnv(num, device=device, seed=0, autoreset_mode="same_step_sync_free",
                            check_actions=False, backend=backend, full_info=False,
                            **ENV_KWARGS)
    if not env.whole_step_graph:
        return None
    env.reset()
    env.action_in.zero_()

    def steps_in_graph() -> None:
        for _ in range(per_graph):
            env.step_in_place()

    capture = CudaCapture() if env.device.type == "cuda" else RecordingCapture()
    return env, GraphedCall(steps_in_graph, capture, (env.generator,))


def graphed_rate(num, device, steps, backend="torch", per_graph=16):
    """Env steps per second of ``per_graph`` sync-free steps replayed as one CUDA graph.

    The step's parts (``env.step_in_place``) on zero actions, as
    :class:`~tether_gym_agents.accel.graphs.RolloutStep` calls them;
    ``ceil(steps / per_graph)`` replays timed after the graph's warm-up calls and
    capture. ``None`` where one graph cannot hold the step (``whole_step_graph``).
    """
    from tether_gym_agents.accel.graphs import WARMUP_STEPS

    t = time.perf_counter()
    made = graphed_env(num, device, backend, per_graph)
    if made is None:
        return None
    env, graph = made
    _sync(env.device)
    start = time.perf_counter() - t
    t = time.perf_counter()
    for _ in range(WARMUP_STEPS + 1):  # the warm-up calls, then the capture and a replay
        graph()
    _sync(env.device)
    capture_s = time.perf_counter() - t
    replays = -(-steps // per_graph)
    t = time.perf_counter()
    for _ in range(replays):
        graph()
    _sync(env.device)
    dt = (time.perf_counter() - t) / (replays * per_graph)
    return {"what": f"TorchTetherVecEnv backend={backend}, sync-free, {per_graph} steps "
                    f"per CUDA graph", "device": str(env.device), "envs": num,
            "reset_s": start, "warmup_and_capture_s": capture_s, "graph_steps": per_graph,
            "ms_per_step": dt * 1e3, "env_steps_per_s": num / dt}


def compiled_rate(num, device, steps):
    """The step's core (physics, failure code, reward, observation) under torch.compile.

    No resets and no random draws: what a fused step would cost. Returns the compile
    time (first call) and the steady-state time per step.
    """
    import torch

    from tether_gym_agents.accel import chain
    from tether_gym_agents.accel.vec_env import TorchTetherVecEnv

    env = TorchTetherVecEnv(num, device=device, seed=0, check_actions=False, **ENV_KWARGS)
    env.reset()
    cc = env.cc

    def core(nu, y, u, dist, noise, par):
        nu2, res = chain.advance(nu, y, u * cc.max_reel_rate, dist, par, cc, cc.substeps)
        code = chain.failure_code(res.y, res.tension_min, cc)
        ref = cc.amplitude * torch.sin(cc.frequency * nu2)
        dref = cc.amplitude * cc.frequency * torch.cos(cc.frequency * nu2)
        reward, _ = chain.reward(res.y, u, torch.zeros_like(u), res.tension_min, ref, dref, cc)
        obs = chain.observation(nu2, res.y, noise, par, u, cc)
        return nu2, res.y, obs, code, reward

    fused = torch.compile(core, dynamic=False)
    args = [env.nu, env.y, env.u, env.disturbance, env.noise, env.par]
    t = time.perf_counter()
    out = fused(*args)
    _sync(env.device)
    first = time.perf_counter() - t
    for _ in range(3):
        out = fused(out[0], out[1], *args[2:])
    _sync(env.device)
    t = time.perf_counter()
    for _ in range(steps):
        out = fused(out[0], out[1], *args[2:])
    _sync(env.device)
    dt = (time.perf_counter() - t) / steps
    return {"what": "torch.compile core step", "device": str(env.device), "envs": num,
            "compile_and_first_s": first, "ms_per_step": dt * 1e3, "env_steps_per_s": num / dt}


def numba_rate(num, steps, warmup=3):
    import gymnasium as gym

    import tether_gym  # noqa: F401

    venv = gym.make_vec(tether_gym.ENV_ID, num_envs=num,
                        vectorization_mode="vector_entry_point", parallel=False, **ENV_KWARGS)
    venv.reset(seed=0)
    a = np.zeros((num, 2))
    for _ in range(warmup):
        venv.step(a)
    t = time.perf_counter()
    for _ in range(steps):
        venv.step(a)
    dt = (time.perf_counter() - t) / steps
    return {"what": "numba", "device": "cpu (1 thread)", "envs": num, "ms_per_step": dt * 1e3,
            "env_steps_per_s": num / dt}


def main(argv=None) -> int:
    from tether_gym_agents.accel.vec_env import BACKENDS

    p = argparse.ArgumentParser()
    p.add_argument("--device", default="cpu")
    p.add_argument("--envs", type=int, nargs="+", default=[256, 4096])
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--backend", nargs="+", default=["torch"],
                   choices=BACKENDS,
                   help="TorchTetherVecEnv backends to time (numba: CPU only; numba-cuda: "
                        "CUDA devices only)")
    p.add_argument("--numba", action="store_true")
    p.add_argument("--compile", action="store_true", help="also time the torch.compile'd core")
    p.add_argument("--graphed", type=int, default=0, metavar="K",
                   help="also time each backend's sync-free step, K steps per CUDA graph "
                        "(the module docstring)")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    if args.graphed < 0:
        p.error(f"--graphed must be >= 1 steps per graph (0: off), got {args.graphed}")
    import torch

    torch.set_num_threads(int(os.environ.get("OMP_NUM_THREADS", "1")))
    from tether_gym_agents.accel.vec_env import resolve_device

    device = resolve_device(args.device)
    rows = []
    meta = {"python": sys.version.split()[0], "torch": torch.__version__,
            "machine": platform.processor() or platform.machine(),
            "gpu": torch.cuda.get_device_name(device) if device.type == "cuda" else None}
    print(json.dumps(meta))
    for num in args.envs:
        for backend in args.backend:
            row = torch_rate(num, device, args.steps, backend=backend)
            rows.append(row)
            print(json.dumps(row), flush=True)
            if args.graphed:
                graphed = graphed_rate(num, device, args.steps, backend, args.graphed)
                if graphed is None:
                    print(json.dumps({"what": f"backend={backend}: no whole-step graph "
                                              f"(its kernel is a host call)", "envs": num}))
                    continue
                rows.append(graphed)
                print(json.dumps(graphed), flush=True)
        if args.numba:
            row = numba_rate(num, args.steps)
            rows.append(row)
            print(json.dumps(row), flush=True)
    if args.compile:
        for num in args.envs:
            row = compiled_rate(num, device, args.steps)
            rows.append(row)
            print(json.dumps(row), flush=True)
    if args.out:
        with open(args.out, "w") as fh:
            json.dump({"meta": meta, "rows": rows}, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
