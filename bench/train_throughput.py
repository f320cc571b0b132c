"""Training throughput per recipe, and where the time goes: ``python bench/train_throughput.py``.

Trains each recipe (a hyperparameter file of ``configs/``) for a small fixed budget of
env steps, in this process, through the same ``training.run.train`` that ``train.py``
runs (envs, VecNormalize, VecMonitor, evaluation and checkpoint callbacks, run folder in
a temporary directory), on one core: the process pins itself to one CPU (``--cpu``),
so the native vector env steps its rows serially, and torch and numba get one thread.
It prints one markdown table. Each share is a part of the wall time of ``model.learn``:

* **env**: inside the native vector env (``TetherLibrationVectorEnv.step`` and
  ``reset``: the compiled step, the random draws, the auto-resets);
* **inference**: the policy's forward passes while collecting experience (PPO:
  ``policy(obs)`` and ``predict_values``; SAC: ``policy.predict``);
* **other rollout**: the rest of the rollout loop's per-step Python: the SB3 adapter's
  info dicts (also shown alone, "adapter"), VecNormalize, VecMonitor, the rollout or
  replay buffer, GAE, the callbacks' per-step calls, tensor conversions;
* **update**: ``PPO.train`` / ``CapsSAC.train`` (minibatch or gradient steps), with the cost
  of one minibatch (PPO) or one gradient step (SAC);
* **eval + ckpt**: the evaluation callback (its episodes, the best-agent saves) and the
  checkpoints, which a recipe's ``eval_freq`` and ``checkpoint_freq`` set;
* **rest**: ``learn``'s set-up and logging.

"per CPU s" divides the env steps by the process's CPU time in ``learn``: on a machine
where other jobs share the core it stays near the idle machine's steps/s while the wall
rate drops (the shares are of wall time, and are disturbed less than the rate).

Budgets are small (the first rollout's warm-up is included), so the figures are a
recipe's steady pace to within a few per cent. Run it on an idle machine: the figures
of a run beside another job are provisional. ``--quick`` divides every budget by 5
(a smoke run; SAC keeps 6000 steps, past ``learning_starts``).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import io
import math
import os
import platform
import sys
import tempfile
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

# one thread for every library, before any of them is imported
for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from tether_gym_agents.files.safe_format import ALGOS  # noqa: E402  (after the threads)

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "agents" / "configs"


@dataclass(frozen=True)
class Recipe:
    """One row: a name, the algorithm, the hyperparameter file and the env-step budget."""

    name: str
    algo: str
    config: Path
    timesteps: int

    @classmethod
    def parse(cls, text: str) -> Recipe:
        """``ALGO:PATH[@STEPS]``, e.g. ``ppo:configs/ppo_fast.yml@300000``."""
        algo, sep, rest = text.partition(":")
        if not sep or algo not in ALGOS:
            raise argparse.ArgumentTypeError(
                f"recipe {text!r}: must be ALGO:PATH[@STEPS] with ALGO one of {list(ALGOS)}")
        path, _, steps = rest.partition("@")
        try:
            budget = int(steps) if steps else (100_000 if algo == "ppo" else 20_000)
        except ValueError:
            raise argparse.ArgumentTypeError(f"recipe {text!r}: STEPS {steps!r} is not an "
                                             "integer") from None
        if budget < 1:
            raise argparse.ArgumentTypeError(f"recipe {text!r}: STEPS must be >= 1")
        return cls(Path(path).stem, algo, Path(path), budget)


def default_recipes() -> list[Recipe]:
    """The shipped PPO recipe, the fast one (if present) and SAC."""
    recipes = [Recipe("ppo", "ppo", CONFIGS / "ppo.yml", 100_000)]
    if (CONFIGS / "ppo_fast.yml").is_file():
        recipes.append(Recipe("ppo_fast", "ppo", CONFIGS / "ppo_fast.yml", 400_000))
    recipes.append(Recipe("sac", "sac", CONFIGS / "sac.yml", 20_000))
    return recipes


class Profile:
    """Wall time spent in named methods, patched on their classes for one run.

    A method wrapped with ``alone=True`` (the evaluation callback) counts all its time
    under its own key: the methods it calls are not counted meanwhile. One wrapped with
    ``in_rollout=True`` counts only inside the rollout (``collect_rollouts``), not in
    ``learn``'s set-up.
    """

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        self.cpu_seconds: dict[str, float] = defaultdict(float)
        self.counts: dict[str, int] = defaultdict(int)
        self._paused = 0
        self._rollouts = 0
        self._undo: list[tuple[type, str, object]] = []

    def wrap(self, owner: type, name: str, key: str, alone: bool = False,
             in_rollout: bool = False, count=None) -> None:
        """Time ``owner.name`` under ``key`` (``count(args, kwargs)``: units per call)."""
        original = getattr(owner, name)
        profile = self
        rollout = key == "rollout"

        @functools.wraps(original)
        def timed(*args, **kwargs):
            if profile._paused or (in_rollout and not profile._rollouts):
                return original(*args, **kwargs)
            profile._paused += alone
            profile._rollouts += rollout
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                return original(*args, **kwargs)
            finally:
                profile.seconds[key] += time.perf_counter() - t0
                profile.cpu_seconds[key] += time.process_time() - c0
                profile.counts[key] += count(args, kwargs) if count else 1
                profile._paused -= alone
                profile._rollouts -= rollout

        self._undo.append((owner, name, vars(owner).get(name)))
        setattr(owner, name, timed)

    def restore(self) -> None:
        """Put every wrapped method back."""
        for owner, name, original in reversed(self._undo):
            if original is None:
                delattr(owner, name)
            else:
                setattr(owner, name, original)
        self._undo.clear()


@contextlib.contextmanager
def profiled():
    """A :class:`Profile` of the methods this bench reports, patched while in use."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
    from stable_baselines3.common.policies import ActorCriticPolicy, BasePolicy

    from tether_gym.envs.vector import TetherLibrationVectorEnv
    from tether_gym_agents.training.callbacks import RunCheckpointCallback, RunEvalCallback
    from tether_gym_agents.training.caps import CapsMixin
    from tether_gym_agents.training.vec_env import TetherSB3VecEnv

    profile = Profile()
    for owner in (OnPolicyAlgorithm, OffPolicyAlgorithm):
        profile.wrap(owner, "learn", "learn")
        profile.wrap(owner, "collect_rollouts", "rollout")
    profile.wrap(PPO, "train", "update")
    # train.py's SAC and TQC are CapsSAC and CapsTQC, whose train is CapsMixin's (the
    # library's own train runs inside it when no smoothing is set)
    profile.wrap(CapsMixin, "train", "update",
                 count=lambda a, k: k.get("gradient_steps", a[1] if len(a) > 1 else 1))
    profile.wrap(TetherLibrationVectorEnv, "step", "env", in_rollout=True)
    profile.wrap(TetherLibrationVectorEnv, "reset", "env", in_rollout=True)
    profile.wrap(TetherSB3VecEnv, "step_wait", "adapter", in_rollout=True)
    profile.wrap(TetherSB3VecEnv, "reset", "adapter", in_rollout=True)
    profile.wrap(ActorCriticPolicy, "forward", "inference", in_rollout=True)
    profile.wrap(ActorCriticPolicy, "predict_values", "inference", in_rollout=True)
    profile.wrap(BasePolicy, "predict", "inference", in_rollout=True)  # SAC's rollout actions
    profile.wrap(RunEvalCallback, "_evaluate", "eval", alone=True)
    profile.wrap(RunEvalCallback, "_on_training_end", "eval", alone=True)
    profile.wrap(RunCheckpointCallback, "_on_step", "ckpt", alone=True)
    try:
        yield profile
    finally:
        profile.restore()


