"""numba's on-disk cache for tether_gym's kernels, keyed on the whole package source.

numba keys a cached function on its own source file only, but tether_gym's step kernels
inline helpers from other files (``physics/kernels.py``, ``tasks/reward.py``, ...): with
numba's own key an edited helper, or a package upgrade over an older cache, would keep
running the old compiled code. :func:`install` (called once by
:mod:`tether_gym.physics.jit`, before any kernel is decorated) changes that for every
function compiled with ``cache=True`` in a file of the tether_gym package:

* **Key.** The source stamp of every such function is :func:`source_stamp`: a sha256 of
  every ``.py`` file of the package (paths and contents) and ``tether_gym.__version__``.
  Any edit of any package source, and any upgrade or downgrade, invalidates every cached
  kernel; numba then recompiles and overwrites the cache files. The source is hashed
  once per process.
* **Place.** The first writable one of: ``NUMBA_CACHE_DIR`` (if set), the package's own
  ``__pycache__`` directories, ``$XDG_CACHE_HOME/tether_gym`` (default
  ``~/.cache/tether_gym``). Writability is tested by creating a file (permission bits
  say nothing for root).
* **No writable place** (a read-only install for a user without a writable home): the
  kernels are compiled in memory by every process, with one :class:`CompileCacheWarning`
  saying how to enable the cache.
* **Cold cache.** When a kernel of the package is compiled (numba found no valid cache
  entry), one line goes to stderr before the compile and one with its duration after it.
  A warm cache compiles nothing and prints nothing.

The mechanism uses numba's cache internals, all reached through
:mod:`tether_gym.physics.numba_private` (which lists them), and the public event API
``numba.core.event``. If the internals are missing, the kernels are compiled in memory
with a :class:`CompileCacheWarning` instead of risking a stale cache.
"""

from __future__ import annotations

import hashlib
import inspect
import os
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass

from numba.core import event

from . import numba_private

__all__ = ["CompileCacheWarning", "CacheState", "install", "state", "source_stamp",
           "find_cache_dir", "writable"]

PACKAGE_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
"""The tether_gym package directory (the one holding ``__init__.py``)."""

COMPILE_HINT = "~5-10 s on an idle core"
"""How long a cold compile of the env kernels takes (shown in the compile message)."""


class CompileCacheWarning(UserWarning):
    """The compiled kernels cannot be cached (they are compiled in memory every run)."""


def source_stamp(package_dir: str, version: str) -> str:
    """sha256 (hex) of every ``.py`` file under ``package_dir`` and of ``version``.

    Files are visited in sorted order of their path relative to ``package_dir``
    (``__pycache__`` and hidden directories skipped); each path and its length-prefixed
    content enter the hash, so a moved, added, removed or edited file changes the stamp.
    """
    digest = hashlib.sha256()
    digest.update(f"tether_gym {version}\0".encode())
    for dirpath, dirnames, filenames in os.walk(package_dir):
        dirnames[:] = sorted(d for d in dirnames
                             if d != "__pycache__" and not d.startswith("."))
        for name in sorted(filenames):
            if not name.endswith(".py"):
                continue
            path = os.path.join(dirpath, name)
            with open(path, "rb") as f:
                data = f.read()
            rel = os.path.relpath(path, package_dir).replace(os.sep, "/")
            digest.update(f"{rel}\0{len(data)}\0".encode())
            digest.update(data)
    return digest.hexdigest()


def writable(directory: str) -> bool:
    """True if ``directory`` exists or can be created and a file can be created in it."""
    try:
        os.makedirs(directory, exist_ok=True)
        tempfile.TemporaryFile(dir=directory).close()
    except OSError:
        return False
    return True


def _source_dirs(package_dir: str) -> list[str]:
    """The directories of the package that hold ``.py`` files."""
    dirs = []
    for dirpath, dirnames, filenames in os.walk(package_dir):
        dirnames[:] = [d for d in dirnames if d != "__pycache__" and not d.startswith(".")]
        if any(name.endswith(".py") for name in filenames):
            dirs.append(dirpath)
    return dirs


def find_cache_dir(package_dir: str, environ=None) -> tuple[str | None, str | None, list[str]]:
    """Where to cache: ``(kind, root, tried)``.

    ``kind`` is ``"NUMBA_CACHE_DIR"``, ``"package"`` (each source directory's
    ``__pycache__``, ``root`` is then ``package_dir``), ``"user"`` or None when no
    candidate is writable; ``tried`` lists the candidates in the order they were tested.
    """
    env = os.environ if environ is None else environ
    tried = []
    numba_dir = env.get("NUMBA_CACHE_DIR", "")
    if numba_dir:
        tried.append(numba_dir)
        if writable(numba_dir):
            return "NUMBA_CACHE_DIR", numba_dir, tried
    tried.append(os.path.join(package_dir, "__pycache__"))
    if all(writable(os.path.join(d, "__pycache__")) for d in _source_dirs(package_dir)):
        return "package", package_dir, tried
    xdg = env.get("XDG_CACHE_HOME", "")
    if xdg and os.path.isabs(xdg):
        user_dir = os.path.join(xdg, "tether_gym")
    else:
        home = env.get("HOME") or os.path.expanduser("~")
        user_dir = os.path.join(home, ".cache", "tether_gym")
    tried.append(user_dir)
    if writable(user_dir):
        return "user", user_dir, tried
    return None, None, tried


