"""The rollout's own arithmetic in ``train.py gpu``, eager and fused (``--compile-rollout``).

    python bench/accel_rollout.py                      # configs/gpu_ppo.yml (J), 1 seed
    python bench/accel_rollout.py --seeds 10 --device cuda
    python bench/accel_rollout.py --env numba         # the whole rollout step, a real env
    python bench/accel_rollout.py --env numba --sync-free  # its autoreset without syncs

A rollout step of the learner is the policy's half (:meth:`~tether_gym_agents.accel.
rollout.Rollout.act`: the action draws, the actions, their records), the env's step and
the learner's half (``take`` and :meth:`~tether_gym_agents.accel.rollout.Rollout.observe`:
the normalisation, the truncation bootstrap, the counts); after ``n_steps`` of them come
the advantages (:meth:`~tether_gym_agents.accel.rollout.Rollout.finish`). This script
runs an iteration of them once eagerly and once fused, and for each reports, per rollout
step (an iteration's count or time divided by ``n_steps``, the advantages included):

* the kernels, from ``torch.profiler`` over one iteration after a warm-up iteration
  (which compiles), counted as ``bench/accel_update.py`` counts them (on the CPU
  Inductor's kernels and the outermost aten operations; on a CUDA device every kernel);
* the milliseconds (median of ``--repeats`` iterations, synced).

By default it runs the rollout's own pieces on made-up env steps of the config's size
(random observations, rewards and ended rows: the arithmetic does not depend on the
values), fused meaning ``Rollout(compiled=True)`` (each piece but the draws through
``torch.compile``): the env's step is not in the figures. With ``--env BACKEND`` it runs
the learner's whole rollout step (:class:`~tether_gym_agents.accel.graphs.RolloutStep`)
on a real env of that backend, fused meaning the env's ``compile=True`` too (with a numba
backend: the torch arithmetic around its kernel), as ``train.py gpu --compile
--compile-rollout`` trains; the policy is the untrained one, whose episodes end sooner
than a trained policy's, so the resets weigh more. The numba kernel itself is not a
torch kernel and is not counted on the CPU (on a GPU it is one of the kernels).
``bench/accel_iteration.py`` times whole iterations. It prints one JSON line.
"""

from __future__ import annotations

import sys
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from accel_update import cli, kernels_and_time, summary  # noqa: E402


def measure(config: Path, device: torch.device, seeds: int, repeats: int,
            env: str | None = None, sync_free: bool = False) -> dict:
    """The module docstring's figures for the config's rollout, eager and fused.

    ``env``: None (made-up env steps) or the backend of a real env; ``sync_free``: that
    env's autoreset without host syncs.
    """
    from tether_gym_agents.accel.cli import read_config
    from tether_gym_agents.accel.graphs import RolloutStep
    from tether_gym_agents.accel.ppo import MultiSeedPolicy
    from tether_gym_agents.accel.rollout import Rollout
    from tether_gym_agents.accel.vec_env import TorchTetherVecEnv

    settings, _, env_kwargs = read_config(config)[:3]
    probe = TorchTetherVecEnv(1, **env_kwargs)
    d, a = probe.observation_dim, probe.n
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
        if env is None:
            rollout.start(made_up[0][0])

            @torch.no_grad()
            def iteration(rollout=rollout) -> None:
                for step in made_up:
                    rollout.act()
                    rollout.take(*step)
                    rollout.observe()
                rollout.finish()
        else:
            mode = "same_step_sync_free" if sync_free else "same_step"
            real = TorchTetherVecEnv(S * N, device=device, seed=S, backend=env,
                                     autoreset_mode=mode, check_actions=False,
                                     compile=fused, full_info=False, **env_kwargs)
            rollout.start(real.reset()[0])
            step = RolloutStep(rollout, real)

            @torch.no_grad()
            def iteration(rollout=rollout, step=step) -> None:
                for _ in range(T):
                    step()
                rollout.finish()

        out["fused" if fused else "eager"] = kernels_and_time(
            iteration, device, repeats, T, "rollout_step", "first_iteration_s")
    return summary(config, device, seeds, out, "rollout_step", env=env, sync_free=sync_free,
                   envs_per_seed=N,
                   rollout_steps_per_iteration=T, repeats=repeats)


def main(argv=None) -> int:
    return cli(measure, __doc__.split("\n")[0], "iteration", argv, env=True)


if __name__ == "__main__":
    sys.exit(main())