def measure(recipe: Recipe, out: Path) -> dict:
    """Train ``recipe`` into ``out``; the profile's figures."""
    from tether_gym_agents.training.run import train
    from tether_gym_agents.training.settings import TrainOptions, resolve_settings

    options = TrainOptions(algo=recipe.algo, config=str(recipe.config), timesteps=recipe.timesteps,
                           out=str(out), no_progress=True, torch_threads=1)
    settings = resolve_settings(options)
    with profiled() as profile, contextlib.redirect_stdout(io.StringIO()):
        summary = train(settings)
    s = profile.seconds
    wall = s["learn"]
    hp = settings.hyperparams
    if recipe.algo == "ppo":
        rollout = settings.n_envs * hp.get("n_steps", 2048)
        minibatches = (profile.counts["update"] * hp.get("n_epochs", 10)
                       * math.ceil(rollout / hp.get("batch_size", 64)))
        unit = f"{1e3 * s['update'] / max(minibatches, 1):.2f} ms/minibatch"
        geometry = (f"{settings.n_envs} envs x {hp.get('n_steps', 2048)}, batch "
                    f"{hp.get('batch_size', 64)}, {hp.get('n_epochs', 10)} epochs")
    else:
        unit = f"{1e3 * s['update'] / max(profile.counts['update'], 1):.2f} ms/grad step"
        geometry = (f"{settings.n_envs} envs, batch {hp.get('batch_size', 256)}, "
                    f"train_freq {hp.get('train_freq', 1)}, grad steps "
                    f"{hp.get('gradient_steps', 1)}")
    net = (hp.get("policy_kwargs") or {}).get("net_arch", "default")
    eval_ckpt = s["eval"] + s["ckpt"]
    other = s["rollout"] - s["env"] - s["inference"] - eval_ckpt
    return {"recipe": recipe.name, "geometry": f"{geometry}, {net}",
            "steps": summary.num_timesteps, "wall": wall,
            "rate": summary.num_timesteps / wall,
            "cpu_rate": summary.num_timesteps / max(profile.cpu_seconds["learn"], 1e-9),
            "env": s["env"] / wall, "inference": s["inference"] / wall,
            "other": other / wall, "adapter": (s["adapter"] - s["env"]) / wall,
            "update": s["update"] / wall, "eval": eval_ckpt / wall,
            "rest": (wall - s["rollout"] - s["update"]) / wall, "unit": unit}


