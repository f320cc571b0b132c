"""Driver and watcher both killed (kill -9): the local Ray instance's processes still end.

Before: ``ray::DashboardAgent`` and ``ray::RuntimeEnvAgent`` (about 200 MB together)
stayed until the next local start reaped them; they notice the raylet's death but then
wait for the dead GCS without end.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import pytest

from tether_gym_agents.training import ray_reaper

LINUX = pytest.mark.skipif(not Path("/proc/self/stat").is_file(),
                           reason="the processes follow the driver through Linux's /proc")


def _alive(pids):
    return [p for p in pids if ray_reaper._start_time(p) is not None]


@LINUX
def test_follow_driver_module_ends_a_child_when_the_driver_dies(tmp_path):
    """The mechanism without Ray: a Python child started with fate_env's environment."""
    driver = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import json, os, subprocess, sys, time
        from tether_gym_agents.training import ray_reaper
        env = {{**os.environ, **ray_reaper.fate_env({str(tmp_path)!r}, os.getpid())}}
        child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(300)"],
                                 env=env, start_new_session=True)
        print(json.dumps({{"child": child.pid}}), flush=True)
        time.sleep(300)
        """)], stdout=subprocess.PIPE, text=True)
    child = json.loads(driver.stdout.readline())["child"]
    time.sleep(1.0)
    assert _alive([child]) == [child]  # it lives while the driver lives
    os.kill(driver.pid, signal.SIGKILL)
    driver.wait()
    end = time.monotonic() + 10
    while _alive([child]) and time.monotonic() < end:
        time.sleep(0.2)
    assert _alive([child]) == []


def test_sitecustomize_chains_to_another(tmp_path):
    """An existing sitecustomize still runs after the one that follows the driver."""
    other = tmp_path / "other"
    other.mkdir()
    (other / "sitecustomize.py").write_text("import os\nos.environ['OTHER_SITE'] = '1'\n")
    env = {**os.environ, **ray_reaper.fate_env(tmp_path, os.getpid())}
    env["PYTHONPATH"] += os.pathsep + str(other)
    out = subprocess.run([sys.executable, "-c", "import os, threading; print(os.environ.get("
                          "'OTHER_SITE'), [t.name for t in threading.enumerate()])"],
                         env=env, capture_output=True, text=True, check=True).stdout
    assert out.startswith("1 ") and "follow-driver" in out


@LINUX
@pytest.mark.slow
def test_local_ray_ends_when_driver_and_watcher_are_killed(tmp_path):
    pytest.importorskip("ray")
    short = tempfile.mkdtemp(prefix="tgr", dir="/tmp")  # Ray's socket paths: <= 107 bytes
    try:
        _kill_driver_and_watcher(tmp_path, short)
    finally:
        shutil.rmtree(short, ignore_errors=True)


def _kill_driver_and_watcher(tmp_path: Path, temp: str) -> None:
    proc = subprocess.Popen([sys.executable, "-c", textwrap.dedent("""
        import json, os, time
        from tether_gym_agents.training import fanout, ray_reaper
        fanout.init_ray(None)
        time.sleep(2)
        watcher = fanout._WATCHERS[os.getpid()].pid
        pids = [p for p, _ in ray_reaper._children(os.getpid()) if p != watcher]
        print(json.dumps({"pids": pids, "watcher": watcher}), flush=True)
        time.sleep(300)
        """)], cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "TMPDIR": temp})
    line = proc.stdout.readline()
    assert line, proc.stderr.read()
    info = json.loads(line)
    agents = [p for p in info["pids"] if "Agent" in Path(f"/proc/{p}/cmdline").read_text()]
    assert agents, info  # ray::DashboardAgent, ray::RuntimeEnvAgent
    os.kill(info["watcher"], signal.SIGKILL)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    end = time.monotonic() + 20
    while _alive(info["pids"]) and time.monotonic() < end:
        time.sleep(0.2)
    left = _alive(info["pids"])
    for pid in left:  # do not leave them to the next test
        os.kill(pid, signal.SIGKILL)
    assert left == []
