"""numba options shared by the compiled kernels.

``KERNEL``: cached, with numpy's error model (1/0 gives inf instead of raising, so a
diverging state is caught by the non-finite checks rather than by an exception).

``LOOP``: ``KERNEL`` without NRT, numba's reference-counting runtime (``_nrt=False``,
an option numba keeps private: :data:`tether_gym.physics.numba_private.NO_NRT`). Used
for the batch loops and the RK4 stepper, which allocate nothing: with NRT, numba emits
an atomic incref and decref for every array argument, view and tuple element it binds,
which dominated the profile of the many-env step kernel; without it the same
arithmetic runs faster with bitwise-identical results (figures: ``bench/README.md``).
A ``LOOP`` function cannot allocate arrays: its ``KERNEL`` or Python caller owns every
array it touches (the scratch comes from :func:`tether_gym.physics.kernels.make_scratch`).

``INLINE``: ``KERNEL`` inlined into the caller at numba IR level (the small hot
helpers); an inlined function runs under its caller's options.

The offset helper :func:`~tether_gym.physics.layout.at`, called at hundreds of sites,
is compiled with ``LOOP`` and left to LLVM to inline: numba's IR-level inlining
deep-copies the callee at every call site, which cost compile time and bought nothing
at run time. (Helpers that Python also calls with arrays cannot do this: a function
compiled without NRT cannot return arrays.)

Importing this module installs :mod:`tether_gym.physics.compile_cache`, before any
kernel is decorated: every ``cache=True`` function of the package is then cached under
one key, a hash of the whole package source and its version, so an edit of any file
(a helper inlined from another file included) or an upgrade recompiles it; without a
writable cache directory the kernels are compiled in memory, with one warning.
"""

from __future__ import annotations

from typing import Any

from . import compile_cache, numba_private

__all__ = ["KERNEL", "LOOP", "INLINE", "CACHE"]

CACHE = compile_cache.install()
"""Where and under which key the kernels are cached (:class:`~.compile_cache.CacheState`)."""

KERNEL: dict[str, Any] = {"cache": True, "error_model": "numpy"}
LOOP: dict[str, Any] = {**KERNEL, **numba_private.NO_NRT}
INLINE: dict[str, Any] = {**KERNEL, "inline": "always"}
