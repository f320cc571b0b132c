"""The rollout's own arithmetic in ``train.py gpu``, eager and fused (``--compile-rollout``).

    python bench/accel_rollout.py                      # configs/gpu_ppo.yml (J), 1 seed
    python bench/accel_rollout.py --seeds 10 --device cuda

A rollout step of the learner is the policy's half (:meth:`~tether_gym_agents.accel.
rollout.Rollout.act`: the action draws, the actions, their records), the env's step and
the learner's half (``take`` and :meth:`~tether_gym_agents.accel.rollout.Rollout.observe`:
the normalisation, the truncation bootstrap, the counts); after ``n_steps`` of them come
the advantages (:meth:`~tether_gym_agents.accel.rollout.Rollout.finish`). This script
runs the rollout's own pieces, without the env, on made-up env steps of the config's
size (random observations, rewards and ended rows: the arithmetic does not depend on the
values), once eagerly and once with ``compiled=True`` (each piece but the draws through
``torch.compile``), and for each reports, per rollout step (an iteration's count or time
divided by ``n_steps``, the advantages included):

* the kernels, from ``torch.profiler`` over one iteration after a warm-up iteration
  (which compiles), counted as ``bench/accel_update.py`` counts them (on the CPU
  Inductor's kernels and the outermost aten operations; on a CUDA device every kernel);
* the milliseconds (median of ``--repeats`` iterations, synced).

The env's step is not in these figures (``bench/accel_ops.py`` counts it,
``bench/accel_iteration.py --compile-rollout`` times the whole iteration). It prints one
JSON line.
"""

from __future__ import annotations

import sys
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from accel_update import cli, kernels_and_time, summary  # noqa: E402


def measure(config: Path, device: torch.device, seeds: int, repeats: int) -> dict:
    """The module docstring's figures for the config's rollout, eager and fused."""
    from tether_gym_agents.accel.cli import read_config
    from tether_gym_agents.accel.ppo import MultiSeedPolicy
    from tether_gym_agents.accel.rollout import Rollout
    from tether_gym_agents.accel.vec_env import TorchTetherVecEnv

    settings, _, env_kwargs = read_config(config)[:3]
    env = TorchTetherVecEnv(1, **env_kwargs)
    d, a = env.observation_dim, env.n
    S, N, T = seeds, settings.n_envs, settings.n_steps
    g = torch.Generator().manual_seed(0)
    f64 = torch.float64
    # T made-up env steps: raw observations, rewards, terminated, truncated, final obs
    made_up = [tuple(x.to(device) for x in (
        torch.randn((S * N, d), generator=g, dtype=f64), torch.randn(S * N, generator=g,
                                                                     dtype=f64),
        torch.rand(S * N, generator=g) < 0.01, torch.rand(S * N, generator=g) < 0.01,
        torch.randn((S * N, d), generator=g, dtype=f64))) for _ in range(T)]
    out: dict = {}
    for fused in (False, True):
        torch.manual_seed(0)
        policy = MultiSeedPolicy(list(range(seeds)), d, a, settings, device)
        rollout = Rollout(policy, settings, d, a, device, compiled=fused)
        rollout.start(made_up[0][0])

        @torch.no_grad()
        def iteration(rollout=rollout) -> None:
            for step in made_up:
                rollout.act()
                rollout.take(*step)
                rollout.observe()
            rollout.finish()

        out["fused" if fused else "eager"] = kernels_and_time(
            iteration, device, repeats, T, "rollout_step", "first_iteration_s")
    return summary(config, device, seeds, out, "rollout_step", envs_per_seed=N,
                   rollout_steps_per_iteration=T, repeats=repeats)


def main(argv=None) -> int:
    return cli(measure, __doc__.split("\n")[0], "iteration", argv)


if __name__ == "__main__":
    sys.exit(main())
