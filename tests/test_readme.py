"""The README's commands of the train/evaluate kind run as printed (issue 24).

Every ``python train.py``, ``python evaluate.py`` and ``python -m
tether_gym_agents.files`` line in the README's code blocks is in :data:`COMMANDS`,
either with the arguments that shrink it to a tiny budget (run in-process in the list's
order, training before evaluating, in a scratch folder laid out like a clone) or with the
reason it is not run here; a README line missing from the list, or a listed line gone
from the README, fails :func:`test_every_readme_command_is_listed`, so the list cannot
drift.
"""

from __future__ import annotations

import contextlib
import io
import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PREFIXES = (("python", "train.py"), ("python", "evaluate.py"),
            ("python", "-m", "tether_gym_agents.files"))

TRAIN_TINY = ("--timesteps", "64", "--n-envs", "1", "--eval-episodes", "1", "--no-progress")
EVAL_TINY = ("--seeds", "1", "--no-plots")
SHORT_EPISODES = ("--env-kwargs", "orbits_per_episode=0.2")  # only where no --env-kwargs
RAY = "a Ray fan-out of full-budget seeds (tests/agents/training cover --seeds on Ray)"
ACCEL = ("a full-budget train.py gpu process (tests/agents/accel/test_accel_cli.py trains "
         "tiny ones; test_shipped_commands.py resolves these)")

