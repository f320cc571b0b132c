"""Hostile agent files, round two (issue 33): weights that are not float32/float64 or not
finite, normalisation statistics that divide by zero or are out of scale, a NaN
``log_std_init``, a malformed ``weights`` entry and an invalid action box are each one
AgentLoadError naming the file and the key (or tensor), through ``TrainedAgent.load`` and
``evaluate.py``; before, they loaded (int8 weights acted [0, 0]) or raised KeyError /
gymnasium's ValueError without the file's name."""

from __future__ import annotations

import json
import re
import shutil

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym_agents.cli.evaluate import main as evaluate_main
from tether_gym_agents.common.jsonio import sha256_file
from tether_gym_agents.files.safe_format import (
    AGENT_FILE,
    WEIGHTS_FILE,
    AgentLoadError,
    ObsNormalization,
    save_agent,
)
from tether_gym_agents.files.trained import TrainedAgent


@pytest.fixture(scope="module")
def unit(tmp_path_factory):
    """A tiny PPO agent folder with normalisation statistics."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.running_mean_std import RunningMeanStd

    env = gym.make(tether_gym.ENV_ID, orbits_per_episode=0.05)
    model = PPO("MlpPolicy", env, n_steps=64, seed=0, device="cpu",
                policy_kwargs={"net_arch": [8, 8]})
    rms = RunningMeanStd(shape=env.observation_space.shape)
    rms.update(np.random.default_rng(0).normal(size=(20, *env.observation_space.shape)))
    folder = tmp_path_factory.mktemp("agent") / "unit"
    save_agent(folder, model.policy, "ppo", ObsNormalization.of_stats(rms, 10.0),
               env_id=tether_gym.ENV_ID, env_kwargs={})
    return folder


def _edited(unit, tmp_path, meta_edit=None, weights_edit=None):
    run = tmp_path / "agent"
    shutil.copytree(unit, run)
    meta = json.loads((run / AGENT_FILE).read_text())
    if weights_edit is not None:
        import safetensors.torch

        state = safetensors.torch.load_file(str(run / WEIGHTS_FILE))
        safetensors.torch.save_file(weights_edit(state), str(run / WEIGHTS_FILE))
        meta["weights"]["sha256"] = sha256_file(run / WEIGHTS_FILE)  # a consistent forgery
    if meta_edit is not None:
        meta_edit(meta)
    (run / AGENT_FILE).write_text(json.dumps(meta))
    return run


def _cast(dtype_name):
    def edit(state):
        import torch

        return {k: v.to(getattr(torch, dtype_name)) for k, v in state.items()}
    return edit


def _poison(value):
    def edit(state):
        name = "action_net.weight"
        state[name] = state[name].clone()
        state[name][1, 3] = value
        return state
    return edit


@pytest.mark.parametrize("dtype", ["int8", "bool", "float16", "bfloat16", "int64"])
def test_weights_of_another_dtype_are_refused_not_cast(unit, tmp_path, dtype):
    """Before: cast on load (the int8 agent acted [0, 0], the bool one [1, 1])."""
    run = _edited(unit, tmp_path, weights_edit=_cast(dtype))
    with pytest.raises(AgentLoadError) as info:
        TrainedAgent.load(run)
    message = str(info.value)
    assert str(run / WEIGHTS_FILE) in message and f"dtype {dtype}" in message, message
    assert "['float32', 'float64']" in message


@pytest.mark.parametrize("value", [float("nan"), float("inf"), float("-inf")])
def test_non_finite_weights_are_refused_naming_file_and_tensor(unit, tmp_path, value):
    """Before: loaded; acting failed later with "actions must be finite", no file named."""
    run = _edited(unit, tmp_path, weights_edit=_poison(value))
    with pytest.raises(AgentLoadError) as info:
        TrainedAgent.load(run)
    assert re.search(rf"{re.escape(str(run / WEIGHTS_FILE))}: tensor 'action_net.weight'"
                     rf"\[1, 3\] = {value}; allowed: finite numbers", str(info.value)), info.value


def test_float64_weights_load_and_act(unit, tmp_path):
    """The dtype bound refuses nothing save_agent writes (a double policy's float64)."""
    agent = TrainedAgent.load(_edited(unit, tmp_path, weights_edit=_cast("float64")))
    assert np.isfinite(agent.predict(np.zeros(agent.observation_space.shape))[0]).all()


def _set(*keys, value):
    def edit(meta):
        target = meta
        for key in keys[:-1]:
            target = target[key]
        target[keys[-1]] = value
    return edit


def _zero_var_and_epsilon(meta):
    meta["obs_normalization"]["epsilon"] = 0
    meta["obs_normalization"]["var"][4] = 0.0


def _weights_extra(meta):
    meta["weights"]["note"] = "x"


def _weights_extra_no_module(meta):
    del meta["weights"]["module"]
    meta["weights"]["modul"] = "policy"


BAD = {
    "var 0 epsilon 0": (_zero_var_and_epsilon,
                        r"obs_normalization.var\[4\]=0.0 with epsilon=0 divides by zero; "
                        r"allowed: var \+ epsilon > 0"),
    "log_std_init nan": (_set("policy_kwargs", "log_std_init", value=float("nan")),
                         r"policy_kwargs.log_std_init=nan; allowed: a finite number in "
                         r"\[-20, 20\]"),
    "log_std_init 1e3": (_set("policy_kwargs", "log_std_init", value=1000.0),
                         r"policy_kwargs.log_std_init=1000.0"),
    "mean 1e308": (_set("obs_normalization", "mean", 0, value=1e308),
                   r"obs_normalization.mean\[0\]=1e\+308; allowed: finite numbers with "
                   r"\|mean\| <= 1e\+06"),
    "var 1e300": (_set("obs_normalization", "var", 1, value=1e300),
                  r"obs_normalization.var\[1\]=1e\+300; allowed: finite numbers >= 0 "
                  r"and <= 1e\+12"),
    "algo list": (_set("algo", value=["ppo"]),
                  r"algo: algorithm \['ppo'\] must be a string, one of "
                  r"\['ppo', 'ppo_lag', 'sac', "),
    "weights extra key": (_weights_extra,
                          r"weights=.*allowed: a mapping of exactly \['file', 'module', "
                          r"'sha256'\] \(unknown: \['note'\], missing: \[\]\)"),
    "weights key misspelt": (_weights_extra_no_module,
                             r"unknown: \['modul'\], missing: \['module'\]"),
    "box low > high": (_set("action_space", "low", value=[2.0, -1.0]),
                       r"action_space.low\[0\]=2.0 > action_space.high\[0\]=1.0; allowed: "
                       r"low <= high"),
    "box nan": (_set("action_space", "high", value=[1.0, "nan"]),
                r"action_space.high\[1\]='nan'; allowed: a number, 'inf' or '-inf'"),
    "box shape": (_set("action_space", "low", value=[-1.0, -1.0, -1.0]),
                  r"action_space.low=\[-1.0, -1.0, -1.0\]; allowed: a list of 2 numbers"),
    "obs box null": (_set("observation_space", "high", value=None),
                     r"observation_space.high=None"),
    # before: numpy's "cannot reshape array of size 1 into shape (20,)", after the weights
    "mean short": (_set("obs_normalization", "mean", value=[0.0]),
                   r"obs_normalization.mean has 1 entries; allowed: \d+ \(one per entry of "
                   r"shape \[\d+\]\)"),
    "var long": (lambda meta: meta["obs_normalization"]["var"].append(1.0),
                 r"obs_normalization.var has \d+ entries; allowed: \d+ "),
}


@pytest.mark.parametrize("case", list(BAD))
def test_each_bad_value_is_one_error_naming_file_and_key(unit, tmp_path, case):
    edit, message = BAD[case]
    run = _edited(unit, tmp_path, meta_edit=edit)
    with pytest.raises(AgentLoadError) as info:
        TrainedAgent.load(run)
    assert str(run / AGENT_FILE) in str(info.value), info.value
    assert re.search(message, str(info.value)), info.value


@pytest.mark.parametrize("case", ["box low > high", "weights key misspelt"])
def test_evaluate_names_the_file(unit, tmp_path, capsys, case):
    """Before: evaluate.py exited 2 with gymnasium's Box message and no file (low > high),
    or a KeyError traceback ('module')."""
    edit, message = BAD[case]
    run = _edited(unit, tmp_path, meta_edit=edit)
    assert evaluate_main([str(run), "--seeds", "1", "--out", str(tmp_path / "ev")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert str(run / AGENT_FILE) in err and re.search(message, err), err


def test_values_in_bounds_still_load(unit, tmp_path):
    """A zero variance with epsilon > 0, infinite observation bounds: as train.py writes."""
    def edit(meta):
        meta["obs_normalization"]["var"][0] = 0.0
        n = len(meta["observation_space"]["low"])
        meta["observation_space"]["low"] = ["-inf"] * n
        meta["observation_space"]["high"] = ["inf"] * n
    agent = TrainedAgent.load(_edited(unit, tmp_path, meta_edit=edit))
    assert np.isfinite(agent.predict(np.zeros(agent.observation_space.shape))[0]).all()


@pytest.mark.parametrize("kwargs, match", [
    ("abc", r"policy_kwargs must be a mapping, got 'abc'"),
    ({"activation_fn": "os.system"}, r"activation_fn 'os.system' is not one of"),
])
def test_bad_policy_kwargs_name_the_agent_file(unit, tmp_path, capsys, kwargs, match):
    """Before: the sweep's agent.activation.code / agent.type.policy_kwargs were refused
    without naming agent.json; now the file leads the one line."""
    def edit(meta):
        meta["policy_kwargs"] = kwargs

    run = _edited(unit, tmp_path, meta_edit=edit)
    with pytest.raises(AgentLoadError, match=re.escape(str(run / AGENT_FILE)) + ": " + match):
        TrainedAgent.load(run)
    assert evaluate_main([str(run), "--suite", "paper", "--seeds", "1", "--no-plots",
                          "--out", str(tmp_path / "ev")]) == 2
    assert f"{run / AGENT_FILE}: " in capsys.readouterr().err


def test_saving_replaces_links_planted_at_its_temporary_names(tmp_path):
    """Before: save_agent wrote agent.json.tmp and policy.safetensors.tmp at fixed names,
    through any symlink planted there (the file it led to was overwritten)."""
    from stable_baselines3 import PPO

    env = gym.make(tether_gym.ENV_ID, orbits_per_episode=0.05)
    model = PPO("MlpPolicy", env, n_steps=64, seed=0, device="cpu",
                policy_kwargs={"net_arch": [8, 8]})
    precious = tmp_path / "precious.txt"
    precious.write_text("keep")
    folder = tmp_path / "agent"
    folder.mkdir()
    for name in (AGENT_FILE + ".tmp", WEIGHTS_FILE + ".tmp", AGENT_FILE, WEIGHTS_FILE):
        (folder / name).symlink_to(precious)
    save_agent(folder, model.policy, "ppo", None, env_id=tether_gym.ENV_ID, env_kwargs={})
    assert precious.read_text() == "keep"
    assert not (folder / AGENT_FILE).is_symlink() and not (folder / WEIGHTS_FILE).is_symlink()
    agent = TrainedAgent.load(folder)
    assert np.isfinite(agent.predict(np.zeros(agent.observation_space.shape))[0]).all()
