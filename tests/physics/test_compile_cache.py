"""The numba cache of tether_gym's kernels: never stale, read-only installs, messages."""

from __future__ import annotations

import io
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from contextlib import redirect_stdout
from types import SimpleNamespace

import numpy as np
import pytest

import tether_gym
from tether_gym.physics import compile_cache, jit
from tether_gym.physics.compile_cache import (
    CacheState,
    _CompileAnnouncer,
    find_cache_dir,
    source_stamp,
    writable,
)

PACKAGE = os.path.dirname(os.path.abspath(tether_gym.__file__))

# one trajectory of the single env through gym.make, printed as JSON
TRAJECTORY = """
import json, gymnasium as gym, numpy as np, tether_gym
env = gym.make("tether_gym/TetherLibration-v2")
obs, _ = env.reset(seed=3)
for k in range(5):
    obs, *_ = env.step(np.full(env.action_space.shape, 0.5 - 0.2 * k, dtype=np.float32))
print(json.dumps({"file": tether_gym.__file__, "obs": obs.tolist()}))
"""

# a line of the physics every env step runs: the linearised gravity term of the default
# "gradient" model (kernels.py); the test edits its coefficient
PHYSICS_LINE = re.compile(r"(V\[5, i\] = )2\.0( \* rr / k)")


def a_kernel():
    """The Python function of one compiled kernel of physics/kernels.py."""
    from tether_gym.physics import kernels

    return next(v.py_func for v in vars(kernels).values() if hasattr(v, "py_func"))


def make_package(root, files: dict[str, str]) -> str:
    for rel, text in files.items():
        path = os.path.join(root, rel)
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, "w") as f:
            f.write(text)
    return str(root)


# ---------------------------------------------------------------------- key
def test_stamp_changes_with_any_source_file_and_the_version(tmp_path):
    pkg = make_package(tmp_path / "pkg", {"__init__.py": "x = 1\n", "sub/a.py": "y = 2\n",
                                          "sub/data.txt": "not source\n"})
    stamp = source_stamp(pkg, "1.0")
    assert stamp == source_stamp(pkg, "1.0")  # deterministic
    assert source_stamp(pkg, "1.1") != stamp  # upgrade / downgrade
    # compiled files and non-source files do not count
    make_package(pkg, {"sub/__pycache__/a.py": "junk\n", "sub/data.txt": "changed\n"})
    assert source_stamp(pkg, "1.0") == stamp
    for rel, text in (("sub/a.py", "y = 3\n"), ("sub/b.py", ""), ("__init__.py", "x = 1 \n")):
        before = open(os.path.join(pkg, rel)).read() if os.path.exists(
            os.path.join(pkg, rel)) else None
        make_package(pkg, {rel: text})
        assert source_stamp(pkg, "1.0") != stamp, rel
        if before is None:
            os.remove(os.path.join(pkg, rel))
        else:
            make_package(pkg, {rel: before})
        assert source_stamp(pkg, "1.0") == stamp, rel
    os.rename(os.path.join(pkg, "sub", "a.py"), os.path.join(pkg, "sub", "c.py"))
    assert source_stamp(pkg, "1.0") != stamp  # a moved file


# what a fresh process installs for a package: its stamp, the package's source stamp, and
# the stamp its locator gives a kernel (printed as JSON)
INSTALLED_STAMPS = """
import json, os, tether_gym
from numba.core import caching
from tether_gym.physics import compile_cache, jit, kernels
impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
func = next(v.py_func for v in vars(kernels).values() if hasattr(v, "py_func"))
locator = impl._locator_classes[0].from_function(func, func.__code__.co_filename)
package = os.path.dirname(tether_gym.__file__)
print(json.dumps([jit.CACHE.stamp, compile_cache.source_stamp(package, tether_gym.__version__),
                  locator.get_source_stamp(), tether_gym.__file__]))
"""


