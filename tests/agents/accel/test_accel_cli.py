"""``python train.py gpu`` in-process with a tiny budget on CPU, scored by ``evaluate.py``."""

from __future__ import annotations

import json

import pytest

pytest.importorskip("torch")
pytest.importorskip("stable_baselines3")

from tether_gym_agents.cli.evaluate import main as evaluate_main  # noqa: E402
from tether_gym_agents.cli.train import main as train_main  # noqa: E402
from tether_gym_agents.files.safe_format import load_agent  # noqa: E402


def test_train_gpu_on_cpu_writes_runs_that_evaluate_scores(tmp_path, capsys):
    out = tmp_path / "gpu"
    code = train_main(["gpu", "--seeds", "2", "--n-envs", "4", "--timesteps", "256",
                       "--device", "cpu", "--out", str(out)])
    assert code == 0
    for k in (0, 1):
        run = out / f"seed_{k}"
        policy, meta = load_agent(run)
        assert meta["algo"] == "ppo" and meta["training"]["seed"] == k
        assert meta["obs_normalization"] is not None
        info = json.loads((run / "train_info.json").read_text())
        assert info["num_timesteps"] >= 256 and info["seeds_in_process"] == 2
        assert (run / "checkpoints").is_dir() and any((run / "checkpoints").iterdir())
    # the two seeds are different networks (own initialisation and data)
    w0 = load_agent(out / "seed_0")[0].state_dict()["action_net.weight"]
    w1 = load_agent(out / "seed_1")[0].state_dict()["action_net.weight"]
    assert not (w0 == w1).all()
    assert evaluate_main([str(out), "--seeds", "1", "--out", str(tmp_path / "eval"),
                          "--no-plots"]) == 0
    res = json.loads((tmp_path / "eval" / "results.json").read_text())
    assert res


BLOCK = "tether_gym/TetherLibration-v2:\n  "


