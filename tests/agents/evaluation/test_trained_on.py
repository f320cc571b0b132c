"""An agent is evaluated on the env it was trained on, beside the baselines (issue 24).

A tiny 4-body agent is trained in-process; the evaluate command train.py prints runs as
printed, every scenario of the default suite is defined for its N, and an agent that
cannot run on the requested N is a clear error naming it and its N.
"""

from __future__ import annotations

import contextlib
import io
import json
import re
import shlex
from types import SimpleNamespace

import pytest

from tether_gym_agents.cli.evaluate import main as evaluate_main
from tether_gym_agents.cli.train import main as train_main
from tether_gym_agents.evaluation.registry import ALONE, PolicySpec, trained_on
from tether_gym_agents.files import pretrained_agents

TINY_EVAL = ["--seeds", "1", "--no-plots"]
SHORT = "orbits_per_episode=0.2"
"""Tiny budget: a fifth of an orbit per episode (no env argument an agent records)."""


def _spec(name: str, **env_kwargs) -> PolicySpec:
    """A trained agent's spec whose one run recorded ``env_kwargs`` (nothing loaded)."""
    agent = SimpleNamespace(env_kwargs=env_kwargs, path=name, hybrid=None)
    return PolicySpec(name, ALONE.kind, [name], form=ALONE, agents=[agent])


def test_trained_on_is_what_the_agents_share():
    assert trained_on([]) == {}
    assert trained_on([_spec("a"), _spec("b", n_bodies=3)]) == {}   # 3 is the default
    assert trained_on([_spec("a", n_bodies=4, amplitude=0.3, eccentricity=0.3)]) == {
        "n_bodies": 4, "amplitude": 0.3}                           # e is the scenario's
    # --env-kwargs win over what the agents recorded
    assert trained_on([_spec("a", amplitude=0.3)], {"amplitude": 0.1}) == {}


def test_agents_trained_on_different_tasks_need_a_choice():
    with pytest.raises(ValueError, match=r"different amplitude: 'a' 0.3, 'b' the default"):
        trained_on([_spec("a", amplitude=0.3), _spec("b")])
    assert trained_on([_spec("a", amplitude=0.3), _spec("b")], {"amplitude": 0.2}) == {}
    with pytest.raises(ValueError, match=r"different n_bodies: 'a' 4, 'b' 3"):
        trained_on([_spec("a", n_bodies=4), _spec("b")])


def test_an_agent_on_another_n_is_an_error_naming_it_and_its_n():
    with pytest.raises(ValueError, match=r"policy 'p' was trained on n_bodies=3 \(2 tethers\) "
                                         r"and cannot run on n_bodies=4"):
        trained_on([_spec("p")], {"n_bodies": 4})


@pytest.fixture(scope="module")
def n4_run(tmp_path_factory):
    """A 64-step PPO agent trained as the issue did: --env-kwargs n_bodies=4 eccentricity=0.3."""
    out = tmp_path_factory.mktemp("variant") / "runs" / "n4"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = train_main(["--timesteps", "64", "--n-envs", "1", "--eval-episodes", "1",
                           "--no-progress", "--env-kwargs", "n_bodies=4", "eccentricity=0.3",
                           "--out", str(out)])
    assert code in (0, None)
    return out, buf.getvalue()


def test_the_printed_evaluate_command_runs_as_printed(n4_run, tmp_path):
    out, printed = n4_run
    commands = re.findall(r"`(python evaluate\.py [^`]*)`", printed)
    assert len(commands) == 1, printed
    argv = shlex.split(commands[0])[2:]
    assert argv[-1] == str(out)
    code = evaluate_main([*argv, *TINY_EVAL, "--env-kwargs", SHORT, "--out", str(tmp_path)])
    assert code == 0
    res = json.loads((tmp_path / "results.json").read_text())
    assert set(res["policies"]) == {"smc", str(out)}
    for name, block in res["scenarios"].items():       # every scenario on its 4 bodies
        assert block["env_kwargs"]["n_bodies"] == 4, name
    mismatch = res["scenarios"]["mismatch"]
    assert len(mismatch["env_kwargs"]["masses"]) == len(mismatch["nominal"]["masses"]) == 3


def test_a_variant_agent_with_masses_beside_the_baselines(n4_run, tmp_path):
    """The issue's second and third commands: n_bodies=4, then with masses=(1,1,1)."""
    out, _ = n4_run
    for extra in (["n_bodies=4"], ["n_bodies=4", "masses=(1,1,1)"]):
        code = evaluate_main(["smc", "smc_filtered", str(out), "--env-kwargs", *extra,
                              SHORT, *TINY_EVAL, "--out", str(tmp_path)])
        assert code == 0, extra
        res = json.loads((tmp_path / "results.json").read_text())
        assert len(res["scenarios"]["mismatch"]["nominal"]["masses"]) == 3


def test_a_three_body_agent_beside_a_four_body_one_is_a_clear_error(n4_run, tmp_path, capsys):
    if "ppo" not in pretrained_agents():
        pytest.skip("no shipped PPO agent")
    out, _ = n4_run
    code = evaluate_main(["ppo", str(out), *TINY_EVAL, "--env-kwargs", SHORT,
                          "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2 and "different n_bodies" in err and "'ppo' 3" in err
    assert "Traceback" not in err
