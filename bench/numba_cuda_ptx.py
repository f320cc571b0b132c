"""Does numba-cuda compile the numba env's own step for a GPU? A probe that needs no GPU.

    pip install "numba-cuda[cu13]"          # NVVM comes with it; no driver needed
    python bench/numba_cuda_ptx.py [--n-bodies 3] [--cc 9.0]

Compiles, with ``numba.cuda.compile_ptx`` (numba-cuda's NVVM, to PTX for the given
compute capability; 9.0 is the H100/H200's), two kernels:

* ``physics``: one chain per thread through ``tether_gym.physics.kernels.advance_one``
  (the reel-command update, RK4 substeps and tensions of one control step);
* ``step``: the kernel of ``backend="numba-cuda"``
  (:func:`tether_gym_agents.accel.numba_cuda.step_kernel`), which calls
  ``tether_gym.envs.step_kernel.step_row``: physics, reward, failure code, cost,
  observation and info of one env step, the very code the numba env runs.

For each it prints (one JSON line) whether it compiled, the compile time, the PTX's size,
the functions still called (not inlined) and the local-memory stack frames declared,
by function and size (``__local_depot``: spills and per-thread arrays, slow on a GPU),
and, assembled to machine code by nvJitLink (no GPU needed either), the registers per
thread and bytes spilled. Compiling a kernel that calls a CPU ``@njit`` function makes
numba-cuda ask the driver for the current device's compute capability; on a machine
without a GPU the probe answers that question with ``--cc`` (a stand-in device object),
which is the only thing it fakes.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time

import numpy as np


class _StandInDevice:
    """What numba-cuda reads of the current device when a kernel calls an @njit function."""

    def __init__(self, cc):
        self.compute_capability = cc
        self.id = 0


def _ptx_facts(ptx: str) -> dict:
    """The PTX's size, the functions it calls (not inlined) and its local-memory frames."""
    called = re.findall(r"^\s*call(?:\.uni)?\s*(?:\([^)]*\),)?\s*\n?\s*([\w$]+)", ptx, re.M)
    frames = {}
    current = "?"
    for line in ptx.splitlines():
        head = re.match(r"^\.(?:visible\s+)?(?:entry|func)\b.*?([\w$]+)\($", line.strip())
        if head:
            current = head.group(1)[:40]
        depot = re.search(r"\.local\s+\.align\s+\d+\s+\.b8\s+__local_depot\d+\[(\d+)\]", line)
        if depot:
            frames[current] = int(depot.group(1))
    return {"ptx_chars": len(ptx), "calls": {name: called.count(name) for name in set(called)},
            "local_frame_bytes": frames}


def _machine_code_facts(ptx: str, cc) -> dict:
    """Registers per thread, spills and stack of the PTX assembled for ``cc`` (nvJitLink).

    nvJitLink (a library of the CUDA toolkit's wheels, cuda.bindings) runs ptxas without
    a GPU. Registers bound how many threads an SM holds at once (65,536 per SM on sm_90).
    """
    try:
        from cuda.bindings import nvjitlink
    except ImportError as exc:
        return {"sass": f"not assembled: {exc}"}
    handle = nvjitlink.create(2, [f"-arch=sm_{cc[0]}{cc[1]}", "-verbose"])
    data = ptx.encode()
    nvjitlink.add_data(handle, nvjitlink.InputType.PTX, data, len(data), "step")
    nvjitlink.complete(handle)
    log = bytearray(nvjitlink.get_info_log_size(handle))
    nvjitlink.get_info_log(handle, log)
    nvjitlink.destroy(handle)
    text = log.decode(errors="replace")
    registers = [int(x) for x in re.findall(r"Used (\d+) registers", text)]
    spills = [int(x) for x in re.findall(r"(\d+) bytes spill stores", text)]
    return {"max_registers_per_thread": max(registers, default=None),
            "spill_store_bytes": sum(spills)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--n-bodies", type=int, default=3)
    p.add_argument("--cc", default="9.0", help="compute capability, major.minor")
    args = p.parse_args(argv)
    cc = tuple(int(x) for x in args.cc.split("."))
    from numba import typeof

    from tether_gym_agents.accel import numba_cuda  # its numpy shim, then numba.cuda

    cuda = numba_cuda.cuda

    if getattr(cuda, "implementation", "") != "NVIDIA":
        print('numba-cuda is not installed: pip install "numba-cuda[cu13]"', file=sys.stderr)
        return 2
    if not cuda.is_available():
        import numba.cuda.dispatcher as dispatcher

        dispatcher.get_current_device = lambda: _StandInDevice(cc)  # type: ignore[attr-defined]

    from tether_gym.envs.batch import step_config
    from tether_gym.envs.config import EnvConfig
    from tether_gym.physics import kernels

    config = EnvConfig.from_kwargs(n_bodies=args.n_bodies,
                                   initial_theta=[0.0] * (args.n_bodies - 1))
    rows, work, action = numba_cuda.kernel_arrays(config, 4, np.zeros)
    cfg = step_config(config)

    def physics(nu, y, command, dist, par, work, out, substeps):
        b = cuda.grid(1)
        if b < y.shape[0]:
            p = work.physics
            mine = kernels.Scratch(p.S[b], p.R[b], p.V[b], p.tension[b], p.k1[b], p.k2[b],
                                   p.k3[b], p.k4[b], p.tmp[b], p.orbit[b])
            nu[b] = kernels.advance_one(nu[b], y[b], kernels.StepInputs(command[b], dist[b]),
                                        par[b], substeps, mine,
                                        kernels.StepOutputs(out.tension_min[b],
                                                            out.derivative[b], out.tension[b]))

    cases = {
        "physics": (physics, (rows.nu, rows.y, rows.command, rows.disturbance, rows.par, work,
                              rows, cfg.substeps)),
        "step": (numba_cuda.step_kernel, ((action,), rows, cfg, work, False)),
    }
    from importlib.metadata import version

    print(json.dumps({"numba_cuda": version("numba-cuda"), "cc": args.cc,
                      "n_bodies": args.n_bodies, "gpu_present": cuda.is_available()}))
    for name, (fn, example) in cases.items():
        sig = tuple(typeof(x) for x in example)
        t = time.perf_counter()
        try:
            ptx, _ = cuda.compile_ptx(fn, sig, cc=cc)
        except Exception as exc:  # noqa: BLE001 - the probe reports what failed
            print(json.dumps({"kernel": name, "ok": False,
                              "error": f"{type(exc).__name__}: {str(exc)[:800]}"}))
            continue
        seconds = round(time.perf_counter() - t, 2)
        print(json.dumps({"kernel": name, "ok": True, "compile_s": seconds,
                          **_ptx_facts(ptx), **_machine_code_facts(ptx, cc)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
