"""The PPO minibatch step captured as a CUDA graph and replayed (``train.py gpu --cuda-graphs``).

On a GPU, a minibatch step of ``train.py gpu`` is a few hundred small kernels. Their
launches, not their arithmetic, set its time: ``bench/accel_ops.py`` counts them.
A CUDA graph records the kernels of one step once. Each later step is then one
launch of the whole graph ("CUDA Graphs" in PyTorch's CUDA semantics notes: warm-up
on a side stream, capture with ``torch.cuda.graph``, replay). What a graph needs
from the step, :func:`~.trainer._minibatch_step` provides:

* no host sync: the distributions skip their argument checks, and the step reads no
  tensor back to the host;
* no random draw and no sort: the minibatch orders are drawn before the steps
  (:func:`~.trainer._permutations`), and the step gets its rows ``idx`` as a tensor;
* fixed inputs: the rollout (:class:`~.trainer.RolloutBatch`), the learning rates and
  the weights stay in the same storage for the whole run and are refilled in place,
  so that every replay reads the new values where the capture found the old ones.

Adam must be built with ``capturable=True`` (the trainer does that when asked for graphs).
The warm-up steps are ordinary training steps. Nothing is run twice, and nothing is
left out.

Not yet measured on a GPU. No device was lent to the session that wrote this
(2026-12-07). Its CPU tests replay the step through :class:`CallCapture`, which
checks how the inputs are fed, not CUDA's capture itself. Step 4 of
``bench/gpu_session3.sh`` runs it on a device.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

__all__ = ["GraphedMinibatchStep", "CudaCapture", "CallCapture"]

WARMUP_STEPS = 3
"""Eager steps of each minibatch shape before its capture (make_graphed_callables' 3)."""


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

    def capture(self, fn: Callable[[], None]) -> Callable[[], None]:
        """Record ``fn``'s kernels (capture runs none of them); its replay."""
        graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(graph):
            fn()
        return graph.replay


class CallCapture:
    """A stand-in for :class:`CudaCapture` on any device.

    Like a capture, :meth:`capture` runs nothing, and each replay runs ``fn`` again on
    the inputs fixed at capture. The tests use it to check on the CPU that the step is
    fed through its fixed inputs: the step is then equal to the eager step.
    """

    def warmup(self, fn: Callable[[], None]) -> None:
        """Run ``fn``."""
        fn()

    def capture(self, fn: Callable[[], None]) -> Callable[[], None]:
        """``fn`` itself, not run: its calls are the replays."""
        return fn


def _addresses(batch: tuple, lr: torch.Tensor, opt: torch.optim.Optimizer) -> tuple:
    """Where a graph reads its inputs: the rollout, the rates and the weights."""
    params = [p for group in opt.param_groups for p in group["params"]]
    return tuple(t.data_ptr() for t in (*batch, lr, *params))


class GraphedMinibatchStep:
    """``step(policy, opt, lr, settings, batch, idx)`` captured once per shape of ``idx``.

    The first :data:`WARMUP_STEPS` calls of a shape run ``step`` eagerly, through
    ``capture.warmup``. The next call captures it, reading a fixed copy of ``idx``. From
    then on, each call copies its ``idx`` into that copy and replays. A call whose
    rollout, rates or weights are no longer where the capture found them raises
    RuntimeError: a replay would read stale memory.

    Parameters
    ----------
    step : callable
        :func:`~.trainer._minibatch_step` (no host sync, no random draw).
    capture : CudaCapture or CallCapture, optional
        The graph API (default: :class:`CudaCapture`).
    """

    def __init__(self, step: Callable, capture=None):
        self._step = step
        self._capture = CudaCapture() if capture is None else capture
        self._warm: dict[tuple, int] = {}
        self._graphs: dict[tuple, tuple] = {}

    @property
    def captured(self) -> int:
        """How many graphs (minibatch shapes) are captured."""
        return len(self._graphs)

    def __call__(self, policy, opt, lr, settings, batch: tuple, idx: torch.Tensor) -> None:
        """One minibatch step: warm-up, capture and replay, or replay."""
        key = tuple(idx.shape)
        if key not in self._graphs:
            self._warm[key] = self._warm.get(key, 0) + 1
            if self._warm[key] <= WARMUP_STEPS:
                self._capture.warmup(lambda: self._step(policy, opt, lr, settings, batch, idx))
                return
            fixed_idx = idx.clone()
            opt.zero_grad(set_to_none=True)  # the captured backward makes the gradients
            replay = self._capture.capture(
                lambda: self._step(policy, opt, lr, settings, batch, fixed_idx))
            self._graphs[key] = (replay, fixed_idx, _addresses(batch, lr, opt))
        replay, fixed_idx, addresses = self._graphs[key]
        if _addresses(batch, lr, opt) != addresses:
            raise RuntimeError("GraphedMinibatchStep: the rollout, learning rates or weights "
                               "moved since the capture; refill them in place")
        fixed_idx.copy_(idx)
        replay()
