"""Worker threads for the threaded step: one per extra chunk of rows.

A worker hands its chunk to the compiled step without the GIL and without a wake-up:
the worker thread sits in the compiled step itself (:func:`~.step_kernel.step_rows`
called with a serving :class:`Relay`), which polls for the next chunk up to
:data:`POLLS` times after each one, yielding the core between polls (``sched_yield``),
and only then returns to Python to block on a semaphore. The calling thread waits for
the chunks in compiled code too (:func:`wait_done`). Waking a blocked thread costs a
sizeable part of a many-env step when the woken core had halted, and the woken thread
then has to take the GIL from a caller that is still in Python; a polling worker starts
its chunk at once (figures: ``bench/README.md``). Serving runs in the one compiled step
(rather than in a function that calls it) so that the step is compiled once: a second
compiled caller would recompile the whole step into itself, lengthening the first
threaded step with an empty cache.

A job is described by a worker's int64 control array (slots :data:`GEN` ...
:data:`STOP`): the caller writes the chunk's bounds into it and then increments the job
counter ``GEN``; the worker steps ``index[LO:HI]`` and sets ``DONE = GEN``. The external
yield call between a poll and the next read is opaque to the compiler, so no read of
the control array or the rows moves across it. Polling takes CPU from another process
only while jobs keep coming; whether threads are used at all is measured by
:mod:`tether_gym.envs.threads`.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys
import threading
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from ..physics.jit import INLINE, LOOP

__all__ = ["Relay", "SpinWorker", "call_address", "next_job", "wait_done", "yield_function",
           "GEN", "DONE", "LO", "HI", "STOP", "SLOTS", "POLLS"]

GEN, DONE, LO, HI, STOP = range(5)
"""Slots of a worker's control array: job counter, last job done, chunk bounds, stop flag."""

SLOTS = 8
"""Length of a control array [-]."""

POLLS = 2000
"""Polls (each a ``sched_yield``) before an idle worker blocks [-]."""


class Relay(NamedTuple):
    """How a call of the compiled step relates to worker threads.

    ``polls`` 0: an ordinary call (the caller's rows, once); > 0: the call serves the
    jobs posted to ``ctl`` until none came for ``polls`` polls. ``give_up`` is
    :func:`yield_function`'s address.
    """

    ctl: np.ndarray   # (SLOTS,) int64 control array
    give_up: int      # address of the C function int f(void) that yields the core
    polls: int


_KEEP: list = []
"""The ctypes objects whose addresses :func:`yield_function` handed out (kept alive)."""


def yield_function() -> tuple[int, bool]:
    """(the address of a C function that gives up the core, whether it is a real one).

    ``sched_yield`` (POSIX) or ``SwitchToThread`` (Windows); where neither is found, a
    do-nothing stand-in (the compiled step needs some function) and False: the vector
    env then steps on one thread. An address (an int) rather than the ctypes function
    itself: numba converts a ctypes function argument through Python on every call,
    which costs more than the rest of a call of the single env's step.
    """
    real = True
    fn: Any
    try:
        if sys.platform == "win32":
            fn = ctypes.windll.kernel32.SwitchToThread  # type: ignore[attr-defined]
        else:
            fn = ctypes.CDLL(ctypes.util.find_library("c") or None).sched_yield
        fn.restype = ctypes.c_int
        fn.argtypes = []
    except (OSError, AttributeError):  # pragma: no cover - platform without either
        fn = ctypes.CFUNCTYPE(ctypes.c_int)(lambda: 0)
        real = False
    _KEEP.append(fn)
    return int(ctypes.cast(fn, ctypes.c_void_p).value or 0), real


@intrinsic
def call_address(typingctx, address):
    """Call the C function ``int f(void)`` at ``address`` (an int); return its result.

    The call is opaque to the compiler, so no read or write of memory that other
    threads can see moves across it.
    """
    if not isinstance(address, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        fnty = ir.FunctionType(ir.IntType(32), [])
        return builder.call(builder.inttoptr(args[0], fnty.as_pointer()), [])

    return types.int32(address), codegen


@njit(**INLINE)
def next_job(relay, seen):
    """The next job posted to ``relay.ctl`` after job ``seen``, or -1.

    Polls up to ``relay.polls`` times; -1 when none came or ``STOP`` is set. On return
    with a job, its bounds, rows and actions (written before ``GEN``) can be read.
    """
    ctl = relay.ctl
    job = ctl[GEN]
    idle = 0
    while job == seen and idle < relay.polls:
        call_address(relay.give_up)
        idle += 1
        job = ctl[GEN]
    if job == seen or ctl[STOP]:
        return -1
    call_address(relay.give_up)  # a compiler barrier: the bounds are read after GEN
    return job


@njit(nogil=True, **LOOP)
def wait_done(ctl, job, give_up):
    """Poll until ``ctl[DONE]`` reaches ``job``; return the number of polls (0: it had)."""
    polls = 0
    while ctl[DONE] < job:
        call_address(give_up)
        polls += 1
    call_address(give_up)  # the worker's rows are read after DONE
    return polls


class SpinWorker:
    """A daemon thread that steps the chunks posted to it (see the module docstring).

    Parameters
    ----------
    step : callable
        The compiled step, called as ``step(*args, Relay(ctl, give_up, POLLS))``.
    args : tuple
        Its other arguments: the batch's row-index (int64, (B,)) and action (float64,
        (B, n)) buffers that every job's chunk is read from, its ``Rows``, its
        ``StepConfig``, this worker's own ``RowWork`` and ``reset=False``.
    give_up : int
        :func:`yield_function`'s address.
    """

    def __init__(self, step: Callable[..., Any], args: tuple, give_up: int,
                 name: str = "tether_gym-rows"):
        self.ctl = np.zeros(SLOTS, dtype=np.int64)
        self.pid = os.getpid()  # a forked child has the object but not the thread
        self._step = step
        self._args = (*args, Relay(self.ctl, give_up, POLLS))
        self._give_up = give_up
        self._go = threading.Semaphore(0)
        self._error: BaseException | None = None
        self._stopped = False
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while True:
            self._go.acquire()
            while self._go.acquire(blocking=False):  # posts seen by the last call
                pass
            if self._stopped:
                return
            try:
                self._step(*self._args)
            except BaseException as exc:  # noqa: BLE001 - handed to the caller in wait()
                self._error = exc
                self.ctl[DONE] = self.ctl[GEN]  # releases the caller's wait

    def start(self, lo: int, hi: int) -> int:
        """Post the chunk ``index[lo:hi]``; return its job number."""
        ctl = self.ctl
        ctl[LO] = lo
        ctl[HI] = hi
        job = int(ctl[GEN]) + 1
        ctl[GEN] = job
        self._go.release()  # wakes the worker if it is blocked (else a no-op for it)
        return job

    def wait(self, job: int) -> int:
        """Block until job ``job`` is done; return the polls it took (0: done already).

        Re-raises an error of the worker thread.
        """
        polls = wait_done(self.ctl, job, self._give_up)
        error, self._error = self._error, None
        if error is not None:
            raise RuntimeError("a worker thread of the vector env failed") from error
        return polls

    def stop(self) -> None:
        """End the thread (after its current job)."""
        self._stopped = True
        self.ctl[STOP] = 1
        self.ctl[GEN] += 1
        self._go.release()
        self._thread.join()