COMMANDS: dict[str, tuple[str, ...] | str] = {
    # Training your own (in this order: later commands use the earlier run folders)
    "python train.py --algo ppo --timesteps 20000 --out runs/ppo": TRAIN_TINY,
    "python train.py --algo ppo --timesteps 20000 --out runs/e03 --env-kwargs "
    "eccentricity=0.3 'masses=(1, 3)'": TRAIN_TINY,
    "python train.py --algo ppo --timesteps 20000 --out runs/n4 --env-kwargs n_bodies=4":
        TRAIN_TINY,
    "python train.py --algo ppo --out runs/ppo --resume --timesteps 10000": TRAIN_TINY,
    "python evaluate.py smc runs/ppo --suite paper --seeds 3 --out runs/eval":
        EVAL_TINY + SHORT_EPISODES,
    "python train.py --config agents/configs/ppo_residual.yml --out runs/hybrid": TRAIN_TINY,
    "python train.py --algo sac --out runs/sac": TRAIN_TINY,
    "python train.py --algo tqc --out runs/tqc": TRAIN_TINY,
    # its config's batch of 512 needs its 64 envs (one fitted rollout of 64 x 1 steps)
    "python train.py --algo ppo_lag --out runs/ppo_lag":
        ("--timesteps", "64", "--eval-episodes", "1", "--no-progress"),
    "python -m tether_gym_agents.files export runs/ppo shipped/ppo": (),
    # How the benchmark is computed
    "python evaluate.py": EVAL_TINY + ("--suite", "paper") + SHORT_EPISODES,
    "python evaluate.py smc runs/ppo runs/sac --out runs/eval": EVAL_TINY + SHORT_EPISODES,
    "python evaluate.py smc smc_filtered --env-kwargs n_bodies=4 'masses=(1,1,1)'": EVAL_TINY,
    "python evaluate.py smc runs/n4": EVAL_TINY + SHORT_EPISODES,
    "python evaluate.py smc --suite my_suite.yml": EVAL_TINY + SHORT_EPISODES,
    # not run here
    "python evaluate.py paper --out docs/paper":
        "reproduces every figure of the paper (minutes; tests/agents/paper check its parts)",
    "python train.py --algo ppo --seeds 10 --seed 0 --out runs/ppo": RAY,
    "python train.py --algo ppo --seed K --resume --timesteps 3000000 --out "
    "runs/ppo/seed_K": "K stands for each seed 0 ... 9 of the shipped agents",
    "python -m tether_gym_agents.files export runs/ppo agents/pretrained/ppo":
        "writes the shipped agents from their full-budget runs",
    "python train.py --config configs/ppo_fast.yml --seed K --out runs/ppo_fast/seed_K":
        "K stands for each seed 0 ... 4 of the shipped agents (about 10 min each; "
        "tests/agents/training/test_shipped_commands.py resolves them)",
    "python train.py gpu --config configs/gpu_ppo.yml --seeds 2 --seed 0 --device cpu "
    "--backend numba --out runs/ppo_accel": ACCEL,
    "python train.py gpu --config configs/gpu_ppo.yml --seeds 4 --seed 2 --device cpu "
    "--backend numba --out runs/ppo_accel": ACCEL,
    "python train.py gpu --config configs/gpu_ppo.yml --seeds 4 --seed 6 --device cpu "
    "--backend numba --out runs/ppo_accel": ACCEL,
    "python evaluate.py curves runs/ppo --out docs/curves/ppo":
        "needs the five ppo runs with their checkpoints (tests/agents/evaluation/"
        "test_curves.py runs the command on tiny runs)",
    "python evaluate.py curves docs/curves/ppo docs/curves/ppo_symlog docs/curves/ppo_g025 "
    "docs/curves/ppo_fast docs/curves/sac docs/curves/smc_residual docs/curves/distill_ppo "
    "docs/curves/sac_residual docs/curves/filtered_distill_ppo docs/curves/ppo_accel "
    "--out docs/curves":
        "rewrites the shipped side-by-side curves (test_curves.py puts written curves side "
        "by side)",
    "python train.py --algo sac --config configs/sac.yml --seeds 5 --out runs/sac": RAY,
    "python -m tether_gym_agents.files export runs/sac agents/pretrained/sac":
        "writes the shipped agents from their full-budget runs",
    "python train.py --config configs/ppo_symlog.yml --seeds 10 --seed 0 --out "
    "runs/ppo_symlog": RAY,
    "python -m tether_gym_agents.files export runs/ppo_symlog/seed_K "
    "agents/pretrained/ppo_symlog/seed_K": "K stands for each seed; writes the shipped agents",
    "python train.py --algo ppo --seeds 10 --seed 0 --env-kwargs increment_gain=0.25 --out "
    "runs/ppo_g025": RAY,
    "python -m tether_gym_agents.files export runs/ppo_g025 agents/pretrained/ppo_g025":
        "writes the shipped agents from their full-budget runs",
    "python train.py --config agents/configs/ppo_residual.yml --seeds 5 --seed 0 --out "
    "runs/hybrid": RAY,
    "python -m tether_gym_agents.files export runs/hybrid agents/pretrained/smc_residual":
        "writes the shipped agents from their full-budget runs",
    "python -m tether_gym_agents.files export runs/distill_ppo agents/pretrained/distill_ppo":
        "writes the shipped agents from their full-budget runs (experiments/issue36/"
        "distill_row.sh, which needs the shared mpc dataset)",
    "python train.py --algo sac --config configs/sac_residual.yml --seed K --out "
    "runs/sac_residual/seed_K": "K stands for each seed 0 ... 4 of the shipped agents (about "
        "12 min each; tests/agents/training/test_shipped_commands.py resolves them)",
    "python -m tether_gym_agents.files export runs/sac_residual agents/pretrained/sac_residual":
        "writes the shipped agents from their full-budget runs",
    "python train.py --algo ppo --seeds 10 --out runs/ppo": RAY,
    "python train.py --algo ppo --seeds 10 --out /shared/runs/ppo --ray-address auto":
        "needs a Ray cluster and shared storage",
    "python train.py --algo ppo --sweep sweep.yml --out runs/sweep":
        "a sweep on Ray Tune (tests/agents/training cover sweeps)",
    "python evaluate.py dataset mpc smc_filtered --episodes 20":
        "minutes of mpc episodes; tests/agents/evaluation/test_minari_datasets.py builds, "
        "loads and replays short datasets through the same command",
    "python -m tether_gym_agents.files convert runs/old_run --allow-pickle":
        "runs/old_run stands for a pickled run folder of one's own",
}

SUITE_FILE = """scenarios:
  - name: ecc_0.5
    description: random initial libration, e = 0.5
    env_kwargs: {eccentricity: 0.5, initial_theta: [0.0, 0.0], init_theta_range: 0.15}
  - name: mismatch
    env_kwargs: {masses: [1.2, 1.6]}
    nominal: {masses: [1.0, 2.0], eccentricity: 0.2}
"""
"""``my_suite.yml``: the example of ``tether_gym_agents.evaluation.scenarios``."""


def _code_lines(text: str) -> list[str]:
    """Lines of the README's fenced and indented code blocks."""
    lines, fenced = [], False
    for line in text.splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif fenced or line.startswith("    "):
            lines.append(line)
    return lines


