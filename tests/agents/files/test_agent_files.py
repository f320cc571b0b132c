"""Agent files: never run code on load, complete units, exact round trips."""

from __future__ import annotations

import base64
import json
import os
import pickle
import zipfile

import gymnasium as gym
import numpy as np
import pytest
import torch
import yaml

import tether_gym
from tether_gym_agents.cli.evaluate import main as evaluate_main
from tether_gym_agents.files.cli import main as agent_files_main
from tether_gym_agents.files.safe_format import (
    AGENT_FILE,
    WEIGHTS_FILE,
    AgentLoadError,
    ObsNormalization,
    save_agent,
)
from tether_gym_agents.files.trained import TrainedAgent


class _Evil:
    """Unpickling this runs a shell command that writes the marker file."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def _sb3_model(algo="ppo"):
    from stable_baselines3 import PPO, SAC

    env = gym.make(tether_gym.ENV_ID, orbits_per_episode=0.05)
    cls = {"ppo": PPO, "sac": SAC}[algo]
    kwargs = {"n_steps": 64} if algo == "ppo" else {"buffer_size": 100}
    return cls("MlpPolicy", env, seed=0, device="cpu", policy_kwargs={"net_arch": [8, 8]},
               **kwargs)


def _crafted_run(tmp_path, marker, evil_zip=True, evil_pkl=True):
    """A run folder as train.py wrote it before the safe format, with poisoned pickles."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.yml").write_text(yaml.safe_dump({
        "algo": "ppo", "env_id": tether_gym.ENV_ID, "env_kwargs": {},
        "hyperparams": {"normalize": {"norm_obs": True}}}))
    model = _sb3_model()
    model.save(run / "best_model.zip")
    if evil_zip:  # replace a cloudpickled entry of `data` by the crafted object
        with zipfile.ZipFile(run / "best_model.zip") as zf:
            members = {n: zf.read(n) for n in zf.namelist()}
        data = json.loads(members["data"])
        data["lr_schedule"][":serialized:"] = base64.b64encode(
            pickle.dumps(_Evil(marker))).decode()
        members["data"] = json.dumps(data).encode()
        with zipfile.ZipFile(run / "best_model.zip", "w") as zf:
            for name, blob in members.items():
                zf.writestr(name, blob)
    if evil_pkl:
        (run / "vecnormalize.pkl").write_bytes(pickle.dumps(_Evil(marker)))
    return run


@pytest.mark.parametrize("evil", ["zip", "pkl"])
def test_crafted_pickles_are_refused_and_never_run(tmp_path, evil):
    marker = tmp_path / "PWNED"
    run = _crafted_run(tmp_path, marker, evil_zip=evil == "zip", evil_pkl=evil == "pkl")
    with pytest.raises(AgentLoadError, match="refusing pickled agent files.*allow-pickle"):
        TrainedAgent.load(run)
    with pytest.raises(AgentLoadError, match="refusing pickled"):
        TrainedAgent.load(run / "best_model.zip")
    rc = evaluate_main([str(run), "--suite", "paper", "--seeds", "1", "--no-plots",
                        "--out", str(tmp_path / "ev")])
    assert rc == 2
    assert not marker.exists()
    # the converter refuses too without the explicit opt-in
    assert agent_files_main(["convert", str(run)]) == 2
    assert not marker.exists()
    # the crafted files are real: the explicit opt-in does run them (with a warning)
    with pytest.warns(UserWarning, match="pickle can run any code"):
        try:
            TrainedAgent.load(run, allow_pickle=True)
        except Exception:  # noqa: BLE001 - the poisoned entry may not be a valid object
            pass
    assert marker.exists()


def _roundtrip(tmp_path, algo, obs_rms):
    model = _sb3_model(algo)
    norm = ObsNormalization.of_stats(obs_rms, 5.0, 1e-8) if obs_rms is not None else None
    save_agent(tmp_path / algo, model.policy, algo, norm, env_id=tether_gym.ENV_ID,
               env_kwargs={"masses": (1.0, 2.0)}, training={"seed": 0, "num_timesteps": 0})
    return model, TrainedAgent.load(tmp_path / algo)


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_safe_files_round_trip_to_identical_actions(tmp_path, algo):
    from stable_baselines3.common.running_mean_std import RunningMeanStd

    rms = RunningMeanStd(shape=(20,))
    rng = np.random.default_rng(1)
    rms.update(rng.normal(0.3, 2.0, size=(50, 20)))
    model, agent = _roundtrip(tmp_path, algo, rms)
    obs = rng.normal(0.0, 1.0, size=(64, 20)).astype(np.float32)
    expected = model.predict(np.clip((obs - rms.mean) / np.sqrt(rms.var + 1e-8), -5, 5)
                             .astype(np.float32), deterministic=True)[0]
    # the float64 NumPy forward pass (tether_gym_agents.files.mlp) agrees to float32 rounding,
    # torch's own forward pass bit for bit
    np.testing.assert_allclose(agent.predict(obs)[0], expected, rtol=0, atol=2e-6)
    agent.mlp = None
    assert np.array_equal(agent.predict(obs)[0], expected)
    assert agent.algo == algo and agent.env_kwargs == {"masses": [1.0, 2.0]}
    meta = json.loads((tmp_path / algo / AGENT_FILE).read_text())  # strict JSON
    assert meta["obs_normalization"]["clip_obs"] == 5.0
    assert np.array_equal(np.array(meta["obs_normalization"]["mean"]), rms.mean)
    # the weights file is safetensors (8-byte header length, JSON header, raw bytes):
    # no pickle opcode, no zip archive
    blob = (tmp_path / algo / WEIGHTS_FILE).read_bytes()
    header = json.loads(blob[8:8 + int.from_bytes(blob[:8], "little")])
    module = model.policy if algo == "ppo" else model.policy.actor  # SAC acts with its actor
    assert {k for k in header if k != "__metadata__"} == set(module.state_dict())
    assert not blob.startswith((b"\x80", b"PK"))
    from safetensors.torch import load_file

    assert all(isinstance(v, torch.Tensor) for v in load_file(tmp_path / algo /
                                                                WEIGHTS_FILE).values())


