"""The trained agents' float64 forward pass: ``python bench/mlp_forward.py``.

Times :class:`~tether_gym_agents.files.mlp.NumpyMLP` (the deterministic action every
learned row of ``evaluate.py`` is scored with) on shipped agents' networks, at the
batch sizes an evaluation uses (one episode; the 10 seeds of a scenario; 70 episodes),
two ways in one run on one thread: the NumPy expression the shipped results were first
made with, ``(h[:, None, :] * W).sum(-1)`` per layer, and the compiled loops that sum in
the same order (``pairwise_linear``; bitwise the same actions, checked here on every
call). It prints one markdown table: ms per call and per row, and the ratio.
Run it on an idle machine.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402


def numpy_forward(mlp, obs: np.ndarray) -> np.ndarray:
    """The forward pass with NumPy's pairwise sum over a (B, out, in) temporary."""
    h = np.asarray(obs, dtype=np.float64)
    for layer in mlp.layers:
        h = (h[:, None, :] * layer.weight[None, :, :]).sum(axis=-1) + layer.bias
        if layer.activation is not None:
            h = np.tanh(h) if layer.activation == "Tanh" else np.maximum(h, 0.0)
    h = (mlp.low + 0.5 * (np.tanh(h) + 1.0) * (mlp.high - mlp.low) if mlp.squash
         else np.clip(h, mlp.low, mlp.high))
    return h.astype(np.float32)


def best_of(fn, repeats: int) -> float:
    """Median seconds per call over ``repeats`` calls (after one warm-up call)."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main(argv=None) -> int:
    from tether_gym_agents.files import TrainedAgent
    from tether_gym_agents.files.trained import pretrained_agents

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--agents", nargs="+", default=["ppo/seed_0", "distill_ppo/seed_0"])
    p.add_argument("--batches", type=int, nargs="+", default=[1, 10, 70])
    p.add_argument("--repeats", type=int, default=200)
    args = p.parse_args(argv)
    shipped = pretrained_agents()
    print(f"{platform.processor() or platform.machine()}, one thread, numpy {np.__version__}\n")
    print("| agent | layers | batch | NumPy expression [ms/call] | compiled [ms/call] | "
          "compiled [ms/row] | ratio |")
    print("|---|---|---|---|---|---|---|")
    rng = np.random.default_rng(0)
    for name in args.agents:
        head, _, rest = name.partition("/")
        agent = TrainedAgent.load(shipped[head] / rest if rest else shipped[head])
        mlp = agent.mlp
        widths = "x".join(str(layer.weight.shape[0]) for layer in mlp.layers[:-1])
        for batch in args.batches:
            obs = rng.normal(size=(batch, mlp.layers[0].weight.shape[1])).astype(np.float32)
            if not np.array_equal(numpy_forward(mlp, obs), mlp(obs)):
                raise SystemExit(f"{name}: the two forward passes differ at batch {batch}")
            slow = best_of(lambda obs=obs, mlp=mlp: numpy_forward(mlp, obs), args.repeats)
            fast = best_of(lambda obs=obs, mlp=mlp: mlp(obs), args.repeats)
            print(f"| {name} | {widths} | {batch} | {slow * 1e3:.3f} | {fast * 1e3:.3f} | "
                  f"{fast * 1e3 / batch:.4f} | {slow / fast:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
