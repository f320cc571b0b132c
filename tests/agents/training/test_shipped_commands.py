"""Every shipped seed's ``command.txt`` retrains it from nothing (issue 26).

Its first line is a fresh ``train.py`` run and every later line resumes the same run
folder; replayed today, the first line resolves to the hyperparameters, env arguments
and seed the seed's ``config.yml`` records, and the lines' budgets add up to the env
steps of its ``train_info.json``.
"""

from __future__ import annotations

import json
import shlex
from dataclasses import asdict
from pathlib import Path

import pytest

from tether_gym.envs import EnvConfig
from tether_gym_agents.cli.train import build_parser
from tether_gym_agents.common.algorithms import ALGORITHMS
from tether_gym_agents.files import pretrained_agents
from tether_gym_agents.files.run_folder import read_config
from tether_gym_agents.training.settings import TrainOptions, resolve_settings

REPO = Path(__file__).resolve().parents[3]
ALL_SEEDS = [(name, run) for name, path in sorted(pretrained_agents().items())
             for run in sorted(Path(path).glob("seed_*"))]


def _trained_by(run: Path) -> str | None:
    """The ``algo`` a seed's ``train_info.json`` records: ``dagger`` for a seed fitted by
    ``train.py distill``, ``ppo_gpu`` for one trained by ``train.py gpu`` (issue 34)."""
    return json.loads((run / "train_info.json").read_text()).get("algo")


SEEDS = [(name, run) for name, run in ALL_SEEDS if _trained_by(run) not in ("dagger", "ppo_gpu")]
"""The seeds trained by stable-baselines3 (``train.py`` with a config)."""
ACCEL = [(name, run) for name, run in ALL_SEEDS if _trained_by(run) == "ppo_gpu"]
"""The seeds trained by ``train.py gpu``, several in one process (issue 34)."""
DISTILLED = [(name, run) for name, run in ALL_SEEDS if _trained_by(run) == "dagger"]
"""The seeds fitted by ``train.py distill`` on the shared mpc dataset (issue 36)."""


def _argv(line: str) -> list[str]:
    words = shlex.split(line)
    assert words[:2] == ["python", "train.py"], line
    return words[2:]


def _env(kwargs: dict) -> EnvConfig:
    return EnvConfig.from_kwargs(**{k: tuple(v) if isinstance(v, list) else v
                                    for k, v in kwargs.items()})


def test_every_shipped_agent_has_seeds():
    assert {name for name, _ in SEEDS} >= {"ppo", "ppo_symlog", "ppo_g025", "smc_residual",
                                           "ppo_fast", "sac", "distill_ppo", "sac_residual"}
    assert {name for name, _ in DISTILLED} == {"distill_bc"}
    assert {name for name, _ in ACCEL} == {"ppo_accel"}
    assert len(ACCEL) == 10


@pytest.mark.parametrize(("name", "run"), ACCEL, ids=[f"{n}-{r.name}" for n, r in ACCEL])
def test_an_accel_seeds_command_is_its_process(name, run, monkeypatch):
    """``command.txt`` of a ``train.py gpu`` seed is the one call that trained it with the
    other seeds of its process (their weights depend on the whole group: one generator
    starts them all). It parses with ``train.py gpu``'s parser; its config resolves to
    the hyperparameters and env arguments the seed's ``config.yml`` records; the seed is
    one of the call's; the device, backend and seeds per process are ``train_info.json``'s,
    and the env steps are the config's budget in whole rollouts."""
    from tether_gym_agents.accel.cli import build_parser as gpu_parser
    from tether_gym_agents.accel.cli import read_config as read_gpu_config

    monkeypatch.chdir(REPO)
    line = (run / "command.txt").read_text().strip()
    assert "\n" not in line
    words = _argv(line)
    assert words[0] == "gpu"
    args = gpu_parser().parse_args(words[1:])
    seed = int(run.name.split("_")[1])
    assert args.seed <= seed < args.seed + args.seeds
    settings, steps, env_kwargs, _ = read_gpu_config(args.config)
    recorded = read_config(run)
    assert recorded["algo"] == "ppo_gpu" and recorded["hyperparams"]["n_timesteps"] == steps
    hyper = {k: v for k, v in recorded["hyperparams"].items() if k != "n_timesteps"}
    assert json.loads(json.dumps(hyper)) == json.loads(json.dumps(asdict(settings)))
    assert _env(env_kwargs) == _env(recorded["env_kwargs"])
    info = json.loads((run / "train_info.json").read_text())
    assert (info["seed"], info["seeds_in_process"], info["device"], info["backend"]) == (
        seed, args.seeds, args.device, args.backend)
    assert info["status"] == "finished" and info["wall_time_s"] > 0
    rollout = settings.n_envs * settings.n_steps
    assert steps <= info["num_timesteps"] < steps + rollout


