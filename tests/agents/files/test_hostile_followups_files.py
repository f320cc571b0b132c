"""Issue 33 follow-ups on agent files, through ``TrainedAgent.load``: a device or FIFO
given as the agent is named as such, and a pickled run's ``config.yml`` that is not
valid YAML or not a mapping is an ``AgentLoadError`` naming the file."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from tether_gym_agents.files.safe_format import AgentLoadError
from tether_gym_agents.files.trained import TrainedAgent

NOT_REGULAR = "is not a regular file or an agent folder"


def test_load_names_a_device_as_not_a_regular_file():
    """Before: ``agent path '/dev/zero' does not exist``."""
    with pytest.raises(AgentLoadError, match=f"/dev/zero {NOT_REGULAR}"):
        TrainedAgent.load("/dev/zero")


def test_load_names_a_fifo_and_a_link_to_a_device(tmp_path):
    """A FIFO (never opened: reading it would hang) and a link to /dev/zero."""
    fifo = tmp_path / "agent_fifo"
    os.mkfifo(fifo)
    with pytest.raises(AgentLoadError, match=NOT_REGULAR):
        TrainedAgent.load(fifo)
    link = tmp_path / "agent_link"
    link.symlink_to("/dev/zero")
    with pytest.raises(AgentLoadError, match=NOT_REGULAR):
        TrainedAgent.load(link, allow_pickle=True)
    with pytest.raises(AgentLoadError, match="does not exist"):
        TrainedAgent.load(tmp_path / "missing")


BAD_CONFIGS = {
    "not YAML": ("algo: [ppo\n", "not valid YAML"),
    "alias": ("a: &x {normalize: false}\nhyperparams: *x\nalgo: ppo\n", "alias"),
    "a list": ("- 1\n- 2\n", "must be a mapping"),
    "hyperparams a list": ("algo: ppo\nhyperparams: [1, 2]\n", "must be a mapping"),
}


@pytest.mark.parametrize("name", list(BAD_CONFIGS))
def test_pickled_run_with_a_bad_config_is_an_agent_load_error(tmp_path, name):
    """Before: a ``YamlFileError`` (not an AgentLoadError), or ``AttributeError: 'list'
    object has no attribute 'get'`` for a config.yml that is not a mapping."""
    text, message = BAD_CONFIGS[name]
    run = tmp_path / "run"
    run.mkdir()
    (run / "final_model.zip").write_bytes(b"never loaded: config.yml is refused first")
    (run / "config.yml").write_text(text)
    with pytest.raises(AgentLoadError, match=f"config.yml.*{message}|{message}.*config.yml"):
        TrainedAgent.load(run, allow_pickle=True)


def test_load_a_path_longer_than_the_system_allows():
    """Before: ``OSError: [Errno 36] File name too long`` from ``Path.exists``."""
    with pytest.raises(AgentLoadError, match=r"\(5000 characters\): File name too long"):
        TrainedAgent.load("p" * 5000)


def _shipped_copy(tmp_path):
    import shutil

    from tether_gym_agents.files.trained import PRETRAINED_DIR

    return Path(shutil.copytree(PRETRAINED_DIR / "ppo_fast" / "seed_0", tmp_path / "unit"))


def test_agent_json_nested_too_deeply_is_named(tmp_path):
    """Before (sweep row agent.json.deep): ``RecursionError`` from ``json.loads``, in
    ``hybrid_of`` (evaluate.py) and in ``TrainedAgent.load``."""
    from tether_gym_agents.cli.evaluate import main

    unit = _shipped_copy(tmp_path)
    (unit / "agent.json").write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(AgentLoadError, match="agent.json is not valid agent JSON: nested"):
        TrainedAgent.load(unit)
    assert main([str(unit), "--seeds", "1", "--out", str(tmp_path / "out")]) == 2
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("value", ["../outside/policy.safetensors", "sub/policy.safetensors",
                                   "..", 7])
def test_weights_file_with_a_folder_part_is_refused(tmp_path, value):
    """Before (sweep rows agent.weights.file_up*): a value with a folder part was
    silently read as its last component, inside the folder."""
    unit = _shipped_copy(tmp_path)
    meta = json.loads((unit / "agent.json").read_text())
    meta["weights"]["file"] = value
    (unit / "agent.json").write_text(json.dumps(meta))
    with pytest.raises(AgentLoadError, match=r"weights.file=.*no folder part"):
        TrainedAgent.load(unit)
