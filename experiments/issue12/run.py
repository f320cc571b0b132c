"""Train one PPO run of an issue-12 variant, then evaluate it; one process, one core.

    python experiments/issue12/run.py VARIANT SEED --steps 1000000 --out experiments/issue12/runs

Mirrors agents/configs/ppo.yml (n_envs 8, n_steps 512, batch 256, 10 epochs, gamma
0.995, gae 0.95, lr 3e-4, clip 0.2, net [64, 64], VecNormalize obs+reward, clip_obs 10,
training distribution of its env_kwargs) with the variant's wrapper and overrides.
Writes RUN/result.json (per-episode metrics on the default suite and on our own
generalisation suite, wall times), RUN/curve.csv (training episodes), model.zip,
vecnormalize.pkl.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402
from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.vec_env import VecEnvWrapper, VecNormalize  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from wrappers import DESIGNS, TaskWrapper  # noqa: E402

import tether_gym  # noqa: E402, F401
from tether_gym_agents.evaluation.metrics import episode_metrics  # noqa: E402
from tether_gym_agents.evaluation.scenarios import RANDOM_INIT, Scenario, get_suite  # noqa: E402
from tether_gym_agents.training.vec_env import make_sb3_vec_env  # noqa: E402

TRAIN_KWARGS = {"initial_theta": (0.0, 0.0), "init_theta_range": 0.15, "init_dtheta_range": 0.1,
                "eccentricity_range": (0.0, 0.35), "mass_range": 0.25, "observe_params": False,
                "disturbance": 0.1, "obs_noise": 0.001}
PPO_KW = dict(n_steps=512, batch_size=256, n_epochs=10, gamma=0.995, gae_lambda=0.95,
              learning_rate=3e-4, clip_range=0.2, ent_coef=0.0,
              policy_kwargs={"net_arch": [64, 64], "log_std_init": -2.0})

GEN_SUITE = (
    Scenario("amp_0.1", "A = 0.1", {**RANDOM_INIT, "amplitude": 0.1}),
    Scenario("amp_0.3", "A = 0.3", {**RANDOM_INIT, "amplitude": 0.3}),
    Scenario("ecc_0.05", "e = 0.05", {**RANDOM_INIT, "eccentricity": 0.05}),
    Scenario("ecc_0.4", "e = 0.4 (outside training range)", {**RANDOM_INIT, "eccentricity": 0.4}),
    Scenario("init_0.25", "theta_i(0) in +-0.25", {**RANDOM_INIT, "init_theta_range": 0.25}),
    Scenario("accel_0.005", "accel limit 0.005 m/s^2", {**RANDOM_INIT, "accel_limit": 0.005}),
    Scenario("orbits_4", "4 orbits", {**RANDOM_INIT, "orbits_per_episode": 4,
                                      "max_episode_steps": -1}),
)


class EpisodeLog(VecEnvWrapper):
    """Records each training episode: end step, success, RMS error after orbit 1, excursion."""

    def __init__(self, venv):
        super().__init__(venv)
        self.rows = []
        self.t = 0
        n = venv.num_envs
        self.sq = np.zeros(n)
        self.cnt = np.zeros(n)
        self.ret = np.zeros(n)
        self.lmin = np.full((n, 2), np.inf)
        self.lmax = np.full((n, 2), -np.inf)
        self.nu0 = [None] * n

    def reset(self):
        return self.venv.reset()

    def step_wait(self):
        obs, rew, dones, infos = self.venv.step_wait()
        self.t += self.num_envs
        for i, info in enumerate(infos):
            if self.nu0[i] is None:
                self.nu0[i] = info["nu"] - 0.025
            self.ret[i] += rew[i]
            length = np.asarray(info["length"])
            self.lmin[i] = np.minimum(self.lmin[i], length)
            self.lmax[i] = np.maximum(self.lmax[i], length)
            if info["nu"] - self.nu0[i] > 2 * math.pi + 1e-9:
                e = np.asarray(info["theta"]) - info["theta_ref"]
                self.sq[i] += float(np.mean(e * e))
                self.cnt[i] += 1
            if dones[i]:
                ok = info.get("failure") is None and info.get("TimeLimit.truncated", False)
                rms = math.sqrt(self.sq[i] / self.cnt[i]) if self.cnt[i] else float("nan")
                self.rows.append((self.t, int(ok), rms, float((self.lmax[i] - self.lmin[i]).max()),
                                  float(self.ret[i]), str(info.get("failure"))))
                self.sq[i] = self.cnt[i] = self.ret[i] = 0.0
                self.lmin[i] = np.inf
                self.lmax[i] = -np.inf
                self.nu0[i] = None
        return obs, rew, dones, infos


def make_env(n_envs, seed, env_kwargs, design):
    venv = make_sb3_vec_env(n_envs, seed=seed, env_kwargs=env_kwargs)
    if design is not None:
        venv = TaskWrapper(venv, design)
    return venv


def _trajectory(infos, rewards, nu0, cfg, truncated):
    """A rollout.Trajectory from the step infos (row 0: the first step's with nu = nu0;
    the metrics read rows 1.. and nu[0] only)."""
    from tether_gym_agents.evaluation.rollout import RECORDED_KEYS, Trajectory

    first = dict(infos[0], nu=nu0)
    arrays = {k: np.array([np.asarray(i[k], dtype=float) for i in [first] + infos])
              for k in RECORDED_KEYS}
    k = len(infos)
    return Trajectory(**arrays, action=np.zeros((k, cfg.n_tethers)),
                      command=np.zeros((k, cfg.n_tethers)), reward=np.asarray(rewards),
                      failure=infos[-1]["failure"], truncated=bool(truncated),
                      settings={"control_step": cfg.control_step})


def evaluate_suite(model, vecnorm, design, scenarios, seeds):
    """Deterministic episodes, one observation per forward pass; per-episode metrics."""
    out = []
    for sc in scenarios:
        kwargs = dict(sc.env_kwargs)
        env = make_env(len(seeds), None, kwargs, design)
        base = env.venv if design is not None else env
        base.seed(seeds[0])
        cfg = base.config
        obs = env.reset()
        num = len(seeds)
        infos = [[] for _ in range(num)]
        rewards = [[] for _ in range(num)]
        finished = [None] * num
        nu0 = [None] * num
        act_dim = env.action_space.shape[0]
        while any(f is None for f in finished):
            nobs = vecnorm.normalize_obs(obs) if vecnorm is not None else obs
            actions = np.zeros((num, act_dim), dtype=np.float32)
            for i in range(num):
                if finished[i] is None:
                    actions[i] = model.predict(nobs[i:i + 1], deterministic=True)[0][0]
            obs, rew, dones, step_infos = env.step(actions)
            for i in range(num):
                if finished[i] is not None:
                    continue
                info = step_infos[i]
                if nu0[i] is None:
                    nu0[i] = info["nu"] - cfg.control_step
                infos[i].append(info)
                rewards[i].append(float(rew[i]))
                if dones[i]:
                    finished[i] = bool(info.get("TimeLimit.truncated", False))
        env.close()
        for i in range(num):
            m = episode_metrics(_trajectory(infos[i], rewards[i], nu0[i], cfg, finished[i]))
            m.update(scenario=sc.name, seed=seeds[i], failure=infos[i][-1]["failure"])
            out.append(m)
    return out


def summary(eps):
    def mean(key, only_success=False):
        vals = [e[key] for e in eps if (not only_success or e["success"]) and
                math.isfinite(e[key])]
        return float(np.mean(vals)) if vals else float("nan")
    return {"success": mean("success"), "tracking_rms": mean("tracking_rms"),
            "tracking_rms_success": mean("tracking_rms", True),
            "reel_excursion": mean("reel_excursion"), "reel_effort": mean("reel_effort"),
            "min_tension": mean("min_tension"), "final_error": mean("final_error"),
            "n": len(eps)}


def strict(obj):
    """JSON-ready copy: NaN/inf become None, numpy scalars become Python numbers."""
    if isinstance(obj, dict):
        return {str(k): strict(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [strict(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("variant", choices=sorted(DESIGNS))
    p.add_argument("seed", type=int)
    p.add_argument("--steps", type=int, default=1_000_000)
    p.add_argument("--out", type=Path, default=Path("experiments/issue12/runs"))
    p.add_argument("--eval-seeds", type=int, default=10)
    p.add_argument("--gen-seeds", type=int, default=5)
    p.add_argument("--eval-only", action="store_true",
                   help="evaluate the run folder's saved model.zip / vecnormalize.pkl")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    design, overrides = DESIGNS[args.variant]
    run_dir = args.out / f"{args.variant}_s{args.seed}"
    run_dir.mkdir(parents=True, exist_ok=True)
    kw = {**PPO_KW, **overrides}
    venv = EpisodeLog(make_env(8, args.seed, TRAIN_KWARGS, design))
    venv = VecNormalize(venv, gamma=kw["gamma"], norm_obs=True, norm_reward=True, clip_obs=10.0)
    if args.eval_only:
        venv = VecNormalize.load(str(run_dir / "vecnormalize.pkl"), venv)
        model = PPO.load(run_dir / "model.zip", device="cpu")
        wall_train = float(json.loads((run_dir / "train_wall.json").read_text())["wall_train_s"]) \
            if (run_dir / "train_wall.json").is_file() else float("nan")
    else:
        model = PPO("MlpPolicy", venv, seed=args.seed, device="cpu", verbose=0, **kw)
        t0 = time.perf_counter()
        model.learn(args.steps)
        wall_train = time.perf_counter() - t0
        model.save(run_dir / "model.zip")
        venv.save(str(run_dir / "vecnormalize.pkl"))
        (run_dir / "train_wall.json").write_text(json.dumps({"wall_train_s": wall_train}))
        log = venv.venv
        with open(run_dir / "curve.csv", "w") as fh:
            fh.write("step,success,rms_after_orbit1,excursion,return,failure\n")
            for row in log.rows:
                fh.write(",".join(str(x) for x in row) + "\n")
    venv.training = False
    t1 = time.perf_counter()
    default = evaluate_suite(model, venv, design, get_suite("default"),
                             list(range(args.eval_seeds)))
    gen = evaluate_suite(model, venv, design, GEN_SUITE,
                         [1000 + i for i in range(args.gen_seeds)])
    wall_eval = time.perf_counter() - t1
    result = {"variant": args.variant, "seed": args.seed, "steps": int(model.num_timesteps),
              "design": None if design is None else design.__dict__, "ppo": kw,
              "wall_train_s": round(wall_train, 1), "wall_eval_s": round(wall_eval, 1),
              "steps_per_s": round(model.num_timesteps / wall_train, 1),
              "command": "python " + " ".join([sys.argv[0]] + (argv or sys.argv[1:])),
              "default": summary(default), "gen": summary(gen),
              "episodes_default": default, "episodes_gen": gen,
              "torch": torch.__version__, "tether_gym": tether_gym.__version__}
    (run_dir / "result.json").write_text(json.dumps(strict(result), indent=1, allow_nan=False))
    print(json.dumps({k: result[k] for k in ("variant", "seed", "wall_train_s", "wall_eval_s",
                                              "steps_per_s", "default", "gen")}, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
