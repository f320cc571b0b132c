"""When the vector env steps its rows on threads: a measured choice.

The threaded step splits the rows into one contiguous chunk per core and runs the
compiled step (which releases the GIL) on each at once (``ChainBatch.step``). On idle
cores that pays from a few dozen envs on. When the cores are shared with another
CPU-bound process (a second training run, the common case of a seed fan-out), a chunk
whose thread is descheduled holds the whole step for a scheduler time slice: numba's
OpenMP threads, used before, were then many times slower than one thread, their idle
workers spinning and taking CPU from the other process (``bench/threads_under_load.py``;
figures in ``bench/README.md``). No static rule knows which case it is in, so
:class:`ThreadPolicy` measures:

* **probe**: a few serial steps, then as many threaded steps; the median time per row
  of each is compared. A threaded step slower than ``alarm`` times the serial median
  ends the probe at once (one such step says enough, and under load it can cost as
  much as a hundred serial steps);
* **exploit**: the winner runs for an interval of steps. Threads must be at least
  ``1 - margin`` (10 %) faster to win, since the serial kernel leaves the other core
  alone. The interval doubles each time a probe confirms the previous choice (from
  ``first_interval`` up to ``max_interval`` steps) and drops back when the choice flips;
  it is also long enough that the probe's steps of the losing mode cost at most
  ``budget`` (2 %) of the time, so a steady machine pays a probe now and then;
* **alarm**: while threaded, ``alarm_steps`` steps in a row slower than ``alarm`` times
  the probe's median end the interval at once (a second job has started).

The first step of each mode is not timed (it loads the kernel and starts the thread
pool). Both kernels run the same per-row code, so the results are bitwise the same
whichever is chosen; only the speed changes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["ThreadPolicy", "chunks_for", "available_cores"]

SERIAL, THREADED = 0, 1


def chunks_for(threads: int, rows: int) -> int:
    """Chunks of the threaded step: one per thread, at most one per row."""
    return min(threads, rows)


def _median(values: list[float]) -> float:
    ordered = sorted(values)
    mid = len(ordered) // 2
    return ordered[mid] if len(ordered) % 2 else 0.5 * (ordered[mid - 1] + ordered[mid])


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity), at least 1."""
    import os

    if hasattr(os, "sched_getaffinity"):
        return max(len(os.sched_getaffinity(0)), 1)
    return os.cpu_count() or 1


