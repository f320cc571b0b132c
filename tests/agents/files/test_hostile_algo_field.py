"""agent.json's ``algo`` and ``policy_class`` are read through the algorithm table: a value
that is not a row (a list, an unknown name, the wrong case, a class of another row) is an
error naming the file and the allowed values, before anything is built."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from tether_gym_agents.cli.evaluate import main as evaluate_main
from tether_gym_agents.files.safe_format import AGENT_FILE, AgentLoadError
from tether_gym_agents.files.trained import TrainedAgent

SHIPPED = Path(__file__).resolve().parents[3] / "agents" / "pretrained" / "ppo" / "seed_0"


def _edited(tmp_path, **changes) -> Path:
    folder = tmp_path / "agent"
    shutil.copytree(SHIPPED, folder)
    meta = json.loads((folder / AGENT_FILE).read_text())
    meta.update(changes)
    (folder / AGENT_FILE).write_text(json.dumps(meta))
    return folder


@pytest.mark.parametrize("changes, message", [
    ({"algo": ["ppo"]}, "algo: algorithm ['ppo'] must be a string, one of "
                        "['ppo', 'ppo_lag', 'sac', 'td3', 'tqc']"),
    ({"algo": None}, "algo: algorithm None must be a string"),
    ({"algo": "dqn"},
     "algo: algorithm 'dqn' is not one of ['ppo', 'ppo_lag', 'sac', 'td3', 'tqc']"),
    ({"algo": "PPO"}, "algo='PPO'; allowed: ['ppo', 'ppo_lag', 'sac', 'td3', 'tqc'] (lower case)"),
    ({"algo": "td3"}, "policy_class='ActorCriticPolicy' does not fit algo 'td3'; allowed: "
                      "'TD3Policy'"),
    ({"policy_class": "SACPolicy"}, "policy_class='SACPolicy' does not fit algo 'ppo'"),
    ({"policy_class": {"x": 1}}, "policy_class={'x': 1} does not fit algo 'ppo'"),
])
def test_algo_and_policy_class_outside_the_table(tmp_path, changes, message):
    folder = _edited(tmp_path, **changes)
    with pytest.raises(AgentLoadError) as exc:
        TrainedAgent.load(folder)
    assert str(folder / AGENT_FILE) in str(exc.value) and message in str(exc.value)


def test_evaluate_py_names_the_file_for_a_list_algo(tmp_path, capsys):
    folder = _edited(tmp_path, algo=["ppo"])
    assert evaluate_main([str(folder), "--suite", "paper", "--seeds", "1", "--no-plots",
                          "--out", str(tmp_path / "eval")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and str(folder / AGENT_FILE) in err
    assert "must be a string" in err
