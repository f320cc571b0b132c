"""numba's private API that tether_gym uses still exists and still works.

Each item of :mod:`tether_gym.physics.numba_private` is checked against the installed
numba. A failure here means that numba changed it: tether_gym then runs slower or
compiles in memory (or, for ``_nrt``, does not import), so fix the item in
``numba_private.py`` before raising numba's upper bound in ``pyproject.toml``.
"""

from __future__ import annotations

import importlib.util
import os
import sys
import textwrap
from types import SimpleNamespace

import numba
import numpy as np
import pytest
from numba import njit
from numba.core import caching
from numba.core.dispatcher import Dispatcher

from tether_gym.physics import numba_private
from tether_gym.physics.numba_private import (
    NO_NRT,
    cache_internals,
    disable_caching,
    entry_point,
    make_locator,
)

CHANGED = (f"numba {numba.__version__} changed a private API that tether_gym uses "
           "(tether_gym/physics/numba_private.py, item {item}): {what}")


def changed(item: int, what: str) -> str:
    """The failure message for item ``item`` of numba_private's docstring."""
    return CHANGED.format(item=item, what=what)


def view_sum(a):
    """Sum of a[1:] through a view (numba binds the view: NRT would count it)."""
    total = 0.0
    b = a[1:]
    for i in range(b.shape[0]):
        total += b[i]
    return total


# ---------------------------------------------------------------- 1. _nrt=False
def test_no_nrt_option_is_accepted_and_removes_reference_counting():
    try:
        plain, no_nrt = njit(view_sum), njit(**NO_NRT)(view_sum)
        a = np.arange(6.0)
        assert no_nrt(a) == plain(a) == 15.0
    except Exception as exc:  # noqa: BLE001 - any error here means the option changed
        pytest.fail(changed(1, f"njit(_nrt=False) no longer compiles: {exc!r}"))
    with_nrt = "".join(plain.inspect_llvm().values())
    without = "".join(no_nrt.inspect_llvm().values())
    assert "NRT_decref" in with_nrt, changed(1, "a view no longer emits NRT_decref "
                                             "(this test's premise, not the option, moved)")
    assert "NRT_decref" not in without, changed(1, "_nrt=False still emits NRT_decref")


# ---------------------------------------------------------------- 2. entry point
def test_entry_point_of_a_compiled_signature_computes_the_same():
    f = njit(view_sum)
    a = np.arange(4.0)
    assert entry_point(f, (a,)) is None  # not compiled yet
    expected = f(a)
    assert hasattr(Dispatcher, "typeof_pyval"), changed(2, "Dispatcher.typeof_pyval is gone")
    assert isinstance(getattr(f, "overloads", None), dict), changed(
        2, "Dispatcher.overloads is no longer a dict of compiled signatures")
    entry = entry_point(f, (a,))
    assert entry is not None, changed(
        2, "Dispatcher.overloads[signature].entry_point no longer gives the compiled function")
    assert entry(a) == expected


def test_direct_calls_the_entry_point_after_the_first_call():
    from tether_gym.physics.dispatch import Direct

    f = njit(view_sum)
    direct = Direct(f)
    a = np.arange(5.0)
    assert direct(a) == direct(a) == 10.0
    assert direct._entry is not f, changed(2, "Direct fell back to the dispatcher")


# ---------------------------------------------------------------- 3. cache locators
def test_cache_internals_exist():
    internals, why = cache_internals()
    assert internals is not None, changed(3, why)
    base, classes = internals
    assert base is caching._CacheLocator
    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
    assert classes is impl._locator_classes
    for name in ("from_function", "get_cache_path", "get_source_stamp", "get_disambiguator",
                 "get_suitable_cache_subpath"):
        assert hasattr(base, name), changed(3, f"_CacheLocator.{name} is gone")


def test_installed_package_locator_is_asked_first():
    import tether_gym.physics.jit  # noqa: F401 - installs the package locator

    (_, classes), _ = cache_internals()
    assert classes[0].__name__ == "PackageCacheLocator"


def write_module(folder, name: str) -> str:
    """A module file with one ``cache=True`` function ``f``; its path."""
    path = os.path.join(folder, f"{name}.py")
    with open(path, "w") as f:
        f.write(textwrap.dedent("""
            from numba import njit

            @njit(cache=True)
            def f(x):
                return 2.0 * x + 1.0
            """))
    return path


def import_file(path: str, name: str):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def fake_state(folder, cache_dir: str, stamp: str = "stamp-1"):
    """What make_locator needs of a CacheState: cover ``folder``, cache in ``cache_dir``."""
    prefix = os.path.realpath(folder) + os.sep
    return SimpleNamespace(enabled=True, stamp=stamp,
                           covers=lambda py_file: os.path.realpath(py_file).startswith(prefix),
                           cache_path=lambda py_file, subpath: cache_dir)


def test_a_locator_built_on_numbas_base_stores_and_reloads_under_our_stamp(tmp_path):
    (base, classes), _ = cache_internals()
    src, cache_dir = tmp_path / "src", str(tmp_path / "cache")
    src.mkdir()
    current = {"state": fake_state(src, cache_dir)}
    locator = make_locator(base, lambda: current["state"])
    classes.insert(0, locator)
    name = "tg_numba_private_probe"
    try:
        module = import_file(write_module(str(src), name), name)
        assert module.f(1.0) == 3.0
        files = os.listdir(cache_dir) if os.path.isdir(cache_dir) else []
        assert any(f.endswith(".nbi") for f in files), changed(
            3, f"numba did not write through the inserted locator (found {files})")
        again = njit(cache=True)(module.f.py_func)  # a new dispatcher, same function
        assert again(1.0) == 3.0
        assert sum(again.stats.cache_hits.values()) == 1, changed(
            3, "numba did not load from the inserted locator's cache")
        current["state"] = fake_state(src, cache_dir, stamp="stamp-2")  # a source change
        third = njit(cache=True)(module.f.py_func)
        assert third(1.0) == 3.0
        assert sum(third.stats.cache_hits.values()) == 0, changed(
            3, "numba no longer keys the cache on the locator's get_source_stamp")
    finally:
        classes.remove(locator)
        sys.modules.pop(name, None)


# ---------------------------------------------------------------- 4. enable_caching
def test_disable_caching_compiles_covered_files_in_memory(tmp_path):
    (base, classes), _ = cache_internals()
    src, cache_dir = tmp_path / "src", str(tmp_path / "cache")
    src.mkdir()
    state = fake_state(src, cache_dir)
    locator = make_locator(base, lambda: state)
    classes.insert(0, locator)
    original = disable_caching(state.covers)
    name = "tg_numba_private_off"
    try:
        module = import_file(write_module(str(src), name), name)
        assert module.f(2.0) == 5.0
        assert not os.path.exists(cache_dir), changed(
            4, "replacing Dispatcher.enable_caching no longer turns cache=True off")
        outside = njit(cache=True)(view_sum)  # a file not covered keeps numba's cache
        assert outside._cache.__class__.__name__ != "NullCache"
    finally:
        Dispatcher.enable_caching = original  # type: ignore[method-assign]
        classes.remove(locator)
        sys.modules.pop(name, None)


def test_every_item_is_exported():
    assert set(numba_private.__all__) == {"NO_NRT", "entry_point", "cache_internals",
                                          "make_locator", "disable_caching"}
