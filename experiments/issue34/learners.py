"""train.py gpu's home-made PPO against rsl_rl's PPO, on the same torch env (issue 34).

    pip install rsl-rl-lib==5.5.1              # not a dependency of the package
    python experiments/issue34/learners.py --learner home --seed 0 --out R.json
    python experiments/issue34/learners.py --learner rsl_rl --seed 0 --out R.json

Issue 34 asks for a well-kept GPU learner (rsl_rl's PPO, skrl or torchrl) and a home-made
PPO only if measured better. This trains one seed of either learner on
``TorchTetherVecEnv`` (``--device``, default cpu) with the hyperparameters of
``cfg/cpu_learners.yml`` (one source for both: stable-baselines3's batch sizes of
ppo_fast.yml, rsl_rl's adaptive learning rate) for ``n_timesteps`` env steps, then scores
the deterministic policy on 64 episodes of the training distribution with the same
function for both (``tether_gym_agents.accel.trainer.deterministic_episodes``), and writes
the wall times and scores as JSON. Each learner runs in its own idiom where they differ:
the home-made learner normalises rewards as VecNormalize does (rsl_rl has no reward
normalisation; ``--learner rsl_rl_rewnorm`` gives it the home-made learner's reward
scaling, to test whether that is the difference) and bootstraps truncated episodes from
their last observation (rsl_rl from the value of the observation before the step);
rsl_rl normalises observations with its EmpiricalNormalization. Both clip actions to
[-1, 1] before the env, as SB3 does.
``experiments/issue34/learners.md`` holds the table of a run of this script.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import torch

HERE = Path(__file__).resolve().parent
CONFIG = HERE / "cfg" / "cpu_learners.yml"


def rsl_env(num: int, seed: int, env_kwargs: dict, device, reward_norm=None):
    """TorchTetherVecEnv as an rsl_rl ``VecEnv`` (same-step autoreset, ``time_outs``).

    ``reward_norm``: PPOSettings whose VecNormalize reward scaling (the home-made
    learner's, ``rollout.scale_rewards``) the env applies to its rewards; None: raw.
    """
    from rsl_rl.env import VecEnv
    from tensordict import TensorDict

    from tether_gym_agents.accel.ppo import RunningStats
    from tether_gym_agents.accel.rollout import scale_rewards
    from tether_gym_agents.accel.vec_env import TorchTetherVecEnv

    class TetherRslEnv(VecEnv):
        def __init__(self):
            self.env = TorchTetherVecEnv(num, device=device, seed=seed, check_actions=False,
                                         autoreset_mode="same_step", **env_kwargs)
            self.num_envs, self.num_actions, self.device = num, self.env.n, self.env.device
            self.max_episode_length = self.env.config.max_episode_steps
            self.episode_length_buf = torch.zeros(num, dtype=torch.long, device=self.device)
            self.cfg = {"env_kwargs": env_kwargs}
            self._obs, _ = self.env.reset()
            self._returns = torch.zeros((1, num), dtype=torch.float64, device=self.device)
            self._stats = RunningStats(1, 1, self.device)

        def get_observations(self):
            return TensorDict({"policy": self._obs.float()}, batch_size=[self.num_envs])

        def step(self, actions):
            a = torch.clamp(actions, -1.0, 1.0).to(torch.float64)
            self._obs, rew, term, trunc, _ = self.env.step(a)
            done = term | trunc
            if reward_norm is not None:
                rew, self._returns = scale_rewards(rew[None], done[None], self._returns,
                                                   self._stats, reward_norm)
                rew = rew[0]
            self.episode_length_buf = torch.where(done, 0, self.episode_length_buf + 1)
            return (self.get_observations(), rew.float(), done.long(),
                    {"time_outs": (trunc & ~term).float()})

    return TetherRslEnv()


def rsl_config(s) -> dict:
    """rsl_rl's OnPolicyRunner configuration for the PPOSettings ``s``."""
    mlp = {"class_name": "MLPModel", "hidden_dims": list(s.net_arch), "activation": "tanh",
           "obs_normalization": True}
    return {
        "num_steps_per_env": s.n_steps, "save_interval": 10**9, "check_for_nan": True,
        "obs_groups": {"actor": ["policy"], "critic": ["policy"]},
        "algorithm": {"class_name": "PPO", "num_learning_epochs": s.n_epochs,
                      "num_mini_batches": s.n_envs * s.n_steps // s.batch_size,
                      "clip_param": s.clip_range, "gamma": s.gamma, "lam": s.gae_lambda,
                      "value_loss_coef": s.vf_coef, "entropy_coef": s.ent_coef,
                      "learning_rate": s.learning_rate, "max_grad_norm": s.max_grad_norm,
                      "schedule": "adaptive" if s.lr_schedule == "adaptive" else "fixed",
                      "desired_kl": s.desired_kl, "use_clipped_value_loss": False,
                      "normalize_advantage_per_mini_batch": True},
        "actor": {**mlp, "distribution_cfg": {"class_name": "GaussianDistribution",
                                              "init_std": math.exp(s.log_std_init),
                                              "std_type": "log"}},
        "critic": dict(mlp),
    }


def train_rsl(settings, steps: int, env_kwargs: dict, seed: int, device,
              reward_norm: bool = False) -> dict:
    from rsl_rl.runners import OnPolicyRunner
    from tensordict import TensorDict

    from tether_gym_agents.accel.trainer import deterministic_episodes

    t0 = time.perf_counter()
    torch.manual_seed(seed)
    env = rsl_env(settings.n_envs, seed * 7919 + 1, env_kwargs, device,
                  settings if reward_norm else None)
    runner = OnPolicyRunner(env, rsl_config(settings), log_dir=None, device=str(env.device))
    per_it = settings.n_envs * settings.n_steps
    iterations = max(1, steps // per_it)
    chunk = max(1, iterations // 10)
    done = 0
    while done < iterations:
        k = min(chunk, iterations - done)
        runner.learn(k)
        done += k
        print(f"rsl_rl seed {seed}: {done * per_it} env steps, "
              f"{time.perf_counter() - t0:.0f} s", flush=True)
    wall = time.perf_counter() - t0
    policy = runner.get_inference_policy(device=str(env.device))

    def act(raw):
        g, e, d = raw.shape
        out = policy(TensorDict({"policy": raw.reshape(g * e, d).float()}, batch_size=[g * e]))
        return out.reshape(g, e, -1)

    final = deterministic_episodes(act, 1, env_kwargs, env.device, 64, seed + 10_000)
    return {"steps": iterations * per_it, "train_wall_s": wall, "final": final}


def train_home(settings, steps: int, env_kwargs: dict, seed: int, device) -> dict:
    from tether_gym_agents.accel.trainer import GpuRun, train_seeds

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as out:
        summary = train_seeds(settings, GpuRun([seed], steps, env_kwargs, Path(out), device,
                                               checkpoints=1, clock_start=t0,
                                               eval_episodes=64))
    return {"steps": summary["steps_per_seed"], "train_wall_s": summary["wall_time_s"],
            "final": summary["final"]}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--learner", choices=["home", "rsl_rl", "rsl_rl_rewnorm"], required=True,
                   help="rsl_rl_rewnorm: rsl_rl on rewards scaled as the home-made learner's")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default="cpu")
    p.add_argument("--config", type=Path, default=CONFIG)
    p.add_argument("--timesteps", type=int, default=None, help="instead of n_timesteps")
    p.add_argument("--out", type=Path, required=True)
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    from tether_gym_agents.accel.cli import read_config
    from tether_gym_agents.accel.vec_env import resolve_device

    settings, steps, env_kwargs, _ = read_config(args.config)
    steps = steps if args.timesteps is None else args.timesteps
    device = resolve_device(args.device)
    t0 = time.perf_counter()
    if args.learner == "home":
        result = train_home(settings, steps, env_kwargs, args.seed, device)
    else:
        result = train_rsl(settings, steps, env_kwargs, args.seed, device,
                           reward_norm=args.learner == "rsl_rl_rewnorm")
    result.update(learner=args.learner, seed=args.seed, device=str(device),
                  whole_s=time.perf_counter() - t0, config=str(args.config.name),
                  torch=torch.__version__)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1))
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
