"""Record env trajectories bit for bit, or compare them with an earlier recording.

``python bench/trajectories.py record FILE.npz`` runs a fixed set of episodes through
the public interface (``gym.make`` and ``gym.make_vec``) and stores every
observation, reward, flag and ``info`` entry; ``python bench/trajectories.py compare
FILE.npz`` runs them again with the installed code and reports every array that is
not bitwise equal. Record before a refactoring that must not change what the env
returns, compare after it.

The cases cover the single env and the vector env (serial and threaded), autoresets
and partial resets, every reset option, randomised e and masses, the Eq. 20
disturbance and observation noise, N = 2, 4, 5, full gravity and reel limits.
"""

from __future__ import annotations

import argparse
import sys

import gymnasium as gym
import numpy as np

import tether_gym

ENV_ID = tether_gym.ENV_ID
STEPS = 300

RANDOMISED = {"initial_theta": (0.0, 0.0), "init_theta_range": 0.15, "init_dtheta_range": 0.1,
              "init_length_range": 0.1, "eccentricity_range": (0.0, 0.35), "mass_range": 0.25}

CASES = {
    "default": {},
    "randomised": RANDOMISED,
    "randomised_hidden": {**RANDOMISED, "observe_params": False},
    "disturbed": {**RANDOMISED, "disturbance": 0.1, "obs_noise": 1e-3},
    "n2": {"n_bodies": 2},
    "n5": {"n_bodies": 5, "init_theta_range": 0.1, "disturbance": 0.05},
    "full_gravity": {"gravity": "full", "total_tether_length": 2.0e5, "n_bodies": 4},
    "limits": {"speed_limit": 5.0, "accel_limit": 0.02, "reel_time_constant": 0.025,
               "eccentricity": 0.4, "amplitude": 0.3, "frequency": 2.0},
    "short": {"orbits_per_episode": 0.1, **RANDOMISED},
}

OPTIONS = ({"nu": 0.3}, {"theta": [0.05, -0.05]}, {"dtheta": [0.1, 0.2]},
           {"length": [0.6, 0.4]}, {"dlength": [0.01, -0.02]})


def _flatten(prefix: str, info: dict, out: dict) -> None:
    for key, value in info.items():
        if key.startswith("_") and isinstance(value, np.ndarray) and value.dtype == bool:
            out.setdefault(f"{prefix}/info/{key}", []).append(np.asarray(value))
            continue
        if isinstance(value, np.ndarray) and value.dtype == object:
            value = np.array(["" if v is None else str(v) for v in value])
        elif value is None or isinstance(value, str):
            value = np.array("" if value is None else value)
        out.setdefault(f"{prefix}/info/{key}", []).append(np.asarray(value))


def _actions(rng: np.random.Generator, shape) -> np.ndarray:
    """Smooth random actions with occasional saturation and jumps."""
    return np.clip(rng.normal(0.0, 0.6, shape), -1.2, 1.2).astype(np.float32)


def single_case(name: str, kwargs: dict, out: dict) -> None:
    env = gym.make(ENV_ID, **kwargs)
    rng = np.random.default_rng(1)
    n = env.unwrapped.config.n_tethers
    for seed in (0, 7):
        prefix = f"single/{name}/seed{seed}"
        obs, info = env.reset(seed=seed)
        out.setdefault(prefix + "/obs", []).append(obs)
        _flatten(prefix, info, out)
        for _ in range(STEPS):
            obs, reward, term, trunc, info = env.step(_actions(rng, (n,)))
            out[prefix + "/obs"].append(obs)
            out.setdefault(prefix + "/reward", []).append(np.float64(reward))
            out.setdefault(prefix + "/flags", []).append(np.array([term, trunc]))
            _flatten(prefix, info, out)
            if term or trunc:
                obs, info = env.reset()
                out[prefix + "/obs"].append(obs)
                _flatten(prefix, info, out)
    if n == 2:
        for i, opt in enumerate(OPTIONS):
            prefix = f"single/{name}/option{i}"
            obs, info = env.reset(seed=3, options=opt)
            out.setdefault(prefix + "/obs", []).append(obs)
            _flatten(prefix, info, out)
            for _ in range(20):
                obs, reward, term, trunc, info = env.step(_actions(rng, (n,)))
                out[prefix + "/obs"].append(obs)
                out.setdefault(prefix + "/reward", []).append(np.float64(reward))
                _flatten(prefix, info, out)
                if term or trunc:
                    break
    env.close()


def vector_case(name: str, kwargs: dict, parallel, num: int, out: dict) -> None:
    env = gym.make_vec(ENV_ID, num_envs=num, vectorization_mode="vector_entry_point",
                       parallel=parallel, **kwargs)
    rng = np.random.default_rng(2)
    n = env.unwrapped.config.n_tethers if hasattr(env, "unwrapped") else env.config.n_tethers
    prefix = f"vector/{name}/{parallel}/{num}"
    obs, info = env.reset(seed=11)
    out.setdefault(prefix + "/obs", []).append(obs)
    _flatten(prefix, info, out)
    for k in range(STEPS):
        obs, reward, term, trunc, info = env.step(_actions(rng, (num, n)))
        out[prefix + "/obs"].append(obs)
        out.setdefault(prefix + "/reward", []).append(reward)
        out.setdefault(prefix + "/flags", []).append(np.stack([term, trunc]))
        _flatten(prefix, info, out)
        if k == 100 and n == 2:  # partial reset with options
            mask = np.zeros(num, dtype=bool)
            mask[::3] = True
            obs, info = env.reset(options={"reset_mask": mask, "length": [0.55, 0.45]})
            out[prefix + "/obs"].append(obs)
            _flatten(prefix + "/partial", info, out)
    env.close()


def record_all() -> dict:
    out: dict = {}
    for name, kwargs in CASES.items():
        single_case(name, kwargs, out)
        vector_case(name, kwargs, False, 6, out)
    for name in ("default", "disturbed", "short"):
        vector_case(name, CASES[name], True, 160, out)
        vector_case(name, CASES[name], False, 160, out)
    return {key: np.stack(values) for key, values in out.items()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mode", choices=("record", "compare"))
    parser.add_argument("file")
    args = parser.parse_args(argv)
    arrays = record_all()
    if args.mode == "record":
        np.savez_compressed(args.file, **arrays)
        print(f"recorded {len(arrays)} arrays to {args.file}")
        return 0
    ref = np.load(args.file)
    missing = sorted(set(ref.files) - set(arrays))
    extra = sorted(set(arrays) - set(ref.files))
    differ = [k for k in ref.files if k in arrays and (
        ref[k].shape != arrays[k].shape or ref[k].dtype != arrays[k].dtype
        or ref[k].tobytes() != arrays[k].tobytes())]
    for k in differ:
        a, b = ref[k], arrays[k]
        detail = (f"shape {a.shape} vs {b.shape}" if a.shape != b.shape else
                  f"dtype {a.dtype} vs {b.dtype}" if a.dtype != b.dtype else
                  f"{np.count_nonzero(a != b)} of {a.size} entries differ")
        print(f"DIFFERS {k}: {detail}")
    for k in missing:
        print(f"MISSING {k}")
    for k in extra:
        print(f"EXTRA {k}")
    same = len(ref.files) - len(differ) - len(missing)
    print(f"{same} of {len(ref.files)} recorded arrays bitwise equal; {len(differ)} differ, "
          f"{len(missing)} missing, {len(extra)} new")
    return 0 if not (differ or missing) else 1


if __name__ == "__main__":
    sys.exit(main())