def machine_lines(cpu: int | None) -> list[str]:
    """The command, the machine, its load and the versions."""
    import numpy as np
    import stable_baselines3
    import torch

    import tether_gym

    return [f"command: `{' '.join([os.path.basename(sys.executable)] + sys.argv)}`",
            f"machine: {platform.machine()}, {os.cpu_count()} cores, pinned to CPU "
            f"{cpu if cpu is not None else 'none'}, torch threads {torch.get_num_threads()}, "
            f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())} (at the start)",
            f"python {platform.python_version()}, numpy {np.__version__}, torch "
            f"{torch.__version__}, stable-baselines3 {stable_baselines3.__version__}, "
            f"tether_gym {tether_gym.__version__}"]


def table(results: list[dict]) -> list[str]:
    """The markdown table of the results."""
    rows = ["| recipe | geometry | env steps | env steps/s | per CPU s | % env | % inference | "
            "% other rollout (adapter) | % update | update cost | % eval + ckpt | % rest |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        rows.append(f"| {r['recipe']} | {r['geometry']} | {r['steps']:,} in {r['wall']:.0f} s "
                    f"| {r['rate']:,.0f} | {r['cpu_rate']:,.0f} | {100 * r['env']:.1f} | "
                    f"{100 * r['inference']:.1f} | "
                    f"{100 * r['other']:.1f} ({100 * r['adapter']:.1f}) | "
                    f"{100 * r['update']:.1f} | {r['unit']} | {100 * r['eval']:.1f} | "
                    f"{100 * r['rest']:.1f} |")
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("recipes", nargs="*", type=Recipe.parse,
                        help="ALGO:PATH[@STEPS] (default: configs/ppo.yml@100000, "
                             "configs/ppo_fast.yml@400000 if present, configs/sac.yml@20000)")
    parser.add_argument("--quick", action="store_true", help="budgets / 5 (a smoke run)")
    parser.add_argument("--cpu", type=int, default=None,
                        help="CPU to pin to (default: the last one this process may use; "
                             "-1: no pinning)")
    args = parser.parse_args(argv)
    recipes = args.recipes or default_recipes()
    for recipe in recipes:
        if not recipe.config.is_file():
            parser.error(f"{recipe.config}: no such hyperparameter file")
    cpu = None
    if args.cpu != -1 and hasattr(os, "sched_setaffinity"):
        cpu = args.cpu if args.cpu is not None else max(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpu})
    if args.quick:
        # SAC keeps a few gradient steps past sac.yml's learning_starts (5000)
        recipes = [Recipe(r.name, r.algo, r.config,
                          max(r.timesteps // 5, 1000 if r.algo == "ppo" else 6000))
                   for r in recipes]
    for line in machine_lines(cpu):
        print(f"- {line}")
    print()
    results = []
    with tempfile.TemporaryDirectory(prefix="train_throughput_") as tmp:
        for i, recipe in enumerate(recipes):
            print(f"  {recipe.name}: {recipe.timesteps:,} env steps of {recipe.config} ...",
                  file=sys.stderr, flush=True)
            results.append(measure(recipe, Path(tmp) / f"{i}_{recipe.name}"))
    print("\n".join(table(results)))
    print(f"\nload average at the end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
