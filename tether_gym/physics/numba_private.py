"""Every use of numba's private (undocumented) API in tether_gym, in one place.

numba may change any of these in a minor release without notice; ``pyproject.toml``
therefore admits only the numba releases they were tested with, and
``tests/physics/test_numba_private.py`` checks each one against the installed numba
(it fails with a message naming the item and this module). Nothing else in the
package touches numba beyond its public API (``njit``, ``numba.types``,
``numba.extending.intrinsic``, ``Dispatcher.py_func``, the event API
``numba.core.event``).

1. **The jit option** ``_nrt=False`` (:data:`NO_NRT`): compile without numba's
   reference-counting runtime. Used by :data:`tether_gym.physics.jit.LOOP`. If numba
   dropped it, ``njit`` would reject the option when the package is imported.
2. **The compiled entry point of a dispatcher** (:func:`entry_point`):
   ``Dispatcher.typeof_pyval`` (the numba type of an argument) and
   ``Dispatcher.overloads[signature].entry_point`` (the compiled function of one
   signature). Used by :class:`tether_gym.physics.dispatch.Direct`. If they moved,
   :func:`entry_point` returns None and the caller goes through the dispatcher
   (slower, same results).
3. **The cache locator machinery** (:func:`cache_internals`, :func:`make_locator`):
   the base class ``numba.core.caching._CacheLocator`` (with its
   ``get_suitable_cache_subpath``), the list ``CacheImpl._locator_classes``
   (``_CacheImpl`` before numba 0.59) that numba asks in order for a locator of each
   ``cache=True`` function, and the locator protocol numba calls
   (``from_function``, ``get_cache_path``, ``get_source_stamp``,
   ``get_disambiguator``). Used by :mod:`tether_gym.physics.compile_cache`. If they are
   missing, :func:`cache_internals` says why and the kernels are compiled in memory.
4. **Turning ``cache=True`` off for some files** (:func:`disable_caching`):
   ``numba.core.dispatcher.Dispatcher.enable_caching``, the method ``cache=True``
   calls, replaced by one that skips the functions of those files. Used by
   :mod:`tether_gym.physics.compile_cache` when no cache directory is writable.
"""

from __future__ import annotations

import inspect
import sys
from collections.abc import Callable
from typing import Any

__all__ = ["NO_NRT", "entry_point", "cache_internals", "make_locator", "disable_caching"]

NO_NRT: dict[str, Any] = {"_nrt": False}
"""jit options that compile a function without numba's reference-counting runtime.

Such a function cannot allocate arrays (or return one); numba then emits no atomic
reference counting for the arrays, views and tuples it binds."""


def entry_point(dispatcher: Any, args: tuple) -> Any:
    """The compiled function that ``dispatcher`` runs for ``args``, or None.

    ``dispatcher`` must already have compiled (or loaded) the signature of ``args``
    (call it with them first). None when numba's internals moved or the signature is
    not compiled. The entry point does not check its arguments' types.
    """
    try:
        sig = tuple(dispatcher.typeof_pyval(a) for a in args)
        return dispatcher.overloads[sig].entry_point
    except (AttributeError, KeyError):
        return None


def cache_internals() -> tuple[tuple[type, list] | None, str]:
    """``((locator base class, numba's list of locator classes), "")``, or ``(None, why)``.

    A locator class inserted at the front of the list is asked first for every function
    compiled with ``cache=True`` (see :func:`make_locator`).
    """
    try:
        from numba.core import caching
        from numba.core.dispatcher import Dispatcher
    except ImportError as exc:  # pragma: no cover - depends on numba's layout
        return None, f"numba.core.caching is missing ({exc})"
    base = getattr(caching, "_CacheLocator", None)
    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
    classes = getattr(impl, "_locator_classes", None)
    if (base is None or not hasattr(base, "get_suitable_cache_subpath")
            or not isinstance(classes, list) or not hasattr(Dispatcher, "enable_caching")):
        return None, (f"numba {getattr(sys.modules.get('numba'), '__version__', '?')} "
                      "lacks the cache internals tether_gym uses (numba.core.caching."
                      "_CacheLocator, CacheImpl._locator_classes, Dispatcher.enable_caching)")
    return (base, classes), ""


def make_locator(base: type, get_state: Callable[[], Any]) -> type:
    """A numba cache locator class, built on numba's ``base``, driven by a cache state.

    ``get_state()`` returns None (the locator declines every function) or an object with
    ``enabled`` (bool), ``stamp`` (str), ``covers(py_file) -> bool`` and
    ``cache_path(py_file, subpath) -> str``
    (:class:`tether_gym.physics.compile_cache.CacheState`). For a function in a covered
    file, the locator keys the cache on ``stamp`` (instead of the file's modification
    time) and stores it under ``cache_path(py_file, numba's subpath for the file)``;
    other functions are left to numba's own locators.
    """

    class PackageCacheLocator(base):
        """Locates the cached kernels of the covered files; stamp = the state's stamp."""

        def __init__(self, py_func, py_file):
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            self._cache_path = get_state().cache_path(
                py_file, self.get_suitable_cache_subpath(py_file))

        def get_cache_path(self):
            return self._cache_path

        def get_source_stamp(self):
            return get_state().stamp

        def get_disambiguator(self):
            return str(self._lineno)

        @classmethod
        def from_function(cls, py_func, py_file):
            state = get_state()
            if state is None or not state.enabled or not state.covers(py_file):
                return None
            return cls(py_func, py_file)

    return PackageCacheLocator


def disable_caching(covers: Callable[[str], bool]) -> Callable:
    """Make ``cache=True`` a no-op (in-memory compile) for functions of covered files.

    ``covers(py_file)`` says which source files. Returns numba's original
    ``Dispatcher.enable_caching`` (to restore it: ``Dispatcher.enable_caching =
    original``).
    """
    from numba.core.dispatcher import Dispatcher

    original = Dispatcher.enable_caching

    def enable_caching(self):
        try:
            ours = covers(inspect.getfile(self.py_func))
        except TypeError:
            ours = False
        if not ours:
            original(self)

    enable_caching.__doc__ = original.__doc__
    Dispatcher.enable_caching = enable_caching  # type: ignore[method-assign]
    return original
