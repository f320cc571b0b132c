"""The policy registry: register_policy through evaluate.py, unknown names, bad input."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings

import numpy as np
import pytest

import tether_gym_agents
from tether_gym_agents.baselines.open_loop import PeriodicReel, RandomPolicy, ZeroStateReel
from tether_gym_agents.baselines.smc import SlidingModeController
from tether_gym_agents.cli.evaluate import main
from tether_gym_agents.evaluation import registry
from tether_gym_agents.evaluation.benchmark import EvalOptions, evaluate
from tether_gym_agents.files import pretrained_agents
from tether_gym_agents.hybrids.policies import FilteredPolicy

SHORT = ["--suite", "paper", "--env-kwargs", "orbits_per_episode=0.2", "--seeds", "1"]


@pytest.fixture(autouse=True)
def clean_registry(monkeypatch):
    """Each test registers into a copy of the registry (and loads plugins afresh)."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    monkeypatch.setattr(registry, "_PLUGINS_LOADED", [])


class HoldLengths:
    """A tiny controller of user code: command zero reel rate, record what it saw."""

    def __init__(self, env, log: dict):
        self.width = env.observation_space.shape[0]
        self.log = log
        log.setdefault("action_mode", []).append(env.unwrapped.config.action_mode)

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        obs = np.asarray(obs)
        self.log.setdefault("widths", set()).add(obs.shape[-1])
        return np.zeros((obs.shape[0], 2), dtype=np.float32), None


def test_help_names_exactly_the_built_in_baselines(capsys):
    """The help's list follows BASELINES: a new built-in appears without editing it."""
    with pytest.raises(SystemExit):
        main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert (f"registered policies ({', '.join(registry.BASELINES)}, and those added with "
            "register_policy)") in text


# --------------------------------------------------------------------------- #
# a policy of one's own, scored beside the shipped ones
# --------------------------------------------------------------------------- #
def test_registered_policy_runs_through_evaluate_py(tmp_path, capsys):
    seen: dict = {}
    tether_gym_agents.register_policy(
        "hold", lambda env, scenario: HoldLengths(env, seen), kind="rl",
        env_kwargs={"action_mode": "rate", "observe_params": "eccentricity"})
    code = main(["hold", "smc", *SHORT, "--out", str(tmp_path), "--no-plots"])
    assert code == 0, capsys.readouterr().err
    res = json.loads((tmp_path / "results.json").read_text())
    block = res["policies"]["hold"]
    assert block["kind"] == "rl" and block["n_runs"] == 1 and block["runs"] == [None]
    assert block["env_kwargs"] == {"action_mode": "rate", "observe_params": "eccentricity"}
    assert res["policies"]["smc"]["kind"] == "baseline"
    assert res["meta"]["agents"] == {}  # no agent files to hash
    # the policy's env arguments built its env and the rollout's: e is observed (21
    # entries instead of 20) and the action is a reel rate
    assert set(seen["action_mode"]) == {"rate"}
    assert seen["widths"] == {21}
    assert "hold" in capsys.readouterr().out


def test_registered_policy_through_evaluate_and_per_seed_factories():
    seeds_seen = []

    def factory(env, scenario, seed):
        seeds_seen.append(seed)
        return RandomPolicy(env, seed=seed)

    tether_gym_agents.register_policy("my_random", factory, kind=registry.PolicyKind.HYBRID,
                                      env_kwargs={"action_mode": "rate"}, per_seed=True)
    res = evaluate(["my_random", "random"], "paper", 2, seed=5,
                   env_kwargs={"orbits_per_episode": 0.1}, out=None, log=None)
    assert res["policies"]["my_random"]["kind"] == "hybrid"
    assert {5, 6} <= set(seeds_seen)  # one object per episode, with its seed
    # the same law as the built-in random baseline: the same episodes
    mine = [e for e in res["episodes"] if e["policy"] == "my_random"]
    ref = [e for e in res["episodes"] if e["policy"] == "random"]
    assert [e["reel_effort"] for e in mine] == [e["reel_effort"] for e in ref]


def test_evaluate_takes_options_as_a_record_or_fields():
    with pytest.raises(TypeError, match="outt"):
        evaluate(["smc"], "paper", 1, outt=None)
    with pytest.raises(ValueError, match="torch_threads=0"):
        EvalOptions(torch_threads=0)