@pytest.mark.parametrize(("name", "run"), DISTILLED, ids=[f"{n}-{r.name}" for n, r in DISTILLED])
def test_a_distilled_seeds_command_is_the_documented_fit(name, run):
    """``command.txt`` of a behaviour-cloned seed parses with ``train.py distill``'s own
    parser into the fit experiments/issue36/distill_row.sh documents: set A of the shared
    dataset (the even parts 0 ... 166, made by make_data.sh), no labelling iterations."""
    from tether_gym_agents.training.distill_cli import build_parser as distill_parser

    line = (run / "command.txt").read_text().strip()
    assert "\n" not in line
    args = distill_parser().parse_args(_argv(line)[1:])
    assert args.seed == int(run.name.split("_")[1])
    assert (args.iterations, args.epochs, args.batch_size, args.symlog_scale,
            args.check_episodes) == (0, 40, 2048, 1e-4, 0)
    parts = sorted(int(Path(f).parent.name.removeprefix("part_")) for f in args.data)
    assert parts == list(range(0, 167, 2))
    info = json.loads((run / "train_info.json").read_text())
    assert info["command"] == line and info["seed"] == args.seed
    assert info["labels"] == 1_256_918 and info["episodes"] == 1667  # docs/distillation.md


@pytest.mark.parametrize(("name", "run"), SEEDS, ids=[f"{n}-{r.name}" for n, r in SEEDS])
def test_command_txt_parses_into_a_from_scratch_run(name, run, tmp_path, monkeypatch):
    monkeypatch.chdir(REPO)  # the commands name configs/ relative to a clone
    lines = [ln for ln in (run / "command.txt").read_text().splitlines() if ln.strip()]
    args = [build_parser().parse_args(_argv(ln)) for ln in lines]
    first, later = args[0], args[1:]
    assert not first.resume and first.seeds is None and first.sweep is None
    assert first.seed == int(run.name.split("_")[1])
    assert all(a.resume and a.out == first.out for a in later)  # one folder, continued
    first.out = str(tmp_path / "run")
    settings = resolve_settings(TrainOptions.from_namespace(first))
    recorded = read_config(run)
    resolved = settings.resolved_config()
    assert (resolved["algo"], resolved["seed"], resolved["n_envs"]) == (
        recorded["algo"], recorded["seed"], recorded["n_envs"])
    # the budget is checked against the steps trained below (a run given --timesteps
    # records its config's n_timesteps, which it did not use)
    skip = ("env_kwargs", "n_timesteps")
    hyper = {k: v for k, v in resolved["hyperparams"].items() if k not in skip}
    want = {k: v for k, v in recorded["hyperparams"].items() if k not in skip}
    # SB3's SAC adds policy_kwargs.use_sde to the mapping it is given, and config.yml
    # records the run's mapping after that (training/run.py)
    if resolved["algo"] == "sac" and "use_sde" not in hyper.get("policy_kwargs", {}):
        want["policy_kwargs"] = {k: v for k, v in want["policy_kwargs"].items()
                                 if k != "use_sde"}
    assert json.loads(json.dumps(hyper)) == json.loads(json.dumps(want))
    assert _env(resolved["env_kwargs"]) == _env(recorded["env_kwargs"])
    # budgets: the first call's n_timesteps, then each resume's --timesteps, in whole
    # rollouts of n_steps (PPO) or train_freq (SAC) x n_envs
    budget = settings.timesteps + sum(a.timesteps for a in later)
    info = json.loads((run / "train_info.json").read_text())
    steps = info["num_timesteps"]
    assert info["wall_time_s"] > 0  # every call's time, killed parts included
    hp = recorded["hyperparams"]  # PPO collects n_steps per env, SAC train_freq (steps)
    rollout = hp["n_steps"] if ALGORITHMS[recorded["algo"]].on_policy else hp.get("train_freq", 1)
    rollout *= recorded["n_envs"]
    assert budget <= steps < budget + rollout * (1 + len(later))