def test_missing_or_modified_pieces_are_named(tmp_path):
    _roundtrip(tmp_path, "ppo", None)
    unit = tmp_path / "ppo"
    meta = json.loads((unit / AGENT_FILE).read_text())
    assert meta["obs_normalization"] is None
    # normalisation statistics must be recorded (null = none), never silently absent
    del meta["obs_normalization"]
    (unit / AGENT_FILE).write_text(json.dumps(meta))
    with pytest.raises(AgentLoadError, match="missing.*obs_normalization"):
        TrainedAgent.load(unit)
    meta["obs_normalization"] = None
    (unit / AGENT_FILE).write_text(json.dumps(meta))
    blob = (unit / WEIGHTS_FILE).read_bytes()
    (unit / WEIGHTS_FILE).write_bytes(blob[: len(blob) // 2])
    with pytest.raises(AgentLoadError, match="SHA-256.*truncated or modified"):
        TrainedAgent.load(unit)
    (unit / WEIGHTS_FILE).unlink()
    with pytest.raises(AgentLoadError, match="weights file policy.safetensors is missing"):
        TrainedAgent.load(unit)
    # a lone weights file is not an agent
    lone = tmp_path / "lone"
    lone.mkdir()
    (lone / WEIGHTS_FILE).write_bytes(blob)
    with pytest.raises(AgentLoadError, match="agent.json is missing"):
        TrainedAgent.load(lone / WEIGHTS_FILE)
    with pytest.raises(AgentLoadError, match="no agent in"):
        TrainedAgent.load(lone)


def test_pickled_unit_needs_its_statistics_and_algorithm(tmp_path):
    run = _crafted_run(tmp_path, tmp_path / "m", evil_zip=False, evil_pkl=False)
    # config.yml says observations were normalised: a missing vecnormalize.pkl is an error
    with pytest.warns(UserWarning), pytest.raises(AgentLoadError,
                                                  match="vecnormalize.pkl are missing"):
        TrainedAgent.load(run, allow_pickle=True)
    (run / "config.yml").unlink()  # a lone zip: the algorithm is not guessed
    with pytest.raises(AgentLoadError, match="config.yml .* is missing"):
        TrainedAgent.load(run / "best_model.zip", allow_pickle=True)


def test_convert_pickled_run(tmp_path):
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    run = _crafted_run(tmp_path, tmp_path / "m", evil_zip=False, evil_pkl=False)
    venv = VecNormalize(DummyVecEnv([lambda: gym.make(tether_gym.ENV_ID)]))
    venv.obs_rms.update(np.random.default_rng(0).normal(size=(20, 20)))
    venv.save(str(run / "vecnormalize.pkl"))
    with pytest.warns(UserWarning):
        legacy = TrainedAgent.load(run, allow_pickle=True)
    with pytest.warns(UserWarning):
        assert agent_files_main(["convert", str(run), "--allow-pickle"]) == 0
    safe = TrainedAgent.load(run)  # the safe files are preferred over the pickles
    assert safe.path == run and (run / AGENT_FILE).is_file()
    obs = np.random.default_rng(2).normal(size=(32, 20)).astype(np.float32)
    assert np.array_equal(safe.predict(obs)[0], legacy.predict(obs)[0])


def test_export_copies_only_the_safe_files(tmp_path):
    """``export`` ships agents without pickles, checkpoints or logs."""
    src = tmp_path / "runs"
    for k in (0, 1):
        run = src / f"seed_{k}"
        _roundtrip(run.parent, "ppo", None)
        (src / "ppo").rename(run)
        for junk in ("best_model.zip", "train.log", "checkpoints/model_100_steps.zip"):
            (run / junk).parent.mkdir(parents=True, exist_ok=True)
            (run / junk).write_text("x")
        (run / "command.txt").write_text("python train.py")
    (src / "learning_curves.png").write_bytes(b"png")
    assert agent_files_main(["export", str(src), str(tmp_path / "ship")]) == 0
    shipped = sorted(str(p.relative_to(tmp_path / "ship")) for p in
                     (tmp_path / "ship").rglob("*") if p.is_file())
    assert shipped == ["learning_curves.png"] + [
        f"seed_{k}/{name}" for k in (0, 1)
        for name in sorted((AGENT_FILE, WEIGHTS_FILE, "command.txt"))]
    assert TrainedAgent.load(tmp_path / "ship" / "seed_1").algo == "ppo"
    (src / "seed_1" / AGENT_FILE).unlink()
    assert agent_files_main(["export", str(src), str(tmp_path / "again")]) == 2


def test_module_command_runs(tmp_path):
    """``python -m tether_gym_agents.files export --help`` is the exporter's command line."""
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-m", "tether_gym_agents.files", "export", "--help"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "seed_K" in proc.stdout, proc.stderr
