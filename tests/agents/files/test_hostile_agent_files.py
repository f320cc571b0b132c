"""Hostile agent folders (issue 24): symlinks that lead out of the folder, and recorded
values out of bounds, are errors naming the file and the key before anything is built."""

from __future__ import annotations

import json
import os
import pickle
import shutil

import gymnasium as gym
import numpy as np
import pytest
import yaml

import tether_gym
from tether_gym_agents.files.cli import main as agent_files_main
from tether_gym_agents.files.export import export_runs
from tether_gym_agents.files.safe_format import (
    AGENT_FILE,
    WEIGHTS_FILE,
    AgentLoadError,
    ObsNormalization,
    save_agent,
)
from tether_gym_agents.files.trained import TrainedAgent

SECRET = "root:x:0:0:secret-outside-the-folder\n"


def _agent(folder, net_arch=(8, 8)):
    """A tiny PPO agent folder with normalisation statistics."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.running_mean_std import RunningMeanStd

    env = gym.make(tether_gym.ENV_ID, orbits_per_episode=0.05)
    model = PPO("MlpPolicy", env, n_steps=64, seed=0, device="cpu",
                policy_kwargs={"net_arch": list(net_arch)})
    rms = RunningMeanStd(shape=env.observation_space.shape)
    rms.update(np.random.default_rng(0).normal(size=(20, *env.observation_space.shape)))
    save_agent(folder, model.policy, "ppo", ObsNormalization.of_stats(rms, 10.0),
               env_id=tether_gym.ENV_ID, env_kwargs={})
    return folder


@pytest.fixture(scope="module")
def unit(tmp_path_factory):
    return _agent(tmp_path_factory.mktemp("agent") / "unit")


def _copy(unit, tmp_path, name="run"):
    dest = tmp_path / name
    shutil.copytree(unit, dest)
    return dest


# ------------------------------------------------------------------ symlinks
def test_export_refuses_a_symlink_out_of_the_folder(unit, tmp_path):
    """Before: ``export`` copied /etc/passwd's contents into DST as command.txt."""
    secret = tmp_path / "passwd"
    secret.write_text(SECRET)
    src = _copy(unit, tmp_path, "src")
    (src / "command.txt").symlink_to(secret)
    with pytest.raises(AgentLoadError, match=r"command.txt leads outside"):
        export_runs(src, tmp_path / "dst")
    assert not (tmp_path / "dst").exists()  # everything is checked before anything is copied
    assert agent_files_main(["export", str(src), str(tmp_path / "dst")]) == 2
    assert not any(SECRET in p.read_text() for p in tmp_path.rglob("*")
                   if p.is_file() and p != secret and p.suffix in ("", ".txt")
                   and not p.is_symlink())


def test_export_refuses_links_out_of_every_seed_run_and_special_files(unit, tmp_path):
    secret = tmp_path / "secret.json"
    secret.write_text('{"secret": 1}')
    src = tmp_path / "runs"
    _copy(unit, src, "seed_0")
    (src / "seed_0" / "train_info.json").symlink_to(secret)
    with pytest.raises(AgentLoadError, match=r"seed_0/train_info.json leads outside"):
        export_runs(src, tmp_path / "dst")
    (src / "seed_0" / "train_info.json").unlink()
    os.mkfifo(src / "seed_0" / "command.txt")  # reading it would block forever
    with pytest.raises(AgentLoadError, match=r"command.txt is not a regular file"):
        export_runs(src, tmp_path / "dst")
    (src / "seed_0" / "command.txt").unlink()
    (src / "seed_0" / "command.txt").symlink_to(tmp_path / "gone")
    with pytest.raises(AgentLoadError, match=r"command.txt leads outside"):
        export_runs(src, tmp_path / "dst")


def test_export_follows_links_inside_the_folder_and_never_writes_through_one(unit, tmp_path):
    src = _copy(unit, tmp_path, "src")
    (src / "notes").mkdir()
    (src / "notes" / "cmd").write_text("python train.py\n")
    (src / "command.txt").symlink_to(src / "notes" / "cmd")
    dst = tmp_path / "dst"
    dst.mkdir()
    victim = tmp_path / "victim"
    victim.write_text("keep me")
    (dst / "command.txt").symlink_to(victim)
    export_runs(src, dst)
    assert (dst / "command.txt").read_text() == "python train.py\n"
    assert not (dst / "command.txt").is_symlink() and victim.read_text() == "keep me"
    assert TrainedAgent.load(dst).algo == "ppo"


