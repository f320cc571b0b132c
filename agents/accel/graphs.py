"""The learner's steps captured as CUDA graphs and replayed (``train.py gpu --cuda-graphs``).

On a GPU, each piece of an iteration of ``train.py gpu`` is tens to hundreds of small
kernels. Their launches, not their arithmetic, set its time: ``bench/accel_ops.py``
counts them. A CUDA graph records the kernels of a piece once, and each later call is
then one launch of the whole graph ("CUDA Graphs" in PyTorch's CUDA semantics notes:
warm-up on a side stream, capture with ``torch.cuda.graph``, replay). Captured are the
rollout step with the env's step (:class:`RolloutStep`: the policy's half
:meth:`~.rollout.Rollout.act` with the env's draws and, on the torch backend, its whole
step; on a numba backend the kernel's results into the state; the learner's half
:meth:`~.rollout.Rollout.observe`; each reset attempt of the autoreset), the
advantages (:meth:`~.rollout.Rollout.finish`) and the update, every minibatch step of
an iteration in one graph (:class:`GraphedUpdate`). What stays eager: the CPU numba
backend's kernel calls (host calls, not CUDA work) and the default autoreset's host syncs
(whether any sub-env ended, whether any start must be drawn again), which decide what
runs next. Without either (``--sync-free`` on the torch backend, or on numba-cuda, whose
kernel is launched on torch's current stream: ``env.whole_step_graph``), nothing in a
rollout needs the host, and the trainer captures the whole rollout, its ``n_steps``
steps with their reset attempts and the advantages, as one graph: one launch per
iteration for the rollout, one for the update.
What a graph needs from a piece, they provide:

* no host sync: the distributions skip their argument checks, and nothing reads a
  tensor back to the host;
* no sort: the minibatch orders are drawn before the update
  (:func:`~.trainer._permutations`) and copied into a tensor that it reads.
  The action samples and the env's draws are made inside the graphs (each replay
  draws fresh numbers from where its generator stands);
* fixed inputs: the rollout's state and buffers (:class:`~.rollout.Rollout`, its step
  index ``t`` included), the env's state and outputs
  (:class:`~.vec_env.TorchTetherVecEnv`), the learning rates, the normalisation
  statistics and the weights stay in the same storage for the whole run and are updated
  in place, so that every replay reads the new values where the capture found the old
  ones. The env's generator is registered with the graphs that draw from it.

Adam must be built with ``capturable=True`` (the trainer does that when asked for
graphs). The warm-up calls are ordinary calls: nothing is run twice, and nothing is
left out.

Not yet measured on a GPU. No device was lent to the session that wrote this
(2026-12-07). Its CPU tests capture and replay through :class:`RecordingCapture`,
which keeps a CUDA graph's rules on the CPU (the recorded operations replayed on the
recorded tensors, the Python not run again), not CUDA's capture itself. Step 4 of
``bench/gpu_session3.sh`` runs it on a device.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch.utils._python_dispatch import TorchDispatchMode

__all__ = ["GraphedCall", "GraphedUpdate", "RolloutStep", "CudaCapture",
           "RecordingCapture"]

WARMUP_STEPS = 3
"""Eager calls of a graphed piece before its capture (make_graphed_callables' 3 warm-ups)."""


class CudaCapture:
    """torch.cuda's graph API: warm-up on a side stream, capture, replay."""

    def __init__(self):
        self._side: torch.cuda.Stream | None = None

    def warmup(self, fn: Callable[[], None]) -> None:
        """Run ``fn`` on a side stream (the warm-up that capture asks for)."""
        if self._side is None:
            self._side = torch.cuda.Stream()
        self._side.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(self._side):
            fn()
        torch.cuda.current_stream().wait_stream(self._side)

    def capture(self, fn: Callable[[], None],
                generators: tuple[torch.Generator, ...] = ()) -> Callable[[], None]:
        """Record ``fn``'s kernels (capture runs none of them); its replay.

        ``generators``: the CUDA generators other than torch's default that ``fn`` draws
        from, registered with the graph so that each replay advances them.
        """
        graph = torch.cuda.CUDAGraph()
        register = getattr(graph, "register_generator_state", None)
        for generator in generators:  # torch builds that register lazily lack the method
            if register is not None:
                register(generator)
        with torch.cuda.graph(graph):
            fn()
        return graph.replay


class RecordingCapture:
    """CUDA-graph semantics on any device: a stand-in for :class:`CudaCapture` in the tests.

    :meth:`capture` runs ``fn`` once under a dispatch mode that records every aten
    operation (the backward pass and the optimizer's included) with the very tensors it
    read and wrote. It then puts back every tensor that existed before and that ``fn``
    wrote, and the CPU generator's state, so that, like a capture, it leaves the state as
    it found it. Each replay runs the recorded operations again on the same tensors,
    without running ``fn``'s Python again: a Python number, or a tensor that Python
    rebinds after the capture, stays as the capture saw it, as in a CUDA graph. A host
    sync during the capture raises RuntimeError, as CUDA's capture does.
    """

    def warmup(self, fn: Callable[[], None]) -> None:
        """Run ``fn``."""
        fn()

    def capture(self, fn: Callable[[], None],
                generators: tuple[torch.Generator, ...] = ()) -> Callable[[], None]:
        """Record ``fn``'s operations, undo its writes; the replay of the record.

        ``generators``: the generators other than torch's default that ``fn`` draws
        from; their states are put back too.
        """
        rng = torch.get_rng_state()
        states = [g.get_state() for g in generators]
        recorder = _Recorder()
        try:
            with recorder:
                fn()
        finally:
            with torch.no_grad():
                for tensor, saved in recorder.saved.values():
                    tensor.copy_(saved)
            torch.set_rng_state(rng)
            for g, state in zip(generators, states, strict=True):
                g.set_state(state)
        return recorder.replay


_UNRECORDED = {"_record_function_enter_new", "_record_function_exit"}
"""Profiler markers: no arithmetic."""


def _tensors(value) -> list[torch.Tensor]:
    """The tensors in an argument or result (a tensor, a list or tuple of them, or none)."""
    if isinstance(value, torch.Tensor):
        return [value]
    if isinstance(value, (list, tuple)):
        return [v for v in value if isinstance(v, torch.Tensor)]
    return []


class _Recorder(TorchDispatchMode):
    """Records aten operations for :class:`RecordingCapture` (see there)."""

    def __init__(self):
        super().__init__()
        self.ops: list[tuple] = []
        self.made: set[int] = set()        # storages that the recorded operations made
        self.saved: dict[tuple, tuple] = {}  # written tensors from before: (tensor, copy)

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        name = func.overloadpacket.__name__
        if name == "_local_scalar_dense":
            raise RuntimeError("RecordingCapture: a host sync (a tensor read back to the "
                               "host) inside a capture")
        if name in _UNRECORDED:
            return func(*args, **kwargs)
        schema = func._schema
        written = []
        for i, arg in enumerate(schema.arguments):
            if arg.alias_info is not None and arg.alias_info.is_write:
                value = args[i] if i < len(args) else kwargs.get(arg.name)
                written.extend(_tensors(value))
        for t in written:
            if t.untyped_storage().data_ptr() not in self.made:
                key = (t.untyped_storage().data_ptr(), t.storage_offset(), tuple(t.shape),
                       t.stride())
                self.saved.setdefault(key, (t, t.detach().clone()))
        out = func(*args, **kwargs)
        if written:
            self.ops.append((func, args, kwargs, None))
        elif not any(r.alias_info is not None for r in schema.returns):  # a new tensor
            self.made.update(t.untyped_storage().data_ptr() for t in _tensors(out))
            self.ops.append((func, args, kwargs, out))
        return out  # a view: it aliases recorded storage, nothing to replay

    def replay(self) -> None:
        """Run the recorded operations again; each new result lands in the recorded one."""
        with torch.no_grad():
            for func, args, kwargs, out in self.ops:
                result = func(*args, **kwargs)
                if out is not None:
                    for dst, src in zip(_tensors(out), _tensors(result), strict=True):
                        dst.copy_(src)


def _addresses(batch: tuple, lr: torch.Tensor, opt: torch.optim.Optimizer) -> tuple:
    """Where a graph reads its inputs: the rollout, the rates and the weights."""
    params = [p for group in opt.param_groups for p in group["params"]]
    return tuple(t.data_ptr() for t in (*batch, lr, *params))


class GraphedCall:
    """``fn()`` run eagerly :data:`WARMUP_STEPS` times, then captured and replayed.

    ``fn`` takes no arguments and must read and write only tensors that stay in the
    same storage from call to call (refilled in place): the replays read them where
    the capture found them. The warm-up calls go through ``capture.warmup`` (a side
    stream on CUDA) and are ordinary calls: nothing is run twice or left out.

    Parameters
    ----------
    fn : callable
        The work of one call, e.g. :meth:`~.rollout.Rollout.act`.
    capture : CudaCapture or RecordingCapture, optional
        The graph API (default: :class:`CudaCapture`).
    generators : tuple of torch.Generator, optional
        The generators other than torch's default that ``fn`` draws from.
    """

    def __init__(self, fn: Callable[[], None], capture=None,
                 generators: tuple[torch.Generator, ...] = ()):
        self._fn = fn
        self._capture = CudaCapture() if capture is None else capture
        self._generators = tuple(generators)
        self._calls = 0
        self._replay: Callable[[], None] | None = None

    @property
    def captured(self) -> bool:
        """Whether the capture happened (the calls are replays from then on)."""
        return self._replay is not None

    def __call__(self) -> None:
        """One call: a warm-up, or the capture and its first replay, or a replay."""
        if self._replay is None:
            self._calls += 1
            if self._calls <= WARMUP_STEPS:
                self._capture.warmup(self._fn)
                return
            self._replay = self._capture.capture(self._fn, self._generators)
        self._replay()


class GraphedUpdate:
    """``steps(policy, opt, lr, settings, batch, orders)``: a whole update as one graph.

    A drop-in for :func:`~.trainer._minibatch_steps` (every minibatch step of an update,
    ``n_epochs`` passes over ``batch`` in the minibatch orders ``orders``): one
    :class:`GraphedCall` per ``orders`` shape (one in training), which each call first
    copies its ``orders`` into (they are drawn eagerly before, by
    :func:`~.trainer._permutations`). A call whose rollout, rates or weights are no
    longer where the first call found them raises RuntimeError: a replay would read
    stale memory.

    Parameters
    ----------
    steps : callable
        :func:`~.trainer._minibatch_steps` (no host sync, no random draw).
    capture : CudaCapture or RecordingCapture, optional
        The graph API (default: :class:`CudaCapture`).
    """

    def __init__(self, steps: Callable, capture=None):
        self._steps = steps
        self._capture = CudaCapture() if capture is None else capture
        self._graphs: dict[tuple, tuple] = {}

    @property
    def captured(self) -> int:
        """How many graphs (orders shapes) are captured."""
        return sum(call.captured for call, _, _ in self._graphs.values())

    def __call__(self, policy, opt, lr, settings, batch: tuple, orders: torch.Tensor) -> None:
        """One update: a warm-up, the capture, or a replay."""
        key = tuple(orders.shape)
        if key not in self._graphs:
            fixed = orders.clone()
            call = GraphedCall(lambda: self._steps(policy, opt, lr, settings, batch, fixed),
                               self._capture)
            self._graphs[key] = (call, fixed, _addresses(batch, lr, opt))
        call, fixed, addresses = self._graphs[key]
        if _addresses(batch, lr, opt) != addresses:
            raise RuntimeError("GraphedUpdate: the rollout, learning rates or weights moved "
                               "since the capture; refill them in place")
        fixed.copy_(orders)
        call()


class RolloutStep:
    """One rollout step, the env's included, made of the env's step's parts; graphed or not.

    A call runs, in this order (the parts of
    :class:`~.vec_env.TorchTetherVecEnv`'s same-step autoreset step):

    1. :meth:`~.rollout.Rollout.act` (its clipped action into the env's
       ``action_in``: :meth:`~.rollout.Rollout.share`), and
       :meth:`~.vec_env.TorchTetherVecEnv.step_begin` (the step's draws; with the
       torch backend the whole step, with a numba backend the copies into its rows);
    2. ``step_kernel``: a numba backend's one kernel launch (nothing with torch);
    3. ``step_end`` (a numba backend's rows into the state; nothing with torch);
    4. ``step_autoreset``: one host sync; in a step where an episode ended, a reset
       attempt or more, each ``reset_begin`` (the draws of a start for every row; with
       the torch backend its evaluation and its copy into the ended rows),
       ``reset_kernel`` (a numba backend's evaluation), ``reset_end`` (a numba
       backend's copy into the ended rows) and one host sync (whether a start failed);
    5. :meth:`~.rollout.Rollout.observe`, which reads the env's outputs where the env
       left them (:meth:`~.rollout.Rollout.share`).

    This is what ``act``, ``env.step``, ``take`` and ``observe`` compute in turn (the
    env's ``step`` is made of the same parts), without ``step``'s and ``take``'s copies
    of what it returns. With ``graphs``, 1, 3, 5, ``reset_begin`` and ``reset_end`` (the last two
    only with a numba backend) are each captured as a graph after their warm-up calls
    and replayed (:class:`GraphedCall`); the kernels and the host syncs stay eager. A
    step then costs the host 2 graph launches and a sync (torch backend), or 3
    launches, a kernel and a sync (numba), plus 1 or 2 launches, a kernel and a sync per
    reset attempt, against about 220 to 1,600 operations eager (bench/accel_ops.py).
    Where one graph can hold a whole step (``env.whole_step_graph``), the trainer calls
    the step ungraphed inside its graph of the whole rollout instead
    (:func:`~.trainer._collector`).

    Parameters
    ----------
    rollout : Rollout
        The learner's rollout (:class:`~.rollout.Rollout`).
    env : TorchTetherVecEnv
        Its env, with ``autoreset_mode="same_step"`` (or ``"same_step_sync_free"``),
        reset; with ``graphs`` its
        generator is registered with the graph that draws (1).
    graphs : bool
        Capture and replay 1, 3 and 5 (default False: call them).
    capture : CudaCapture or RecordingCapture, optional
        The graph API with ``graphs`` (default: :class:`CudaCapture`).
    """

    def __init__(self, rollout, env, graphs: bool = False, capture=None):
        if not env.same_step:
            raise ValueError(f"RolloutStep needs autoreset_mode='same_step' or "
                             f"'same_step_sync_free', got {env.autoreset_mode!r}")
        self._env = env
        o = env.outputs  # the rollout reads the env's step and writes its actions in place
        rollout.share(env.obs, o.reward, o.terminated, o.truncated, o.final_obs, env.action_in)

        def act() -> None:
            rollout.act()
            env.step_begin()

        numba = env.backend != "torch"
        self._act: Callable[[], None] = act
        self._end: Callable[[], None] | None = env.step_end if numba else None
        self._observe: Callable[[], None] = rollout.observe
        self._reset_begin: Callable[[], None] | None = None  # None: the env's own
        self._reset_end: Callable[[], None] | None = None
        self.parts: list[GraphedCall] = []
        if graphs:
            capture = CudaCapture() if capture is None else capture
            draws = (env.generator,)
            self._act = GraphedCall(act, capture, draws)
            self._observe = GraphedCall(rollout.observe, capture)
            self._reset_begin = GraphedCall(env.reset_begin, capture, draws)
            self.parts = [self._act, self._observe, self._reset_begin]
            if numba:
                self._end = GraphedCall(env.step_end, capture)
                self._reset_end = GraphedCall(env.reset_end, capture)
                self.parts += [self._end, self._reset_end]

    @property
    def captured(self) -> bool:
        """Whether every graph is captured (the calls are replays from then on)."""
        return bool(self.parts) and all(part.captured for part in self.parts)

    def __call__(self) -> None:
        """One rollout step (the class docstring says what runs)."""
        env = self._env
        self._act()
        env.step_kernel()
        if self._end is not None:
            self._end()
        env.step_autoreset(self._reset_begin, self._reset_end)
        self._observe()
