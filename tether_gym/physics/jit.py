"""numba options shared by the compiled kernels.

``KERNEL``: cached, with numpy's error model (1/0 gives inf instead of raising, so a
diverging state is caught by the non-finite checks rather than by an exception).

``LOOP``: ``KERNEL`` without NRT, numba's reference-counting runtime (``_nrt=False``,
an option numba has long had but keeps private). Used for the batch loops and the
RK4 stepper, which allocate nothing: with NRT, numba emits an atomic incref and
decref for every array argument, view and tuple element it binds, and these took
41 % of the samples of ``perf`` on the 256-env step kernel; without it the same
arithmetic runs about 2.5x faster with bitwise-identical results. A ``LOOP``
function cannot allocate arrays: its ``KERNEL`` or Python caller owns every array
it touches (the scratch comes from :func:`tether_gym.physics.kernels.make_scratch`).

``INLINE``: ``KERNEL`` inlined into the caller at numba IR level (the small hot
helpers); an inlined function runs under its caller's options.
"""

from __future__ import annotations

__all__ = ["KERNEL", "LOOP", "INLINE"]

KERNEL = {"cache": True, "error_model": "numpy"}
LOOP = {**KERNEL, "_nrt": False}
INLINE = {**KERNEL, "inline": "always"}
