"""A local Ray instance ends with its driver, even on kill -9; a dead address fails fast.

Before: after ``kill -9`` of the ``train.py --seeds`` driver, ``ray::DashboardAgent`` and
``ray::RuntimeEnvAgent`` lived on (about 100 MB each, deaf to SIGTERM); ``--ray-address
127.0.0.1:1`` retried silently for minutes; every local start printed Ray's
token-authentication banner.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from tether_gym_agents.training import fanout, ray_reaper

LINUX = pytest.mark.skipif(not Path("/proc/self/stat").is_file(),
                           reason="the process records read Linux's /proc")


def _alive(pid: int) -> bool:
    return ray_reaper._start_time(pid) is not None


def _wait_gone(pids, timeout: float) -> list[int]:
    end = time.monotonic() + timeout
    while time.monotonic() < end and any(_alive(p) for p in pids):
        time.sleep(0.2)
    return [p for p in pids if _alive(p)]


def _driver(code: str, tmp_path: Path, env=None) -> tuple[subprocess.Popen, dict]:
    """Start a driver process running ``code``; wait for the JSON line it prints."""
    proc = subprocess.Popen([sys.executable, "-c", textwrap.dedent(code)], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, **(env or {})})
    line = proc.stdout.readline()
    assert line, proc.stderr.read()
    return proc, json.loads(line)


@LINUX
def test_watcher_kills_what_a_killed_driver_left(tmp_path):
    """The mechanism without Ray: a child the driver leaves behind dies with the driver."""
    proc, info = _driver("""
        import json, os, subprocess, sys, time
        from pathlib import Path
        from tether_gym_agents.training import ray_reaper
        child = subprocess.Popen(["sleep", "300"])
        record = Path("rec") / f"driver_{os.getpid()}.json"
        ray_reaper.record(record, os.getpid())
        subprocess.Popen([sys.executable, ray_reaper.__file__, str(os.getpid()), str(record)],
                         start_new_session=True)
        print(json.dumps({"child": child.pid}), flush=True)
        time.sleep(300)
        """, tmp_path, {"TMPDIR": str(tmp_path)})
    assert _alive(info["child"])
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert _wait_gone([info["child"]], 10) == []
    assert list((tmp_path / "rec").glob("*.json")) == []


@LINUX
def test_next_start_reaps_records_of_dead_drivers_only(tmp_path):
    sleeper = subprocess.Popen(["sleep", "300"])
    bystander = subprocess.Popen(["sleep", "300"])
    try:
        started = ray_reaper._start_time(sleeper.pid)
        dead = {"driver": [sleeper.pid, -1],  # that driver is gone (its start time differs)
                "processes": [[sleeper.pid, started],
                              [bystander.pid, -5]]}  # a reused pid: never signalled
        (tmp_path / "driver_1.json").write_text(json.dumps(dead))
        live = {"driver": [os.getpid(), ray_reaper._start_time(os.getpid())],
                "processes": [[bystander.pid, ray_reaper._start_time(bystander.pid)]]}
        (tmp_path / "driver_2.json").write_text(json.dumps(live))
        assert ray_reaper.reap_stale(tmp_path) == 1
        assert sleeper.wait(5) == -signal.SIGKILL
        assert bystander.poll() is None  # a running driver's process is left alone
        assert [p.name for p in tmp_path.iterdir()] == ["driver_2.json"]
    finally:
        for p in (sleeper, bystander):
            p.kill()
            p.wait()


def test_unreachable_address_fails_fast_naming_it(tmp_path, capsys, monkeypatch):
    pytest.importorskip("ray")
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    monkeypatch.setattr(fanout, "train", lambda s: pytest.fail("trained"))
    from tether_gym_agents.cli.train import main

    t0 = time.monotonic()
    assert main(["--seeds", "2", "--ray-address", "127.0.0.1:1", "--out", str(tmp_path / "o"),
                 "--timesteps", "64", "--no-progress"]) == 2
    assert time.monotonic() - t0 < 60
    err = capsys.readouterr().err
    assert err.startswith("train.py: error: cannot connect to the Ray cluster at "
                          "--ray-address/RAY_ADDRESS '127.0.0.1:1'")
    assert len(err.strip().splitlines()) == 1


def test_probe_is_what_bounds_the_wait(monkeypatch):
    """A host that never answers: the probe gives up after CONNECT_TIMEOUT_S."""
    import socket

    def silent(address, timeout):
        assert timeout == fanout.CONNECT_TIMEOUT_S <= 30
        raise TimeoutError

    monkeypatch.setattr(socket, "create_connection", silent)
    with pytest.raises(OSError, match="no answer within 10 s"):
        fanout._probe("10.255.255.1:6379")
    fanout._probe("auto")  # left to Ray


@LINUX
@pytest.mark.slow
def test_local_ray_dies_with_a_killed_driver_and_shows_no_banner(tmp_path):
    pytest.importorskip("ray")
    proc, info = _driver("""
        import json, os, time
        from tether_gym_agents.training import fanout
        fanout.init_ray(None)
        record = fanout.reaper_folder() / f"driver_{os.getpid()}.json"
        pids = [p for p, _ in json.loads(record.read_text())["processes"]]
        print(json.dumps({"pids": pids}), flush=True)
        time.sleep(300)
        """, tmp_path)
    agents = [p for p in info["pids"] if "Agent" in Path(f"/proc/{p}/cmdline").read_text()]
    assert len(agents) >= 1, info  # ray::DashboardAgent, ray::RuntimeEnvAgent
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert _wait_gone(info["pids"], 20) == []
    assert "Token authentication" not in proc.stderr.read()


POSIX = pytest.mark.skipif(not hasattr(os, "getuid"), reason="folder owners are POSIX's")


@POSIX
def test_the_reaper_folder_is_made_private(tmp_path, monkeypatch):
    monkeypatch.setattr("tempfile.gettempdir", lambda: str(tmp_path))
    folder = fanout.reaper_folder()
    assert folder == tmp_path / f"tether_gym_ray_{os.getuid()}"
    assert folder.is_dir() and folder.stat().st_mode & 0o777 == 0o700
    assert fanout.reaper_folder() == folder  # an existing private folder is taken


@POSIX
@pytest.mark.parametrize("case", ["world-writable", "another owner", "a symlink"])
def test_a_reaper_folder_others_can_write_is_refused(tmp_path, monkeypatch, capsys, case):
    """Before: any folder of that name in the shared temporary directory was taken; its
    sitecustomize.py goes first on the PYTHONPATH of every Python process of a local Ray
    instance, and the reaper SIGKILLs what its records name."""
    monkeypatch.setattr("tempfile.gettempdir", lambda: str(tmp_path))
    folder = tmp_path / f"tether_gym_ray_{os.getuid()}"
    if case == "a symlink":
        (tmp_path / "elsewhere").mkdir(mode=0o700)
        folder.symlink_to(tmp_path / "elsewhere")
    else:
        folder.mkdir()
        os.chmod(folder, 0o777 if case == "world-writable" else 0o700)
        if case == "another owner":
            if os.getuid() != 0:
                pytest.skip("only root can give a folder to another user")
            os.chown(folder, 12345, 12345)
    with pytest.raises(fanout.ConfigError, match=rf"{folder} is not a private folder of "
                                                 r"this user .*set TMPDIR"):
        fanout.reaper_folder()
    assert not (folder / "site").exists()
