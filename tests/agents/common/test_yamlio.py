"""The shared safe YAML loader refuses hostile files with one error naming the file."""

from __future__ import annotations

import os
import sys
import threading
import time

import pytest

from tether_gym_agents.common.yamlio import (
    MAX_YAML_BYTES,
    MAX_YAML_DEPTH,
    YamlFileError,
    load_yaml_file,
    load_yaml_text,
)

BOMB = "\n".join(["a: &a [x, x, x, x, x, x, x, x, x]"]
                 + [f"{chr(98 + k)}: &{chr(98 + k)} [*{chr(97 + k)}, *{chr(97 + k)}, "
                    f"*{chr(97 + k)}, *{chr(97 + k)}, *{chr(97 + k)}, *{chr(97 + k)}, "
                    f"*{chr(97 + k)}, *{chr(97 + k)}, *{chr(97 + k)}]" for k in range(8)])


def test_plain_document_round_trips(tmp_path):
    path = tmp_path / "suite.yml"
    path.write_text("scenarios:\n  - name: a  # comment\n    env_kwargs: {n_bodies: 3, "
                    "masses: [1.0, 2.5]}\n    nominal: null\n  - {name: b, flag: true}\n")
    assert load_yaml_file(path) == {"scenarios": [
        {"name": "a", "env_kwargs": {"n_bodies": 3, "masses": [1.0, 2.5]}, "nominal": None},
        {"name": "b", "flag": True}]}
    (tmp_path / "empty.yml").write_text("")
    assert load_yaml_file(tmp_path / "empty.yml") is None
    assert load_yaml_text("[1, [2, [3]]]", source="x") == [1, [2, [3]]]


def test_alias_bomb_is_refused_fast_naming_the_file(tmp_path):
    path = tmp_path / "bomb.yml"
    path.write_text(BOMB)
    start = time.perf_counter()
    with pytest.raises(YamlFileError, match=r"suite file .*bomb\.yml.*line 1.*aliases"):
        load_yaml_file(path, what="suite file")
    assert time.perf_counter() - start < 1.0


@pytest.mark.parametrize("text", ["a: &x 1\nb: 2\n", "a: 1\nb: *x\n", "- &s [1]\n"])
def test_any_anchor_or_alias_is_refused(text):
    with pytest.raises(YamlFileError, match="config c.yml: .*anchors and aliases"):
        load_yaml_text(text, source="config c.yml")


def test_deep_nesting_is_an_error_not_a_recursion_error(tmp_path):
    path = tmp_path / "deep.yml"
    path.write_text("[" * 50_000)
    with pytest.raises(YamlFileError, match=rf"deep\.yml.*deeper than {MAX_YAML_DEPTH}"):
        load_yaml_file(path)
    depth_ok = "[" * MAX_YAML_DEPTH + "]" * MAX_YAML_DEPTH
    assert load_yaml_text(depth_ok, source="x") is not None
    with pytest.raises(YamlFileError, match="deeper"):
        load_yaml_text("a:\n" + "".join(" " * k + "- \n" for k in range(1, 60)), source="x")


def test_binary_file_names_the_file(tmp_path):
    path = tmp_path / "weights.yml"
    path.write_bytes(b"a: 1\n\xff\xfe\x00\x81 binary")
    with pytest.raises(YamlFileError, match=r"weights\.yml: not UTF-8 text"):
        load_yaml_file(path)


def test_syntax_error_names_file_and_line(tmp_path):
    path = tmp_path / "bad.yml"
    path.write_text("a: 1\nb: [1, 2\nc: 3\n")
    with pytest.raises(YamlFileError, match=r"bad\.yml: not valid YAML: line \d+") as info:
        load_yaml_file(path)
    assert "\n" not in str(info.value)


def test_size_cap_refuses_before_parsing(tmp_path):
    path = tmp_path / "big.yml"
    row = "- {name: s, description: 'xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx'}\n"
    path.write_text(row * (9_500_000 // len(row)))
    start = time.perf_counter()
    with pytest.raises(YamlFileError, match=rf"big\.yml: larger than {MAX_YAML_BYTES} bytes"):
        load_yaml_file(path)
    assert time.perf_counter() - start < 0.5
    small = tmp_path / "small.yml"
    small.write_text("a: 12345\n")
    with pytest.raises(YamlFileError, match="larger than 4 bytes"):
        load_yaml_file(small, max_bytes=4)
    with pytest.raises(YamlFileError, match="larger than"):
        load_yaml_text("a: 12345", source="x", max_bytes=4)


def test_missing_file_and_folder(tmp_path):
    with pytest.raises(YamlFileError, match=r"config .*nope\.yml does not exist"):
        load_yaml_file(tmp_path / "nope.yml", what="config")
    with pytest.raises(YamlFileError, match="is a folder"):
        load_yaml_file(tmp_path)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")
def test_fifo_and_device_are_refused_without_blocking(tmp_path):
    fifo = tmp_path / "config.yml"
    os.mkfifo(fifo)
    link = tmp_path / "zero.yml"
    link.symlink_to("/dev/zero")
    errors: list = []

    def read_all():
        for path in (fifo, link):
            try:
                load_yaml_file(path)
            except YamlFileError as exc:
                errors.append(str(exc))

    worker = threading.Thread(target=read_all, daemon=True)
    worker.start()
    worker.join(timeout=5)
    if worker.is_alive():  # unblock the reader before failing
        with open(fifo, "w"):
            pass
        pytest.fail("load_yaml_file blocked on a FIFO or device")
    assert len(errors) == 2
    assert "config.yml is not a regular file (a FIFO)" in errors[0]
    assert "zero.yml is not a regular file (a device)" in errors[1]


def test_code_tags_are_not_executed():
    with pytest.raises(YamlFileError, match="could not determine a constructor"):
        load_yaml_text("!!python/object/apply:os.system ['echo hi']", source="x")


def test_missing_pyyaml_names_the_pip_command(monkeypatch):
    monkeypatch.setitem(sys.modules, "yaml", None)
    with pytest.raises(YamlFileError, match=r"x: reading YAML needs PyYAML: pip install"):
        load_yaml_text("a: 1", source="x")