# --------------------------------------------------------------------------- #
# unknown names
# --------------------------------------------------------------------------- #
def test_unknown_name_exits_2_listing_the_valid_names(tmp_path, capsys):
    code = main(["no_such_policy", *SHORT, "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2
    line, = err.strip().splitlines()
    assert line.startswith("evaluate.py: error: unknown policy 'no_such_policy'")
    for name in (*registry.BASELINES, *pretrained_agents(), "handover:<agent>", "path"):
        assert name in line, name
    assert not (tmp_path / "results.json").exists()


def test_unknown_name_suggests_a_close_one_and_lists_registered_ones():
    tether_gym_agents.register_policy("hold", lambda env, scenario: HoldLengths(env, {}))
    with pytest.raises(ValueError, match="did you mean 'smc_filtered'") as exc:
        registry.resolve_policy("smc_filterd")
    assert "hold" in str(exc.value)


def test_handover_needs_a_trained_agent():
    tether_gym_agents.register_policy("hold", lambda env, scenario: HoldLengths(env, {}),
                                      kind="rl")
    with pytest.raises(ValueError, match="acts alone.*registered policy"):
        registry.resolve_policy("handover:hold")


# --------------------------------------------------------------------------- #
# no name runs another policy's law (the old if/elif with a catch-all)
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("name, cls", [
    ("smc", SlidingModeController), ("smc_filtered", FilteredPolicy),
    ("zero", ZeroStateReel), ("periodic", PeriodicReel), ("random", RandomPolicy)])
def test_every_baseline_builds_its_own_law(name, cls):
    import gymnasium as gym

    import tether_gym

    env = gym.make(tether_gym.ENV_ID, action_mode="rate")
    assert type(registry.make_policy(name, env)) is cls


def test_a_name_without_a_factory_cannot_run_another_law(monkeypatch):
    # listed as a baseline but never registered: an error, not the periodic law
    monkeypatch.setattr(registry, "BASELINES", (*registry.BASELINES, "new_law"))
    assert "new_law" in registry.default_policies()
    with pytest.raises(ValueError, match="unknown policy 'new_law'"):
        evaluate(registry.default_policies(), "paper", 1, out=None, log=None)
    # an entry needs a callable factory, and a spec needs an entry or an agent form
    with pytest.raises(TypeError, match="factory must be callable"):
        registry.PolicyEntry("new_law", None)
    with pytest.raises(ValueError, match="exactly one of entry"):
        registry.PolicySpec("new_law", registry.PolicyKind.BASELINE, [None])


# --------------------------------------------------------------------------- #
# register_policy checks its input
# --------------------------------------------------------------------------- #
def _factory(env, scenario):
    return HoldLengths(env, {})


@pytest.mark.parametrize("kwargs, error, words", [
    ({"name": ""}, ValueError, "''"),
    ({"name": 3}, ValueError, "3"),
    ({"name": "a:b"}, ValueError, "'a:b'"),
    ({"name": "runs/ppo"}, ValueError, "'runs/ppo'"),
    ({"name": "./mine"}, ValueError, "'./mine'"),
    ({"name": "my law"}, ValueError, "'my law'"),
    ({"name": "smc"}, ValueError, "'smc' is already registered"),
    ({"factory": None}, TypeError, "factory must be callable"),
    ({"factory": "smc"}, TypeError, "'smc'"),
    ({"kind": "expert"}, ValueError, "kind='expert'"),
    ({"kind": 1}, ValueError, "kind=1"),
    ({"env_kwargs": "action_mode=rate"}, TypeError, "'action_mode=rate'"),
    ({"env_kwargs": {"action_mod": "rate"}}, ValueError, "action_mod"),
    ({"per_seed": 1}, TypeError, "per_seed"),
    ({"overwrite": "yes"}, TypeError, "overwrite"),
])
def test_register_policy_rejects_bad_input(kwargs, error, words):
    args = {"name": "mine", "factory": _factory, "kind": "baseline", "env_kwargs": None,
            **kwargs}
    before = dict(registry._REGISTRY)
    with pytest.raises(error, match=words.replace("(", r"\(").replace(".", r"\.")):
        tether_gym_agents.register_policy(**args)
    assert registry._REGISTRY == before


def test_register_policy_overwrite_and_shipped_names():
    entry = tether_gym_agents.register_policy("mine", _factory)
    assert entry.kind is registry.PolicyKind.BASELINE and dict(entry.env_kwargs) == {}
    with pytest.raises(ValueError, match="already registered"):
        tether_gym_agents.register_policy("mine", _factory)
    tether_gym_agents.register_policy("mine", _factory, "rl", overwrite=True)
    assert registry.resolve_policy("mine").kind is registry.PolicyKind.RL
    shipped = list(pretrained_agents())
    if shipped:
        with pytest.raises(ValueError, match="shipped agent"):
            tether_gym_agents.register_policy(shipped[0], _factory)
    with pytest.raises(TypeError):  # read-only: an entry's env arguments cannot drift
        entry.env_kwargs["action_mode"] = "rate"  # type: ignore[index]


# --------------------------------------------------------------------------- #
# plugin packages
# --------------------------------------------------------------------------- #
class _EntryPoint:
    def __init__(self, name, hook):
        self.name, self.value, self._hook = name, f"plugin:{name}", hook

    def load(self):
        if isinstance(self._hook, Exception):
            raise self._hook
        return self._hook


def test_plugins_register_lazily_and_a_broken_one_is_skipped(monkeypatch):
    calls = []

    def register():
        calls.append(1)
        tether_gym_agents.register_policy("plugged", _factory, env_kwargs={"action_mode": "rate"})

    eps = [_EntryPoint("good", register), _EntryPoint("broken", ImportError("no module x"))]
    monkeypatch.setattr(registry.metadata, "entry_points",
                        lambda group: eps if group == registry.ENTRY_POINT_GROUP else [])
    registry.resolve_policy("smc")
    assert calls == []  # not loaded while every name is found
    with pytest.warns(RuntimeWarning, match="'broken'.*no module x"):
        spec = registry.resolve_policy("plugged")
    assert spec.entry is not None and spec.env_kwargs == {"action_mode": "rate"}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        registry.resolve_policy("plugged")
        with pytest.raises(ValueError, match="plugged"):
            registry.resolve_policy("unplugged")
    assert calls == [1]  # loaded once


# --------------------------------------------------------------------------- #
# a light import
# --------------------------------------------------------------------------- #
def test_importing_the_package_loads_neither_torch_nor_sb3():
    code = ("import sys, tether_gym_agents as t; t.register_policy, t.evaluate; "
            "print(sorted(m for m in ('torch', 'stable_baselines3') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


# --------------------------------------------------------------------------- #
# the README's example runs as shown
# --------------------------------------------------------------------------- #
def test_readme_example_runs_as_shown(capsys):
    import re
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[3] / "README.md").read_text()
    section = readme[readme.index("## Evaluate your own controller"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    exec(compile(code, "README.md", "exec"), {"__name__": "readme_example"})
    printed = capsys.readouterr().out.strip().splitlines()
    shown = [line[2:] for line in code.splitlines() if line.startswith("# ") and ":" in line
             and line[2:].split(":")[0] in ("hold", "smc")]
    assert printed == shown and len(shown) == 2


@pytest.mark.parametrize("policy, given, own", [
    # before: ppo (trained in the default increment mode, which its agent.json does not
    # record) ran in the rate mode, its increments read as reel rates
    ("ppo", "action_mode=rate", "action_mode='increment'"),
    ("ppo", "increment_gain=0.25", "increment_gain=0.5"),
    ("smc", "action_mode=increment", "action_mode='rate'"),
    ("distill_ppo", "observe_params=True", "observe_params=False"),
])
def test_an_env_argument_a_policy_replaces_is_refused(tmp_path, capsys, policy, given, own):
    out = tmp_path / "never"
    assert main([policy, "--suite", "paper", "--seeds", "1", "--env-kwargs", given,
                 "--out", str(out), "--no-plots"]) == 2
    err = capsys.readouterr().err
    key = given.split("=")[0]
    assert (f"policy {policy!r} runs with {own} (what its actions and observations mean); "
            f"leave {key} out of --env-kwargs") in err, err
    assert len(err.strip().splitlines()) == 1 and not out.exists()


def test_a_trained_agent_runs_in_the_mode_it_was_trained_in(tmp_path):
    """An argument its agent.json leaves out is the env's default, made explicit."""
    spec = registry.resolve_policy("ppo")
    spec.load()
    assert spec.env_kwargs["action_mode"] == "increment"
    assert dict(spec.env_kwargs) == {"action_mode": "increment", "increment_gain": 0.5,
                                     "observe_params": False}
    # an argument that agrees with the policy's is taken
    assert main(["ppo", "--suite", "paper", "--seeds", "1", "--env-kwargs",
                 "orbits_per_episode=0.2", "action_mode=increment", "--no-plots",
                 "--out", str(tmp_path / "agree")]) == 0
