"""Calling a compiled kernel without numba's per-call type dispatch.

numba's dispatcher works out the numba type of every argument on every call. For
arrays and plain tuples it has a fast path; for named tuples it falls back to Python,
which costs more than a whole single-env step (figures: ``bench/README.md``). The
callers of :class:`Direct` pass arguments whose types never change (arrays they
allocated themselves, with fixed dtypes, dimensions and C order), so the compiled entry
point found on the first call serves every later call.
"""

from __future__ import annotations

from typing import Any

from . import numba_private

__all__ = ["Direct"]


class Direct:
    """A compiled function called through its entry point after the first call.

    Parameters
    ----------
    dispatcher : numba Dispatcher
        The ``@njit`` function.

    Notes
    -----
    The first call goes through the dispatcher (compiling or loading from the cache)
    and records the entry point of the signature it resolved. Every argument of a
    later call must have the same numba type (dtype, ndim, layout, tuple structure)
    as in that first call: the entry point does not check it. Where numba's private
    attributes this relies on have moved (:func:`.numba_private.entry_point`), every
    call goes through the dispatcher.
    """

    def __init__(self, dispatcher: Any):
        self._dispatcher = dispatcher
        self._entry: Any = None
        self.__doc__ = dispatcher.__doc__

    def __call__(self, *args: Any) -> Any:
        """Call the compiled function (see the class notes)."""
        entry = self._entry
        if entry is not None:
            return entry(*args)
        result = self._dispatcher(*args)
        entry = numba_private.entry_point(self._dispatcher, args)
        self._entry = self._dispatcher if entry is None else entry
        return result