@pytest.mark.parametrize("name", [WEIGHTS_FILE, AGENT_FILE])
def test_load_refuses_a_file_that_leads_out_of_the_folder(unit, tmp_path, name):
    """Before: ``TrainedAgent.load`` followed a policy.safetensors symlink anywhere."""
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    shutil.copy2(unit / name, outside / name)  # a valid file, only in the wrong place
    run = _copy(unit, tmp_path)
    (run / name).unlink()
    (run / name).symlink_to(outside / name)
    with pytest.raises(AgentLoadError, match=rf"{name} leads outside .*run"):
        TrainedAgent.load(run)


def test_load_follows_a_link_that_stays_inside(unit, tmp_path):
    run = _copy(unit, tmp_path)
    (run / "blobs").mkdir()
    (run / WEIGHTS_FILE).rename(run / "blobs" / "w.safetensors")
    (run / WEIGHTS_FILE).symlink_to("blobs/w.safetensors")
    assert TrainedAgent.load(run).algo == "ppo"


def test_pickled_statistics_outside_the_run_are_not_unpickled(tmp_path):
    """With --allow-pickle too: a vecnormalize.pkl linking out of the run is never read."""
    marker = tmp_path / "PWNED"

    class Evil:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    (tmp_path / "evil.pkl").write_bytes(pickle.dumps(Evil()))
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.yml").write_text(yaml.safe_dump({
        "algo": "ppo", "env_id": tether_gym.ENV_ID, "env_kwargs": {},
        "hyperparams": {"normalize": True}}))
    from stable_baselines3 import PPO

    PPO("MlpPolicy", gym.make(tether_gym.ENV_ID), n_steps=64, device="cpu",
        policy_kwargs={"net_arch": [8]}).save(run / "best_model.zip")
    (run / "vecnormalize.pkl").symlink_to(tmp_path / "evil.pkl")
    with pytest.warns(UserWarning), \
            pytest.raises(AgentLoadError, match="vecnormalize.pkl leads outside"):
        TrainedAgent.load(run, allow_pickle=True)
    assert not marker.exists()


# ------------------------------------------------------------------ values
BAD_VALUES = {
    "var nan": (("obs_normalization", "var", 0), "nan", r"obs_normalization.var\[0\]='nan'"
                r"; allowed: finite numbers >= 0"),
    "var negative": (("obs_normalization", "var", 1), -1.0,
                     r"obs_normalization.var\[1\]=-1.0; allowed: finite numbers >= 0"),
    "mean inf": (("obs_normalization", "mean", 2), "inf",
                 r"obs_normalization.mean\[2\]='inf'; allowed: finite numbers"),
    "mean text": (("obs_normalization", "mean", 0), "abc", r"obs_normalization.mean\[0\]"),
    "clip_obs text": (("obs_normalization", "clip_obs"), "ten",
                      r"obs_normalization.clip_obs='ten'; allowed: a finite number > 0"),
    "clip_obs negative": (("obs_normalization", "clip_obs"), -1,
                          r"obs_normalization.clip_obs=-1; allowed: a finite number > 0"),
    "clip_obs zero": (("obs_normalization", "clip_obs"), 0, r"clip_obs=0"),
    "clip_obs bool": (("obs_normalization", "clip_obs"), True, r"clip_obs=True"),
    "epsilon negative": (("obs_normalization", "epsilon"), -1e-8,
                         r"obs_normalization.epsilon=-1e-08; allowed: a finite number in"),
    "count nan": (("obs_normalization", "count"), float("nan"), r"obs_normalization.count"),
    "net_arch huge": (("policy_kwargs", "net_arch"), [200000, 200000],
                      r"policy_kwargs.net_arch\[0\]=200000; allowed: an integer in 1 .. 4096"),
    "net_arch deep": (("policy_kwargs", "net_arch"), [64] * 9,
                      r"policy_kwargs.net_arch=\[64, .*; allowed: a list of at most 8"),
    "net_arch too many parameters": (("policy_kwargs", "net_arch"), [4096] * 8,
                                     r"parameters .*allowed: at most 20,000,000"),
    "net_arch float": (("policy_kwargs", "net_arch"), [64.5], r"net_arch\[0\]=64.5"),
    "net_arch text": (("policy_kwargs", "net_arch"), "big", r"net_arch='big'"),
    "net_arch zero": (("policy_kwargs", "net_arch"), {"pi": [0], "vf": [8]},
                      r"net_arch.pi\[0\]=0"),
    "net_arch foreign key": (("policy_kwargs", "net_arch"), {"pi": [8], "qf": [8]},
                             r"net_arch names \['qf'\]; allowed for PPO: \['pi', 'vf'\]"),
    "env id": (("env", "id"), "Pendulum-v1",
               r"env.id='Pendulum-v1' is not a tether_gym env; allowed: "
               r"\['tether_gym/TetherLibration-v1', 'tether_gym/TetherLibration-v2'\] or null"),
    "env kwargs": (("env", "kwargs"), "n_bodies=4", r"env.kwargs='n_bodies=4'"),
    "space shape": (("observation_space", "shape"), [10 ** 9],
                    r"observation_space.shape=\[1000000000\] has 1000000000 entries"),
}