def test_installed_locator_keys_package_files_on_the_package_stamp(tmp_path):
    """The installed locator gives the package's kernels the install's stamp, and that
    stamp is the source stamp of the package the process imported.

    The second part runs in a fresh process over a copy of the package that nothing
    edits: the stamp is taken once per process, at import, so a hash of this working
    tree taken when this test runs (minutes later in a full run) differs from it as soon
    as any package file was edited meanwhile, e.g. by another session working in the same
    tree (a full run failed here that way).
    """
    from numba.core import caching

    state = jit.CACHE
    assert state is compile_cache.state()
    assert re.fullmatch(r"[0-9a-f]{64}", state.stamp)
    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
    locator_cls = impl._locator_classes[0]
    assert locator_cls.__name__ == "PackageCacheLocator"
    func = a_kernel()
    py_file = func.__code__.co_filename
    if state.enabled:
        locator = locator_cls.from_function(func, py_file)
        assert locator.get_source_stamp() == state.stamp
        assert locator.get_cache_path().startswith(
            os.path.dirname(py_file) if state.kind == "package" else state.root)
    # files outside the package keep numba's own locators
    assert locator_cls.from_function(test_stamp_changes_with_any_source_file_and_the_version,
                                     __file__) is None
    root = copy_package(tmp_path / "copy")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update({"PYTHONPATH": root, "NUMBA_CACHE_DIR": str(tmp_path / "numba")})
    out = subprocess.run([sys.executable, "-c", INSTALLED_STAMPS], cwd=root, env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    installed, package, located, init = json.loads(out.stdout.strip().splitlines()[-1])
    assert init == os.path.join(root, "tether_gym", "__init__.py")
    assert installed == package == located


# ---------------------------------------------------------------------- place
def test_cache_dir_order_and_fallbacks(tmp_path):
    pkg = make_package(tmp_path / "pkg", {"__init__.py": "", "sub/a.py": ""})
    blocker = tmp_path / "a_file"
    blocker.write_text("a regular file: nothing can be created below it, even by root\n")
    numba_dir = str(tmp_path / "numba")
    env = {"NUMBA_CACHE_DIR": numba_dir, "HOME": str(tmp_path / "home")}
    assert find_cache_dir(pkg, env)[:2] == ("NUMBA_CACHE_DIR", numba_dir)
    env["NUMBA_CACHE_DIR"] = str(blocker / "numba")
    kind, root, tried = find_cache_dir(pkg, env)
    assert (kind, root) == ("package", pkg)
    assert os.path.isdir(os.path.join(pkg, "sub", "__pycache__"))
    assert tried == [str(blocker / "numba"), os.path.join(pkg, "__pycache__")]
    # a subpackage whose __pycache__ cannot be made disqualifies the package
    shutil.rmtree(os.path.join(pkg, "sub", "__pycache__"))
    (tmp_path / "pkg" / "sub" / "__pycache__").write_text("")
    kind, root, _ = find_cache_dir(pkg, env)
    assert (kind, root) == ("user", str(tmp_path / "home" / ".cache" / "tether_gym"))
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg")
    assert find_cache_dir(pkg, env)[1] == str(tmp_path / "xdg" / "tether_gym")
    env["XDG_CACHE_HOME"] = str(blocker / "xdg")
    kind, root, tried = find_cache_dir(pkg, env)
    assert (kind, root) == (None, None)
    assert tried[-1] == str(blocker / "xdg" / "tether_gym")
    assert writable(str(tmp_path / "new" / "dir")) and not writable(str(blocker / "x"))


def test_a_user_locator_override_is_warned_about():
    """NUMBA_CACHE_LOCATOR_CLASSES bypasses the package-wide key: say so (import only)."""
    env = {**os.environ, "NUMBA_CACHE_LOCATOR_CLASSES": "InTreeCacheLocator"}
    out = subprocess.run([sys.executable, "-c", "import tether_gym.physics"], env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stderr.count("CompileCacheWarning") == 1
    assert "NUMBA_CACHE_LOCATOR_CLASSES is set" in out.stderr


# ---------------------------------------------------------------------- message
def fake_event(func, start: bool):
    dispatcher = SimpleNamespace(py_func=func)
    return SimpleNamespace(data={"dispatcher": dispatcher}, is_start=start, is_end=not start)


def test_compile_message_around_each_burst_of_package_compiles():
    ours = a_kernel()
    state = CacheState(PACKAGE, "stamp", "package", PACKAGE, [])
    out = io.StringIO()
    announcer = _CompileAnnouncer(state, stream=out)
    # a user's function compiling (not ours): nothing
    announcer.on_start(fake_event(test_cache_dir_order_and_fallbacks, True))
    announcer.on_end(fake_event(test_cache_dir_order_and_fallbacks, False))
    assert out.getvalue() == ""
    # a kernel compiling two helpers inside it: one start line, one done line
    for start in (True, True, False, True, False, False):
        (announcer.on_start if start else announcer.on_end)(fake_event(ours, start))
    lines = out.getvalue().splitlines()
    assert len(lines) == 2
    assert lines[0].startswith("tether_gym: compiling the physics kernels (once per install")
    assert re.fullmatch(r"tether_gym: \.\.\. done in \d+\.\d s", lines[1])
    # a later burst says "more"
    announcer.on_start(fake_event(ours, True))
    announcer.on_end(fake_event(ours, False))
    assert out.getvalue().splitlines()[2] == "tether_gym: compiling more kernels ..."
    off = io.StringIO()
    _CompileAnnouncer(CacheState(PACKAGE, "s", None, None, []), stream=off).on_start(
        fake_event(ours, True))
    assert "caching is off" in off.getvalue()


# ---------------------------------------------------------------------- end to end
def copy_package(dest) -> str:
    """A copy of the package source (no compiled files) under ``dest``; its path."""
    shutil.copytree(PACKAGE, os.path.join(dest, "tether_gym"),
                    ignore=shutil.ignore_patterns("__pycache__"))
    return str(dest)


def run_trajectory(root: str, env_extra=None):
    env = {k: v for k, v in os.environ.items()
           if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME", "PYTHONPATH")}
    env.update({"PYTHONPATH": root, "NUMBA_NUM_THREADS": "1", **(env_extra or {})})
    out = subprocess.run([sys.executable, "-c", TRAJECTORY], cwd=root, env=env,
                         capture_output=True, text=True, timeout=1200)
    if out.returncode != 0:
        raise AssertionError(f"subprocess failed ({out.returncode}):\n{out.stderr}")
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["file"] == os.path.join(root, "tether_gym", "__init__.py")
    return result["obs"], out.stderr


@pytest.mark.slow  # 4 subprocesses, 3 of them compile the env kernels cold (~1-3 min)
def test_an_edited_helper_reaches_the_env_with_a_warm_cache(tmp_path):
    """Edit a physics line inlined into the env's step kernel, then revert it: each
    time the next run uses the source as it is (numba's own key missed both)."""
    root = copy_package(tmp_path)
    cold, err = run_trajectory(root)
    assert "tether_gym: compiling the physics kernels" in err
    warm, err = run_trajectory(root)
    assert warm == cold
    assert "compiling" not in err  # a warm cache compiles nothing, says nothing
    kernels_py = os.path.join(root, "tether_gym", "physics", "kernels.py")
    with open(kernels_py) as f:
        source = f.read()
    edited, count = PHYSICS_LINE.subn(r"\g<1>2.5\g<2>", source)
    assert count == 1, "kernels.py changed: point PHYSICS_LINE at a line the env runs"
    with open(kernels_py, "w") as f:
        f.write(edited)
    changed, err = run_trajectory(root)
    assert "compiling" in err
    assert not np.allclose(changed, cold, rtol=1e-6, atol=0)
    with open(kernels_py, "w") as f:
        f.write(source)
    reverted, _ = run_trajectory(root)
    assert reverted == cold


def make_uncacheable(top: str, package: str) -> list[str]:
    """Leave no place under ``top`` where this process could write a cache; the
    regular files it planted (for any user, root included, and on any machine).

    The copy becomes read-only (mode 555 / 444). Permission bits bind an ordinary user
    but not root (nor a process with CAP_DAC_OVERRIDE): when this process can still
    create a directory in the copy, every source directory of the package gets a regular
    *file* named ``__pycache__``, where nobody can create the cache directory (nor
    Python its bytecode).
    """
    for dirpath, _dirs, files in os.walk(top):
        os.chmod(dirpath, 0o555)  # readable and traversable by anyone, not writable
        for name in files:
            os.chmod(os.path.join(dirpath, name), 0o444)
    probe = os.path.join(package, "__pycache__")
    try:
        os.mkdir(probe)
    except OSError:
        return []  # the bits bind this process: the copy is read-only for it
    os.rmdir(probe)
    planted = []
    for dirpath, dirs, files in os.walk(package):
        dirs[:] = [d for d in dirs if not d.startswith(".")]
        if any(name.endswith(".py") for name in files):
            path = os.path.join(dirpath, "__pycache__")
            with open(path, "w"):
                pass
            planted.append(path)
    return planted


@pytest.mark.slow  # 1 subprocess compiling the env kernels in memory (~20-60 s)
def test_read_only_install_compiles_in_memory_with_one_warning():
    """A package copy where no cache can be written (read-only, or blocked by files where
    permission bits do not bind, as for root), and a HOME under a regular file: the env
    runs with the kernels compiled in memory, one warning, nothing written, and the
    trajectory of an install with a cache.

    Run as the current user with this interpreter, so it holds wherever the tests run
    (it ran the copy as uid 65534 before, which fails where that user cannot enter the
    interpreter's directory, e.g. a pyenv Python under /root).
    """
    top = tempfile.mkdtemp(prefix="tether_gym_ro_")
    try:
        root = copy_package(top)
        blocker = os.path.join(top, "a_file")
        with open(blocker, "w") as f:
            f.write("a regular file: nothing can be created below it, even by root\n")
        planted = make_uncacheable(top, os.path.join(root, "tether_gym"))
        obs, err = run_trajectory(root, env_extra={
            "HOME": os.path.join(blocker, "home"),
            "XDG_CACHE_HOME": os.path.join(blocker, "xdg")})
        assert err.count("CompileCacheWarning") == 1, err
        assert "no writable cache directory" in err and "NUMBA_CACHE_DIR" in err
        assert "caching is off" in err
        written = [d for d, _, _ in os.walk(top) if d.endswith("__pycache__")]
        assert written == []
        assert all(os.path.isfile(p) and os.path.getsize(p) == 0 for p in planted)
        # the same trajectory as this process computes with its own cache
        namespace: dict = {}
        buffer = io.StringIO()
        with redirect_stdout(buffer):
            exec(compile(TRAJECTORY, "<trajectory>", "exec"), namespace)
        assert json.loads(buffer.getvalue())["obs"] == obs
    finally:
        for dirpath, _dirs, _files in os.walk(top):
            os.chmod(dirpath, 0o755)
        shutil.rmtree(top, ignore_errors=True)
