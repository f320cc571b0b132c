"""Worker threads for the threaded step: one per extra chunk of rows.

Work is handed over by semaphores (a wake-up costs a few microseconds, a thread pool's
futures several tens).

The compiled step releases the GIL, so a worker runs its chunk while the calling thread
runs another; nothing spins while idle (see :mod:`tether_gym.envs.threads` for when
threads are used at all).
"""

from __future__ import annotations

import threading
from collections.abc import Callable

__all__ = ["ChunkWorker"]


class ChunkWorker:
    """A daemon thread that runs one job per :meth:`start` and reports it by :meth:`wait`."""

    def __init__(self, name: str = "tether_gym-rows"):
        self._go = threading.Semaphore(0)
        self._done = threading.Semaphore(0)
        self._job: Callable[[], object] | None = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while True:
            self._go.acquire()
            job = self._job
            if job is None:
                return
            try:
                job()
            except BaseException as exc:  # noqa: BLE001 - handed to the caller in wait()
                self._error = exc
            self._done.release()

    def start(self, job: Callable[[], object]) -> None:
        """Run ``job()`` on the worker thread."""
        self._job = job
        self._go.release()

    def wait(self) -> None:
        """Block until the job given to :meth:`start` has finished; re-raise its error."""
        self._done.acquire()
        error, self._error = self._error, None
        if error is not None:
            raise error

    def stop(self) -> None:
        """End the thread (after its current job)."""
        self._job = None
        self._go.release()
        self._thread.join()