class ThreadPolicy:
    """Serial or threaded stepping of a vector env, per step.

    Call :meth:`chunks` before each batched step (0: serial, > 0: that many threads,
    one chunk of rows each) and :meth:`record` after it with the time it took.

    Parameters
    ----------
    parallel : bool or "auto"
        False: always serial. True: always threaded (when ``rows`` >= 2). "auto":
        serial below ``min_rows`` rows or on one core, else measured.
    min_rows : int
        Fewest rows for which "auto" considers threads (below it no thread is
        started) [-].
    num_threads : callable, optional
        Returns the number of threads to use (default :func:`available_cores`);
        called only when threads are considered.
    probe_steps : int
        Timed steps of each mode per probe (the median counts) [-].
    first_interval, max_interval : int
        Shortest and longest run of the chosen mode between probes [steps].
    budget : float
        Largest share of the time the losing mode's probe steps may cost: the interval
        after a probe is at least their excess time over the winner's, divided by
        ``budget`` (up to ``max_interval``) [-].
    margin : float
        Threads win when their median time per row is below ``margin`` times the
        serial one [-].
    alarm : float
        While threaded, a step slower than ``alarm`` times the probe's threaded median
        (per row) is a strike; in a probe, a threaded step slower than ``alarm`` times
        the serial median ends the probe [-].
    alarm_steps : int
        Strikes in a row that end the interval and start a probe [-].
    """

    def __init__(self, parallel: bool | str, min_rows: int, *,
                 num_threads: Callable[[], int] | None = None, probe_steps: int = 3,
                 first_interval: int = 16, max_interval: int = 1 << 16,
                 budget: float = 0.02, margin: float = 0.9, alarm: float = 2.0,
                 alarm_steps: int = 3):
        if not (parallel is True or parallel is False or parallel == "auto"):
            raise TypeError(f"parallel={parallel!r} must be True, False or 'auto'")
        for name, value, low in (("min_rows", min_rows, 1), ("probe_steps", probe_steps, 1),
                                 ("first_interval", first_interval, 1),
                                 ("alarm_steps", alarm_steps, 1)):
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError(f"{name}={value!r} must be an int >= {low}")
        if isinstance(max_interval, bool) or not isinstance(max_interval, int) \
                or max_interval < first_interval:
            raise ValueError(f"max_interval={max_interval!r} must be an int >= "
                             f"first_interval={first_interval}")
        if not 0.0 < budget <= 1.0:
            raise ValueError(f"budget={budget!r} must be in (0, 1]")
        if not 0.0 < margin <= 1.0:
            raise ValueError(f"margin={margin!r} must be in (0, 1]")
        if not alarm > 1.0:
            raise ValueError(f"alarm={alarm!r} must be > 1")
        self.parallel = parallel
        self.min_rows = min_rows
        self._num_threads = num_threads if num_threads is not None else available_cores
        self.probe_steps = probe_steps
        self.first_interval = first_interval
        self.max_interval = max_interval
        self.budget = budget
        self.margin = margin
        self.alarm = alarm
        self.alarm_steps = alarm_steps
        # the mode of the step in flight (None: not measured), the probe plan
        self._current: int | None = None
        self._plan: list[int] = []
        self._probing = False
        self._untimed = {SERIAL, THREADED}  # first step of each mode: kernel load, pool
        self._samples: dict[int, list[float]] = {SERIAL: [], THREADED: []}
        self._choice: int | None = None
        self._interval = first_interval
        self._left = 0
        self._reference = 0.0
        self._strikes = 0
        self.steps = {SERIAL: 0, THREADED: 0}
        self.probes = 0
        self.last_ratio = float("nan")

    # ------------------------------------------------------------------ #
    def chunks(self, rows: int) -> int:
        """Chunks for the next step of ``rows`` rows: 0 for the serial kernel."""
        self._current = None
        if self.parallel is False or rows < 2:
            return 0
        if self.parallel == "auto" and rows < self.min_rows:
            return 0
        threads = self._num_threads()
        if self.parallel is True:
            return chunks_for(threads, rows)
        if threads < 2:
            return 0
        mode = self._next_mode()
        self._current = mode
        return chunks_for(threads, rows) if mode == THREADED else 0

    def record(self, rows: int, seconds: float) -> None:
        """The step announced by the last :meth:`chunks` took ``seconds`` for ``rows``."""
        mode, self._current = self._current, None
        if mode is None or rows < 1:
            return
        self.steps[mode] += 1
        per_row = seconds / rows
        if mode in self._untimed:
            self._untimed.discard(mode)
            return
        if self._probing:
            self._samples[mode].append(per_row)
            serial = self._samples[SERIAL]
            if mode == THREADED and serial and per_row > self.alarm * _median(serial):
                self._plan.clear()  # threads lose by far: no need to pay for more
            if not self._plan:
                self._decide()
            return
        self._left -= 1
        if mode == THREADED and per_row > self.alarm * self._reference:
            self._strikes += 1
            if self._strikes >= self.alarm_steps:
                self._interval = self.first_interval
                self._left = 0
        else:
            self._strikes = 0

    def summary(self) -> dict[str, Any]:
        """Counts for benchmarks and debugging."""
        return {"serial_steps": self.steps[SERIAL], "threaded_steps": self.steps[THREADED],
                "probes": self.probes,
                "choice": {None: None, SERIAL: "serial", THREADED: "threads"}[self._choice],
                "threaded/serial time": round(self.last_ratio, 3)}

    # ------------------------------------------------------------------ #
    def _next_mode(self) -> int:
        if self._untimed:
            # the untimed first step of each mode, threaded first (it starts the pool)
            return THREADED if THREADED in self._untimed else SERIAL
        if (not self._probing and (self._choice is None or self._left <= 0)) \
                or (self._probing and not self._plan):  # (the latter: a step not recorded)
            self._start_probe()
        if self._plan:
            return self._plan.pop(0)
        return SERIAL if self._choice is None else self._choice

    def _start_probe(self) -> None:
        # serial first: threads that just ran may still spin and slow a serial step
        self._plan = [SERIAL] * self.probe_steps + [THREADED] * self.probe_steps
        self._samples = {SERIAL: [], THREADED: []}
        self._probing = True
        self._strikes = 0
        self.probes += 1

    def _decide(self) -> None:
        if not (self._samples[SERIAL] and self._samples[THREADED]):
            self._start_probe()  # a probe step went unrecorded: probe again
            return
        self._probing = False
        serial = _median(self._samples[SERIAL])
        threaded = _median(self._samples[THREADED])
        self.last_ratio = threaded / serial if serial > 0 else float("inf")
        choice = THREADED if threaded < self.margin * serial else SERIAL
        if choice == self._choice:
            interval = min(2 * self._interval, self.max_interval)
        else:
            interval = self.first_interval
        # the probe's steps of the losing mode, in excess of the winner's time
        best = threaded if choice == THREADED else serial
        lost = sum(max(t / best - 1.0, 0.0) for t in self._samples[1 - choice]) \
            if best > 0 else float("inf")
        self._interval = int(min(max(interval, lost / self.budget), self.max_interval))
        self._choice = choice
        self._left = self._interval
        self._reference = threaded