@pytest.mark.parametrize("text, message", [
    # the largest value allowed, written in full (before: [1, 4.1943e+06])
    (BLOCK + "n_envs: 0\n", "n_envs=0 must be an integer in [1, 4194304]"),
    (BLOCK + "n_epochs: 1000000000\n", "n_epochs=1000000000 must be an integer in"),
    (BLOCK + "learning_rate: .nan\n", "learning_rate=nan"),
    (BLOCK + "bogus: 1\n", "unknown key"),
    ("n_envs: 8\n", "keyed by the env id"),
    ("a: &x [1]\nb: *x\n", "anchors"),
    ("[", "not readable YAML"),
    # before: TypeError tracebacks from EnvConfig.from_kwargs
    (BLOCK + "env_kwargs: {1: 2}\n", "env_kwargs must be a mapping of argument names"),
    (BLOCK + "env_kwargs: {n_bodies: x}\n", "env_kwargs: n_bodies must be an int, got str"),
    (BLOCK + "env_kwargs: {eccentricity: 1.5}\n", "env_kwargs: eccentricity=1.5"),
])
def test_bad_config_is_one_line_naming_the_file(tmp_path, capsys, text, message):
    cfg = tmp_path / "bad.yml"
    cfg.write_text(text)
    code = train_main(["gpu", "--config", str(cfg), "--device", "cpu",
                       "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and message in err and str(cfg) in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err


def test_cuda_without_a_gpu_is_a_clear_error(tmp_path, capsys):
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU")
    code = train_main(["gpu", "--device", "cuda", "--out", str(tmp_path / "o")])
    assert code == 2 and "pip install" in capsys.readouterr().err


@pytest.mark.parametrize("extra, message", [
    (["--backend", "jax"], "backend='jax' must be one of"),
    (["--backend", "numba-cuda", "--compile"], "needs a CUDA device, got device='cpu'"),
    (["--backend", "numba-cuda"], "needs a CUDA device, got device='cpu'"),
    (["--cuda-graphs"], "--cuda-graphs needs a CUDA device"),
])
def test_bad_backend_is_one_line_before_any_work(tmp_path, capsys, extra, message):
    code = train_main(["gpu", "--device", "cpu", "--out", str(tmp_path / "o"), *extra])
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("case, message", [
    ("a file", "o': is a file; give a folder"),                # --out is a file
    ("seed is a file", "seed_3: is a file; give a folder"),    # --out/seed_3 is a file
    ("seed file is a folder", "train_info.json is a folder"),  # a file the run writes
    ("/proc", "cannot write there"),
])
def test_unwritable_out_is_one_line_before_any_work(tmp_path, capsys, case, message):
    out = tmp_path / "o"
    if case == "a file":
        out.write_text("x")
    elif case == "seed is a file":
        out.mkdir()
        (out / "seed_3").write_text("x")
    elif case == "seed file is a folder":
        (out / "seed_3" / "train_info.json").mkdir(parents=True)
    else:
        out = tmp_path.root + "proc/tether_gym_run"
    code = train_main(["gpu", "--device", "cpu", "--seed", "3", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert err.startswith(f"train.py gpu: error: --out {str(out)!r}: ") and message in err


def test_an_earlier_run_in_out_is_refused_and_left_as_it_was(tmp_path, capsys):
    """No resume here: a second run into a folder with checkpoints would leave them beside
    its own (``evaluate.py curves`` reads both), so it is refused before any work."""
    out = tmp_path / "run"
    tiny = ("--n-envs", "4", "--timesteps", "512")
    first = _trained(out, *tiny)
    before = {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()}
    capsys.readouterr()
    code = train_main(["gpu", "--device", "cpu", "--out", str(out), "--n-envs", "4",
                       "--timesteps", "256"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert (f"{out / 'seed_0'}: already holds an earlier training run (checkpoints/"
            "agent_") in err
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()} == before
    # a seed the earlier call did not train is a new run folder: it trains
    assert _trained(out, *tiny, "--seed", "1", seed=1).keys() == first.keys()
    # so does a call killed before its first checkpoint (its records only)
    for name in ("agent.json", "policy.safetensors"):
        (out / "seed_0" / name).unlink()
    import shutil

    shutil.rmtree(out / "seed_0" / "checkpoints")
    again = _trained(out, *tiny)
    assert all((first[k] == again[k]).all() for k in first)


def test_the_device_scripts_configs_load():
    """The configs bench/gpu_session*.sh train with are valid for today's env id."""
    from pathlib import Path

    from tether_gym_agents.accel.cli import read_config

    root = Path(__file__).resolve().parents[3]
    files = sorted((root / "experiments" / "issue34" / "cfg").glob("*.yml"))
    assert len(files) >= 4
    for f in files:
        settings, steps, env_kwargs, checkpoints = read_config(f)
        assert steps >= settings.n_envs * settings.n_steps and env_kwargs


def _trained(out, *argv, seed=0):
    """A tiny ``train.py gpu`` run on the CPU into ``out``: seed ``seed``'s weights."""
    assert train_main(["gpu", "--device", "cpu", "--out", str(out), *argv]) == 0
    return load_agent(out / f"seed_{seed}")[0].state_dict()


def test_numba_backend_trains_what_the_torch_backend_trains(tmp_path):
    """Same seed and budget: the numba backend's run ends with the torch backend's weights."""
    weights = {}
    for backend in ("torch", "numba"):
        out = tmp_path / backend
        weights[backend] = _trained(out, "--n-envs", "8", "--timesteps", "512",
                                    "--backend", backend)
        info = json.loads((out / "seed_0" / "train_info.json").read_text())
        assert info["num_timesteps"] >= 512 and info["backend"] == backend
    for name, w in weights["torch"].items():  # bitwise equal when written (2026-12-06)
        assert (weights["numba"][name] - w).abs().max() <= 1e-6 * (1.0 + w.abs().max()), name


def test_a_process_of_seeds_reproduces_and_its_seeds_depend_on_the_group(tmp_path):
    """The rule behind the shipped ``ppo_accel`` seeds' ``command.txt`` (docs/gpu.md): the
    same call gives bitwise the same weights for every seed, and a seed trained in a
    group of two is not the seed trained alone (one generator starts the whole group),
    so a seed is retrained by rerunning its group's command."""
    tiny = ("--n-envs", "4", "--timesteps", "256")
    first = _trained(tmp_path / "a", *tiny, "--seeds", "2", "--seed", "0", seed=1)
    again = _trained(tmp_path / "b", *tiny, "--seeds", "2", "--seed", "0", seed=1)
    alone = _trained(tmp_path / "c", *tiny, "--seeds", "1", "--seed", "1", seed=1)
    assert all((first[k] == again[k]).all() for k in first)
    assert not (first["action_net.weight"] == alone["action_net.weight"]).all()


@pytest.mark.parametrize("flag", ["--compile-update", "--compile-rollout"])
def test_compiled_learners_train_what_the_eager_learner_trains(tmp_path, flag):
    """``--compile-update`` (the minibatch steps fused by torch.compile) and
    ``--compile-rollout`` (the rollout's arithmetic fused): same seed and budget, the
    run ends with the eager run's weights to float32 rounding (not bitwise: Inductor
    reorders the arithmetic), in standard agent folders."""
    tiny = ("--n-envs", "8", "--timesteps", "512", "--seeds", "2")
    eager = _trained(tmp_path / "eager", *tiny, seed=1)
    fused = _trained(tmp_path / "fused", *tiny, flag, seed=1)
    for name, w in eager.items():
        assert (fused[name] - w).abs().max() <= 1e-4 * (1.0 + w.abs().max()), name
    assert any(not (fused[k] == eager[k]).all() for k in eager)  # it ran compiled
    assert json.loads((tmp_path / "fused" / "seed_1" / "train_info.json").read_text())[
        "num_timesteps"] >= 512


def test_compile_on_the_numba_backend_trains_bitwise_the_eager_run(tmp_path):
    """``--backend numba --compile`` fuses the env's torch arithmetic around the kernel,
    which is copies, masks and comparisons: the run's weights are the eager run's, bitwise."""
    tiny = ("--n-envs", "8", "--timesteps", "1024", "--backend", "numba")
    eager = _trained(tmp_path / "eager", *tiny)
    fused = _trained(tmp_path / "fused", *tiny, "--compile")
    assert eager.keys() == fused.keys() and all((fused[k] == eager[k]).all() for k in eager)


def test_sync_free_trains_on_both_backends_and_compiles_bitwise(tmp_path):
    """``--sync-free`` (the autoreset without host syncs): the numba backend trains the
    torch backend's weights, as without the flag, and ``--compile`` on the numba backend
    (the failed starts' codes then inside a compiled piece) the eager run's, bitwise; the
    command is recorded with the run."""
    tiny = ("--n-envs", "8", "--timesteps", "1024", "--sync-free")
    torch_run = _trained(tmp_path / "torch", *tiny)
    eager = _trained(tmp_path / "eager", *tiny, "--backend", "numba")
    fused = _trained(tmp_path / "fused", *tiny, "--backend", "numba", "--compile")
    assert all((fused[k] == eager[k]).all() for k in eager)
    for name, w in torch_run.items():
        assert (eager[name] - w).abs().max() <= 1e-6 * (1.0 + w.abs().max()), name
    assert "--sync-free" in (tmp_path / "fused" / "seed_0" / "command.txt").read_text()


@pytest.mark.parametrize("flag", ["--compile", "--compile-update", "--compile-rollout"])
def test_compiling_on_a_cpu_without_a_compiler_is_one_line(tmp_path, capsys, monkeypatch,
                                                          flag):
    """torch.compile's CPU code needs a C++ compiler: without one, a clear error before
    any work (no run folder)."""
    from tether_gym_agents.accel import cli

    monkeypatch.setattr(cli.shutil, "which", lambda name: None)
    out = tmp_path / "o"
    assert train_main(["gpu", "--device", "cpu", flag, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{flag} on the CPU needs a C++ compiler" in err and "g++" in err
    assert len(err.strip().splitlines()) == 1 and not out.exists()


def test_rollout_bytes_counts_what_the_rollout_keeps_per_sample():
    """The memory check's formula against the tensors a Rollout allocates: its (T, S, N)
    buffers and its batch, plus what ``finish`` and the minibatch orders add (2 float32
    temporaries per sample; int64 orders per epoch, stacked from a list: 16 bytes) and
    the minibatch's activations."""
    import torch

    from tether_gym_agents.accel.cli import rollout_bytes
    from tether_gym_agents.accel.ppo import MultiSeedPolicy, PPOSettings
    from tether_gym_agents.accel.rollout import Rollout

    s, d, a = PPOSettings(n_envs=3, n_steps=5, n_epochs=4), 7, 2
    rollout = Rollout(MultiSeedPolicy([0, 1], d, a, s, "cpu"), s, d, a, "cpu")
    samples = 5 * 2 * 3

    def kept(obj, lead):
        return sum(t.nbytes for t in vars(obj).values()
                   if isinstance(t, torch.Tensor) and tuple(t.shape[:len(lead)]) == lead)

    buffers, batch = kept(rollout, (5, 2, 3)), kept(rollout.batch, (2, 15))
    assert buffers == samples * 4 * (d + a + 4) and batch == samples * 4 * (d + a + 3)
    activations = 2 * 15 * 8 * (d + a + 3 * 128)  # minibatches of min(8192, T N) = 15
    assert rollout_bytes(s, 2, d, a) == (buffers + batch + samples * (2 * 4 + 16 * 4)
                                         + activations)


def test_a_rollout_past_the_memory_cap_is_one_line_before_any_work(tmp_path, capsys):
    cfg = tmp_path / "big.yml"
    cfg.write_text(BLOCK + "n_envs: 65536\n  n_steps: 4096\n")
    code = train_main(["gpu", "--config", str(cfg), "--device", "cpu", "--out",
                       str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "65536 x 4096 x 1 samples per rollout with n_epochs=10 would keep 93.0 GiB" in err
    assert "at most 32 GiB" in err and not (tmp_path / "o").exists()
