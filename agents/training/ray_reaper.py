"""Stop the processes of a local Ray instance whose driver died (``kill -9`` included).

A local instance started by ``train.py --seeds`` (:func:`~.fanout.init_ray`) is a tree
of processes under the driver. When the driver is killed without a chance to call
``ray.shutdown()``, most of them follow it, but Ray's ``ray::DashboardAgent`` and
``ray::RuntimeEnvAgent`` (about 100 MB each) were seen to live on, ignoring SIGTERM.
So the driver records the processes it started in a file (:func:`record`) and starts
this file as a small watcher process (:func:`watch`, ``python ray_reaper.py DRIVER_PID
RECORD``, in its own session) that SIGKILLs the recorded processes still alive once the
driver is gone. If the watcher is killed too, the next local start reaps what the
record files of dead drivers name (:func:`reap_stale`).

The agents notice the raylet's death, but then wait without end for the dead GCS to take
their last report; so, third, every Python process of a local instance follows the driver
by itself: :func:`fate_env` puts a ``sitecustomize`` module (:data:`FOLLOW_DRIVER`, the
standard library only) first on the ``PYTHONPATH`` the instance's processes inherit, whose
daemon thread ends its process (``os._exit``) within :data:`POLL_S` once the driver named
in ``TETHER_GYM_RAY_DRIVER`` is gone; it then imports any other ``sitecustomize`` as
before. (Ray's C++ processes, GCS and raylet, end with the driver by themselves.)

Processes are named by (pid, start time) as Linux's ``/proc`` gives them: a pid reused
by another process is never signalled (where there is no ``/proc`` nothing is
recorded). Only the standard library is imported: the watcher starts in a moment.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from pathlib import Path

__all__ = ["record", "reap", "reap_stale", "watch", "fate_env", "POLL_S", "FOLLOW_DRIVER",
           "DRIVER_VARIABLE"]

POLL_S = 0.5
"""Seconds between the watcher's checks of the driver [s]."""


def _stat(pid: int) -> tuple[int, int] | None:
    """(parent pid, start time [clock ticks after boot]) of ``pid`` from /proc; None if gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2:].split()  # after "pid (name) "
    if fields[0] == "Z":  # a zombie has exited
        return None
    return int(fields[1]), int(fields[19])


def _start_time(pid: int) -> int | None:
    """The start time of process ``pid`` (None: no such process)."""
    stat = _stat(pid)
    return None if stat is None else stat[1]


def _children(driver: int) -> list[list[int]]:
    """[pid, start time] of every descendant of ``driver`` (Linux /proc; else none)."""
    parents: dict[int, list[list[int]]] = {}
    for entry in Path("/proc").glob("[0-9]*"):
        stat = _stat(int(entry.name))
        if stat is not None:
            parents.setdefault(stat[0], []).append([int(entry.name), stat[1]])
    out, todo = [], [driver]
    while todo:
        for child in parents.get(todo.pop(), []):
            out.append(child)
            todo.append(child[0])
    return out


def record(path: Path, driver: int) -> list[int]:
    """Write the driver's process tree (pid and start time of each) to ``path``; its pids."""
    procs = _children(driver)
    doc = {"driver": [driver, _start_time(driver)], "processes": procs}
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(doc))
    os.replace(tmp, path)
    return [pid for pid, _ in procs]


def _alive(entry) -> bool:
    pid, started = entry
    return started is not None and _start_time(pid) == started


def reap(path: Path) -> int:
    """SIGKILL the processes ``path`` records that still run; remove it; how many."""
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return 0
    killed = 0
    for entry in doc.get("processes", []):
        if _alive(entry):
            try:
                os.kill(entry[0], signal.SIGKILL)
                killed += 1
            except OSError:
                pass
    Path(path).unlink(missing_ok=True)
    return killed


def reap_stale(folder: Path) -> int:
    """Reap the record files in ``folder`` whose driver no longer runs; processes killed."""
    killed = 0
    for path in sorted(Path(folder).glob("driver_*.json")):
        try:
            driver = json.loads(path.read_text())["driver"]
        except (OSError, ValueError, KeyError):
            path.unlink(missing_ok=True)
            continue
        if not _alive(driver):
            killed += reap(path)
    return killed


DRIVER_VARIABLE = "TETHER_GYM_RAY_DRIVER"
"""Environment variable naming the driver a local instance's processes follow
(``PID:START``, START its start time as /proc gives it)."""

FOLLOW_DRIVER = f"""# written by tether_gym_agents.training.ray_reaper: the processes of a local Ray
# instance end when the driver that started it is gone (kill -9 included)
import os, sys, threading, time


def _start_time(pid):
    try:
        with open(f"/proc/{{pid}}/stat") as fh:
            text = fh.read()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2:].split()
    return None if fields[0] == "Z" else fields[19]


def _follow(pid, started):
    while _start_time(pid) == started:
        time.sleep({POLL_S!r})
    os._exit(0)


def _main():
    pid, _, started = os.environ.get({DRIVER_VARIABLE!r}, "").partition(":")
    if pid.isdigit() and started and _start_time(int(pid)) is not None:
        threading.Thread(target=_follow, args=(int(pid), started), daemon=True,
                         name="follow-driver").start()


_main()
# then any other sitecustomize, as if this one were not here
_here = os.path.dirname(os.path.abspath(__file__))
sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != _here]
del sys.modules["sitecustomize"]
try:
    import sitecustomize  # noqa: F401
except ImportError:
    pass
"""
"""Source of the ``sitecustomize`` module of a local instance's processes."""


def fate_env(folder: Path, driver: int) -> dict[str, str]:
    """Environment that makes the Python processes a local instance starts follow ``driver``.

    Writes :data:`FOLLOW_DRIVER` as ``folder/site/sitecustomize.py``; returns
    ``PYTHONPATH`` (that folder first) and :data:`DRIVER_VARIABLE`. Empty where there is
    no /proc (nothing to follow with).
    """
    started = _start_time(driver)
    if started is None:
        return {}
    site = Path(folder) / "site"
    site.mkdir(parents=True, exist_ok=True)
    target = site / "sitecustomize.py"
    if not target.is_file() or target.read_text() != FOLLOW_DRIVER:
        tmp = site / f".sitecustomize.{os.getpid()}.tmp"
        tmp.write_text(FOLLOW_DRIVER)
        os.replace(tmp, target)
    path = os.environ.get("PYTHONPATH")
    return {"PYTHONPATH": str(site) + (os.pathsep + path if path else ""),
            DRIVER_VARIABLE: f"{driver}:{started}"}


def watch(driver: int, path: Path) -> None:
    """Wait until ``driver`` has exited (or ``path`` is removed), then :func:`reap`."""
    started = _start_time(driver)
    while Path(path).is_file() and started is not None and _start_time(driver) == started:
        time.sleep(POLL_S)
    reap(path)


if __name__ == "__main__":
    watch(int(sys.argv[1]), Path(sys.argv[2]))