@dataclass
class CacheState:
    """What :func:`install` decided (see :func:`state`)."""

    package_dir: str
    """The package whose files are covered."""
    stamp: str
    """:func:`source_stamp` of the package (the key of every cached kernel)."""
    kind: str | None
    """``"NUMBA_CACHE_DIR"``, ``"package"``, ``"user"`` or None (compiled in memory)."""
    root: str | None
    """The cache directory (``package_dir`` for ``"package"``), None when off."""
    tried: list[str]
    """The candidate directories tested, in order."""
    reason: str = ""
    """Why caching is off, when it is."""

    @property
    def enabled(self) -> bool:
        """True when the kernels are cached on disk."""
        return self.root is not None

    def covers(self, py_file: str) -> bool:
        """True for a file inside the package."""
        try:
            path = os.path.realpath(py_file)
        except (TypeError, ValueError):
            return False
        return path.startswith(os.path.realpath(self.package_dir) + os.sep)

    def cache_path(self, py_file: str, subpath: str) -> str:
        """The directory holding the cache files of the functions of ``py_file``."""
        if self.kind == "package":
            return os.path.join(os.path.dirname(os.path.abspath(py_file)), "__pycache__")
        return os.path.join(str(self.root), subpath)


_STATE: CacheState | None = None


def state() -> CacheState | None:
    """The decision of :func:`install` (None before it ran)."""
    return _STATE


class _CompileAnnouncer(event.Listener):
    """numba ``"numba:compile"`` listener: a line on stderr around each compile burst.

    A burst is an outermost compile of a package function (the functions it pulls in
    compile inside it). numba broadcasts the event only on a real compile, after the
    cache lookup failed, so a warm cache prints nothing.
    """

    def __init__(self, state_: CacheState, stream=None):
        self._state = state_
        self._stream = stream
        self._depth = 0
        self._start = 0.0
        self._bursts = 0

    def _ours(self, ev) -> bool:
        data = ev.data if isinstance(ev.data, dict) else {}
        func = getattr(data.get("dispatcher"), "py_func", None)
        try:
            return func is not None and self._state.covers(inspect.getfile(func))
        except TypeError:
            return False

    def _print(self, text: str) -> None:
        print(text, file=self._stream if self._stream is not None else sys.stderr,
              flush=True)

    def on_start(self, ev) -> None:
        if not self._ours(ev):
            return
        self._depth += 1
        if self._depth > 1:
            return
        self._start = time.perf_counter()
        self._bursts += 1
        if self._bursts > 1:
            self._print("tether_gym: compiling more kernels ...")
            return
        why = ("once per install and source change" if self._state.enabled
               else "caching is off: every run")
        self._print(f"tether_gym: compiling the physics kernels ({why}, {COMPILE_HINT}) ...")

    def on_end(self, ev) -> None:
        if not self._ours(ev):
            return
        self._depth -= 1
        if self._depth == 0:
            self._print(f"tether_gym: ... done in {time.perf_counter() - self._start:.1f} s")


def install(package_dir: str = PACKAGE_DIR, version: str | None = None) -> CacheState:
    """Route the package's ``cache=True`` kernels through the package-wide key (once).

    Returns the :class:`CacheState`; later calls return the first one. Emits one
    :class:`CompileCacheWarning` when no cache directory is writable or numba lacks the
    internals used.
    """
    global _STATE
    if _STATE is not None:
        return _STATE
    if version is None:
        from .. import __version__ as version
    stamp = source_stamp(package_dir, str(version))
    internals, reason = numba_private.cache_internals()
    kind = root = None
    tried: list[str] = []
    if internals is not None:
        kind, root, tried = find_cache_dir(package_dir)
        if kind is None:
            reason = ("no writable cache directory (tried " + ", ".join(tried)
                      + ", the last from XDG_CACHE_HOME or HOME)")
    _STATE = CacheState(package_dir, stamp, kind, root, tried, reason)
    if internals is not None:
        base, classes = internals
        classes.insert(0, numba_private.make_locator(base, state))
    if not _STATE.enabled:
        numba_private.disable_caching(_STATE.covers)
        fix = ("set the environment variable NUMBA_CACHE_DIR to a writable directory"
               if internals is not None else "use numba 0.59 to 0.68")
        warnings.warn(
            f"tether_gym: {reason}; its numba kernels are compiled in memory by every "
            f"process ({COMPILE_HINT} each time). To cache them, {fix}.",
            CompileCacheWarning, stacklevel=2)
    elif os.environ.get("NUMBA_CACHE_LOCATOR_CLASSES"):
        warnings.warn(
            "tether_gym: NUMBA_CACHE_LOCATOR_CLASSES is set, so numba caches tether_gym's "
            "kernels with those locators, keyed on each function's own file: after an "
            "edit of a helper that a kernel inlines from another file, or an upgrade, a "
            "stale compiled kernel can run. Unset it to key them on the package source.",
            CompileCacheWarning, stacklevel=2)
    event.register("numba:compile", _CompileAnnouncer(_STATE))
    return _STATE