def readme_commands(text: str) -> list[str]:
    """The README's train/evaluate/files commands, comments removed, in order, once each."""
    found: list[str] = []
    for line in _code_lines(text):
        for segment in line.split("&&"):
            if not segment.strip().startswith(tuple(" ".join(p) for p in PREFIXES)):
                continue
            tokens = shlex.split(segment, comments=True)
            if any(tuple(tokens[:len(p)]) == p for p in PREFIXES):
                command = shlex.join(tokens)
                if command not in found:
                    found.append(command)
    return found


def test_every_readme_command_is_listed():
    found = readme_commands(README.read_text())
    assert set(found) == set(COMMANDS), (
        f"in the README, not listed: {sorted(set(found) - set(COMMANDS))}; listed, not in "
        f"the README: {sorted(set(COMMANDS) - set(found))}")


def _run(tokens: list[str]) -> tuple[int, str]:
    from tether_gym_agents.cli.evaluate import main as evaluate_main
    from tether_gym_agents.cli.train import main as train_main
    from tether_gym_agents.files.cli import main as files_main

    if tokens[1] == "train.py":
        main, argv = train_main, tokens[2:]
    elif tokens[1] == "evaluate.py":
        main, argv = evaluate_main, tokens[2:]
    else:
        main, argv = files_main, tokens[3:]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(argv)
    return int(code or 0), buf.getvalue()


def test_the_cheap_readme_commands_run_as_printed(tmp_path, monkeypatch):
    """Each runs with its tiny budget, in the list's order, from a clone-like folder."""
    (tmp_path / "agents").mkdir()
    (tmp_path / "agents" / "configs").symlink_to(ROOT / "agents" / "configs")
    (tmp_path / "configs").symlink_to(ROOT / "agents" / "configs")
    (tmp_path / "my_suite.yml").write_text(SUITE_FILE)
    monkeypatch.chdir(tmp_path)
    printed = {}
    for command, extra in COMMANDS.items():   # the list's order: train before evaluate
        if isinstance(extra, str):
            continue
        code, out = _run([*shlex.split(command), *extra])
        assert code == 0, f"{command} exited with {code}:\n{out[-2000:]}"
        printed[command] = out
    assert (tmp_path / "runs" / "eval" / "results.json").is_file()
    assert (tmp_path / "shipped" / "ppo" / "agent.json").is_file()
    # the README's evaluate line for runs/n4 is the one train.py printed for it
    n4 = next(out for cmd, out in printed.items() if "--out runs/n4" in cmd)
    assert re.findall(r"`(python evaluate\.py [^`]*)`", n4) == ["python evaluate.py smc runs/n4"]
    # and the README's comment on the runs/ppo evaluation quotes what train.py printed
    ppo = printed["python train.py --algo ppo --timesteps 20000 --out runs/ppo"]
    (suggested,) = re.findall(r"`(python evaluate\.py [^`]*)`", ppo)
    line = next(x for x in README.read_text().splitlines()
                if x.startswith("python evaluate.py smc runs/ppo --suite paper"))
    assert f"train.py's last line suggests `{suggested}`" in line


@pytest.mark.parametrize("text", ["```bash\npython evaluate.py smc runs/x   # note\n```\n",
                                  "    python evaluate.py smc runs/x\n"])
def test_commands_are_read_from_fenced_and_indented_blocks(text):
    assert readme_commands(text + "prose: python evaluate.py ppo\n") == [
        "python evaluate.py smc runs/x"]


def test_the_safety_filter_wrapper_example_runs(capsys):
    readme = README.read_text()
    section = readme[readme.index("**Safety filter as a wrapper.**"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    exec(compile(code, "README.md", "exec"), {"__name__": "readme_example"})
    active, correction, feasible = capsys.readouterr().out.split()
    assert active in ("True", "False") and float(correction) >= 0.0
    assert feasible in ("True", "False")


def test_the_trained_agent_example_runs_an_episode():
    readme = README.read_text()
    section = readme[readme.index("**Use a trained agent in your own code.**"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    assert "from tether_gym_agents.files.trained import PRETRAINED_DIR, TrainedAgent" in code
    scope: dict = {"__name__": "readme_example"}
    exec(compile(code, "README.md", "exec"), scope)
    assert scope["done"] and scope["agent"].algo == "ppo"
    assert scope["env"].observation_space.contains(scope["obs"])