def _set(meta, keys, value):
    for key in keys[:-1]:
        meta = meta[key]
    meta[keys[-1]] = value


@pytest.mark.parametrize("case", list(BAD_VALUES))
def test_each_value_out_of_bounds_is_named_before_anything_is_built(unit, tmp_path,
                                                                   monkeypatch, case):
    keys, value, message = BAD_VALUES[case]
    run = _copy(unit, tmp_path)
    meta = json.loads((run / AGENT_FILE).read_text())
    _set(meta, keys, value)
    (run / AGENT_FILE).write_text(json.dumps(meta))  # NaN written as JSON's NaN literal too
    from stable_baselines3.common import policies

    def never(*args, **kwargs):
        raise AssertionError("the policy was built from a value out of bounds")

    monkeypatch.setattr(policies.ActorCriticPolicy, "__init__", never)
    with pytest.raises(AgentLoadError) as info:
        TrainedAgent.load(run)
    assert str(run / AGENT_FILE) in str(info.value)
    assert info.value.args and __import__("re").search(message, str(info.value)), info.value


def test_values_in_bounds_load_and_act(unit, tmp_path):
    """The bounds do not refuse what train.py writes: a 0 variance, wide nets, null id."""
    run = _copy(unit, tmp_path)
    meta = json.loads((run / AGENT_FILE).read_text())
    meta["obs_normalization"]["var"][0] = 0.0
    meta["env"]["id"] = None
    (run / AGENT_FILE).write_text(json.dumps(meta))
    agent = TrainedAgent.load(run)
    assert np.isfinite(agent.predict(np.zeros(agent.observation_space.shape))[0]).all()
    big = _agent(tmp_path / "big", net_arch=(1024, 1024, 1024))
    assert TrainedAgent.load(big).algo == "ppo"


def test_tqc_critics_are_counted_with_their_quantiles():
    """A TQC critic has n_quantiles outputs: 8 [1024, 1024] critics of 256 quantiles build
    8 nets x (critic + target) x 1.3M weights, over the bound; SAC's of one output do not.
    The counts lie in the algorithm's bounds (common.algorithms)."""
    from tether_gym_agents.files.agent_values import ValueProblem, check_net_arch

    check_net_arch("sac", {"net_arch": [1024, 1024], "n_critics": 8}, 12, 2)
    check_net_arch("tqc", {"net_arch": [1024, 1024]}, 12, 2)  # 25 quantiles by default
    with pytest.raises(ValueProblem, match=r"builds about 2[0-9],\d{3},\d{3} parameters"):
        check_net_arch("tqc", {"net_arch": [1024, 1024], "n_quantiles": 256, "n_critics": 8},
                       12, 2)
    with pytest.raises(ValueProblem, match=r"policy_kwargs.n_quantiles=4096; allowed: a "
                                           r"whole number in \[1, 256\]"):
        check_net_arch("tqc", {"net_arch": [64], "n_quantiles": 4096}, 12, 2)
    with pytest.raises(ValueProblem, match=r"policy_kwargs.n_critics='two'"):
        check_net_arch("tqc", {"net_arch": [64], "n_critics": "two"}, 12, 2)
    with pytest.raises(ValueProblem, match=r"policy_kwargs.n_critics=1000000; allowed: a "
                                           r"whole number in \[1, 16\]"):
        check_net_arch("td3", {"net_arch": [64], "n_critics": 1000000}, 12, 2)
