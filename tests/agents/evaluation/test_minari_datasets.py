"""``evaluate.py dataset``: Minari datasets that load, recreate their env and replay exactly."""

from __future__ import annotations

import numpy as np
import pytest

from tether_gym_agents.cli.evaluate import main
from tether_gym_agents.evaluation.datasets import INFO_KEYS, content_checksum
from tether_gym_agents.evaluation.registry import make_policy

minari = pytest.importorskip("minari")
pytest.importorskip("h5py")

SHORT = ["--env-kwargs", "orbits_per_episode=0.05", "mass_range=0.25", "obs_noise=0.001",
         "eccentricity_range=(0.0,0.35)"]


@pytest.fixture
def root(tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    return tmp_path / "minari"


def _checksum_printed(out: str, dataset_id: str) -> str:
    line = next(s for s in out.splitlines() if s.startswith(f"{dataset_id}: "))
    return line.split("content sha256 ")[1].split(",")[0]


def test_a_dataset_loads_recreates_its_env_and_replays(root, capsys):
    assert main(["dataset", "smc_filtered", "--episodes", "2", "--seed", "5", *SHORT]) == 0
    out = capsys.readouterr().out
    dataset_id = "tether_gym/libration/smc_filtered-v0"
    assert "episode 2/2 (env seed 6)" in out
    dataset = minari.load_dataset(dataset_id)
    assert dataset.total_episodes == 2
    assert dataset.storage.metadata["algorithm_name"] == "smc_filtered"
    assert content_checksum(dataset.iterate_episodes()) == _checksum_printed(out, dataset_id)
    env = dataset.recover_environment()  # from the recorded spec: id and every kwarg
    assert env.spec.kwargs["action_mode"] == "rate" and env.spec.kwargs["mass_range"] == 0.25
    policy = make_policy("smc_filtered", env)
    for k, episode in enumerate(dataset.iterate_episodes()):
        steps = len(episode.rewards)
        assert episode.observations.shape == (steps + 1, env.observation_space.shape[0])
        assert episode.actions.shape == (steps, 2) and steps > 5
        for key in INFO_KEYS:
            assert len(episode.infos[key]) == steps + 1
        obs, info = env.reset(seed=5 + k)
        np.testing.assert_array_equal(obs, episode.observations[0])
        for t in range(steps):
            action, _ = policy.predict(obs, episode_start=np.array([t == 0]))
            np.testing.assert_array_equal(np.float32(action), episode.actions[t])
            obs, reward, terminated, truncated, info = env.step(episode.actions[t])
            np.testing.assert_array_equal(obs, episode.observations[t + 1])
            assert reward == episode.rewards[t] and info["cost"] == episode.infos["cost"][t + 1]
            assert (terminated, truncated) == (episode.terminations[t], episode.truncations[t])
        assert episode.truncations[-1] or episode.terminations[-1]


def test_the_checksum_is_the_content(root, capsys):
    args = ["dataset", "smc_filtered", "--episodes", "1", *SHORT]
    assert main([*args, "--dataset-id", "tether_gym/libration/a-v0"]) == 0
    assert main([*args, "--dataset-id", "tether_gym/libration/b-v0"]) == 0
    assert main([*args, "--seed", "1", "--dataset-id", "tether_gym/libration/c-v0"]) == 0
    out = capsys.readouterr().out
    a, b, c = (_checksum_printed(out, f"tether_gym/libration/{x}-v0") for x in "abc")
    assert a == b != c


def test_mpc_demonstrations(root, capsys):
    pytest.importorskip("casadi")
    assert main(["dataset", "mpc", "--episodes", "1", "--env-kwargs",
                 "orbits_per_episode=0.02"]) == 0
    episode = next(minari.load_dataset("tether_gym/libration/mpc-v0").iterate_episodes())
    assert len(episode.rewards) >= 4 and np.all(np.abs(episode.actions) <= 1.0)
    assert not episode.terminations.any()


@pytest.mark.parametrize("args, message", [
    (["smc", "--episodes", "0"], "episodes 0 must be in [1, 100000]"),
    # the bound below 2**31 - 1 says why
    (["smc", "--seed", "-5"], "seed -5 must be in [0, 2147383647] (episode k resets with "
                              "seed + k, and every env seed stays below 2**31 for up to "
                              "100000 episodes)"),
    (["nope"], "unknown policy 'nope'"),
    (["smc", "zero", "--dataset-id", "tether_gym/libration/x-v0"],
     "--dataset-id 'tether_gym/libration/x-v0' names one dataset; 2 policies given"),
    (["smc", "--dataset-id", "x"], "dataset id 'x' must look like"),
    (["smc", "--env-kwargs", "bogus=1"], "unknown argument(s) 'bogus'"),
])
def test_bad_requests_are_one_line_before_any_episode(root, capsys, args, message):
    assert main(["dataset", *args]) == 2
    captured = capsys.readouterr()
    assert message in captured.err and "episode" not in captured.out
    assert not root.exists() or not any(root.rglob("*.hdf5"))


def test_an_existing_dataset_is_not_overwritten(root, capsys):
    args = ["dataset", "zero", "--episodes", "1", *SHORT]
    assert main(args) == 0
    assert main(args) == 2
    assert "exists at" in capsys.readouterr().err
