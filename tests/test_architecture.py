"""The package's floor plan, checked: imports go downhill only, signatures stay short.

Layers, top to bottom: ``tether_gym_agents`` (agents/) -> ``tether_gym.wrappers`` ->
``tether_gym.safety`` -> ``tether_gym.envs`` -> ``tether_gym.tasks`` ->
``tether_gym.physics`` -> ``tether_gym.params``. The safety filter sits above the env
(it predicts the env's step; nothing below may depend on it) and the wrappers above
both. A module may
import its own layer and the layers below it; ``tether_gym`` never imports
``tether_gym_agents``, stable-baselines3 or torch.

Inside ``tether_gym_agents`` the subpackages are ranked (:data:`AGENT_RANKS`, bottom
to top): common < baselines < hybrids < files < evaluation = training < paper < cli.
A module may import its own subpackage and lower-ranked ones; the siblings of one
rank (evaluation, training) may not import each other; the package root
(``agents/__init__.py``) re-exports and may import anything, so nothing imports it.
No two modules of agents/ import each other, directly or around a loop (imports
inside functions count too), and no function anywhere takes more than 10
parameters.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "tether_gym"
LAYERS = ("params", "physics", "tasks", "envs", "safety", "wrappers")
FORBIDDEN_EVERYWHERE = ("tether_gym_agents", "agents", "stable_baselines3", "torch")
MAX_PARAMETERS = 10

AGENTS = ROOT / "agents"
AGENTS_NAME = "tether_gym_agents"
AGENT_RANKS = {"common": 0, "baselines": 1, "hybrids": 2, "files": 3,
               "evaluation": 4, "training": 4, "accel": 4, "paper": 5, "cli": 6}


def _modules():
    return sorted(p for p in PACKAGE.rglob("*.py"))


def _agent_modules():
    return sorted(p for p in AGENTS.rglob("*.py"))


def _layer(path: Path) -> str | None:
    rel = path.relative_to(PACKAGE).parts
    name = rel[0].removesuffix(".py")
    return name if name in LAYERS else None


def _imports(source: str, package: str) -> list[str]:
    """Absolute names of every module imported by ``source`` (a module of ``package``)."""
    return _resolved_imports(source, package, is_package=True, known=set())


def _violations(source: str, package: str, own: str | None) -> list[str]:
    """Imports of a module of layer ``own`` that break the layering."""
    bad = []
    for name in _imports(source, package):
        parts = name.split(".")
        if parts[0] in FORBIDDEN_EVERYWHERE:
            bad.append(name)
        elif parts[0] == "tether_gym" and own is not None and len(parts) > 1 \
                and parts[1] in LAYERS and LAYERS.index(parts[1]) > LAYERS.index(own):
            bad.append(name)
    return bad


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_imports_go_downhill(path):
    package = ".".join(("tether_gym",) + path.relative_to(PACKAGE).parent.parts)
    assert _violations(path.read_text(), package, _layer(path)) == []


def test_the_layering_check_catches_upward_imports():
    """The check is not vacuous: upward and forbidden imports are reported."""
    source = ("from ..envs import config\nfrom ..tasks.reward import COMPONENTS\n"
              "import torch\nfrom stable_baselines3 import PPO\nfrom .state import STATE\n"
              "from ..params import Gravity\n")
    assert _violations(source, "tether_gym.physics", "physics") == [
        "tether_gym.envs", "tether_gym.tasks.reward", "torch", "stable_baselines3"]
    assert _violations(source, "tether_gym.envs", "envs") == ["torch", "stable_baselines3"]


# ---------------------------------------------------------------------------
# tether_gym_agents: subpackage ranks and import cycles
# ---------------------------------------------------------------------------

def _module_name(path: Path) -> tuple[str, bool]:
    """Dotted name of a module of agents/ and whether it is a package (``__init__.py``)."""
    parts = path.relative_to(AGENTS).with_suffix("").parts
    is_package = parts[-1] == "__init__"
    if is_package:
        parts = parts[:-1]
    return ".".join((AGENTS_NAME,) + parts), is_package


def _agent_sources() -> dict[str, tuple[str, bool]]:
    """Every module of agents/: dotted name -> (source, is a package)."""
    out = {}
    for path in _agent_modules():
        name, is_package = _module_name(path)
        out[name] = (path.read_text(), is_package)
    return out


def _resolved_imports(source: str, module: str, is_package: bool,
                      known: set[str]) -> list[str]:
    """Absolute names of the modules ``source`` imports, anywhere in it (functions too).

    ``module`` is the dotted name of the importing module and ``is_package`` says
    whether it is an ``__init__.py`` (its relative imports then start from itself,
    not from its parent). ``from X import name`` counts as an import of ``X.name``
    when that is a module in ``known``, else as an import of ``X``.
    """
    package = module if is_package else module.rpartition(".")[0]
    names = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                if node.level > len(parts):
                    raise ValueError(f"{module}: relative import of level {node.level} "
                                     f"leaves the top-level package {parts[0]}")
                base = ".".join(parts[: len(parts) - node.level + 1])
                origin = f"{base}.{node.module}" if node.module else base
            else:
                origin = node.module or ""
            for alias in node.names:
                child = f"{origin}.{alias.name}"
                names.append(child if child in known else origin)
    return list(dict.fromkeys(names))


def _subpackage(module: str) -> str | None:
    """The subpackage of agents/ a dotted name belongs to (None for the root itself)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def _rank_violations(source: str, module: str, is_package: bool,
                     known: set[str]) -> list[str]:
    """Imports of agents module ``module`` that go up, sideways or to the package root."""
    own = _subpackage(module)
    if own is None:  # the package root re-exports: it may import anything
        return []
    if own not in AGENT_RANKS:
        return [f"{module} is in no ranked subpackage ({', '.join(AGENT_RANKS)})"]
    bad = []
    for name in _resolved_imports(source, module, is_package, known):
        if name.split(".")[0] in ("agents", "stable_baselines3_agents"):
            bad.append(name)
            continue
        if name.split(".")[0] != AGENTS_NAME:
            continue
        other = _subpackage(name)
        if other == own:
            continue
        if other is None:
            bad.append(f"{name} (the package root; import from the defining module)")
        elif other not in AGENT_RANKS or AGENT_RANKS[other] >= AGENT_RANKS[own]:
            bad.append(name)
    return bad


def _import_graph(sources: dict[str, tuple[str, bool]]) -> dict[str, set[str]]:
    """Module -> the modules of ``sources`` it imports."""
    known = set(sources)
    return {name: {n for n in _resolved_imports(src, name, pkg, known)
                   if n in known and n != name}
            for name, (src, pkg) in sources.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


_AGENT_SOURCES = _agent_sources()


@pytest.mark.parametrize("path", _agent_modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_agent_imports_go_down_the_subpackage_ranks(path):
    name, is_package = _module_name(path)
    assert _rank_violations(path.read_text(), name, is_package, set(_AGENT_SOURCES)) == []


def test_no_import_cycle_in_agents():
    cycles = _cycles(_import_graph(_AGENT_SOURCES))
    assert cycles == [], "import cycles among the modules of agents/:\n" + "\n".join(
        " <-> ".join(c) for c in cycles)


def test_agent_modules_are_found_and_named():
    """The checks above see the real tree: modules of every ranked subpackage."""
    names = set(_AGENT_SOURCES)
    assert AGENTS_NAME in names
    for sub in AGENT_RANKS:
        assert f"{AGENTS_NAME}.{sub}" in names, f"agents/{sub}/__init__.py is missing"
    assert len(_import_graph(_AGENT_SOURCES)[AGENTS_NAME]) > 0


_FAKE = {  # a tiny package laid out like agents/, to check the checks
    "tether_gym_agents": ("from .baselines.smc import S\nfrom .cli import main\n", True),
    "tether_gym_agents.common": ("", True),
    "tether_gym_agents.common.obs": ("import numpy as np\nfrom tether_gym.envs import x\n",
                                     False),
    "tether_gym_agents.baselines": ("from .smc import S\n", True),
    "tether_gym_agents.baselines.smc": ("from ..common.obs import L\n"
                                        "from ..common import obs\n", False),
    "tether_gym_agents.hybrids": ("", True),
    "tether_gym_agents.hybrids.policies": (
        "from ..baselines import smc\n"
        "def f():\n    from ..files.trained import T\n", False),
    "tether_gym_agents.files": ("from .trained import T\n", True),
    "tether_gym_agents.files.trained": ("from . import T2\nfrom ..hybrids import policies\n",
                                        False),
    "tether_gym_agents.evaluation": ("from . import rollout\n", True),
    "tether_gym_agents.evaluation.rollout": ("from ..training import fanout\n"
                                             "from .. import SlidingModeController\n"
                                             "from ..paper.table import rows\n", False),
    "tether_gym_agents.training": ("", True),
    "tether_gym_agents.training.fanout": (
        "import tether_gym_agents.evaluation.rollout\nfrom .sweep import run\n", False),
    "tether_gym_agents.training.sweep": ("def g():\n    from .fanout import x\n", False),
    "tether_gym_agents.paper": ("", True),
    "tether_gym_agents.paper.table": ("from ..evaluation import rollout\n", False),
    "tether_gym_agents.cli": ("from ..evaluation.rollout import main\n", True),
    "tether_gym_agents.tools": ("", False),
}


def _fake_violations(name: str) -> list[str]:
    source, is_package = _FAKE[name]
    return _rank_violations(source, name, is_package, set(_FAKE))


def test_relative_imports_resolve_in_modules_and_packages():
    known = set(_FAKE)
    resolve = _resolved_imports
    # a module: "." is its parent package; "from ..common import obs" names a module
    assert resolve(_FAKE["tether_gym_agents.baselines.smc"][0],
                   "tether_gym_agents.baselines.smc", False, known) == [
        "tether_gym_agents.common.obs"]
    # a package (__init__.py): "." is the package itself
    assert resolve("from .smc import S\nfrom . import smc\nfrom .. import common\n",
                   "tether_gym_agents.baselines", True, known) == [
        "tether_gym_agents.baselines.smc", "tether_gym_agents.common"]
    assert resolve("from .baselines.smc import S\nfrom . import files\n",
                   "tether_gym_agents", True, known) == [
        "tether_gym_agents.baselines.smc", "tether_gym_agents.files"]
    # a name that is not a module counts as an import of the package that holds it
    assert resolve("from . import T2\n", "tether_gym_agents.files.trained", False, known) == [
        "tether_gym_agents.files"]
    with pytest.raises(ValueError, match="level 3"):
        resolve("from ... import x\n", "tether_gym_agents.common.obs", False, known)


def test_the_rank_check_catches_upward_sideways_and_root_imports():
    """The check is not vacuous: imports up, between siblings and of the root are reported."""
    assert _fake_violations("tether_gym_agents") == []
    assert _fake_violations("tether_gym_agents.common.obs") == []
    assert _fake_violations("tether_gym_agents.baselines.smc") == []
    assert _fake_violations("tether_gym_agents.hybrids.policies") == [
        "tether_gym_agents.files.trained"]  # inside a function, still counted
    assert _fake_violations("tether_gym_agents.evaluation.rollout") == [
        "tether_gym_agents.training.fanout",
        "tether_gym_agents (the package root; import from the defining module)",
        "tether_gym_agents.paper.table"]
    assert _fake_violations("tether_gym_agents.training.fanout") == [
        "tether_gym_agents.evaluation.rollout"]
    assert _fake_violations("tether_gym_agents.paper.table") == []
    assert _fake_violations("tether_gym_agents.cli") == []
    assert _fake_violations("tether_gym_agents.tools") == [
        "tether_gym_agents.tools is in no ranked subpackage "
        "(common, baselines, hybrids, files, evaluation, training, accel, paper, cli)"]


def test_the_cycle_check_reports_every_cycle():
    """The check is not vacuous: each loop of imports is one component, listed whole."""
    assert _cycles(_import_graph(_FAKE)) == [
        # rollout imports the root, the root imports cli, cli imports rollout
        ["tether_gym_agents", "tether_gym_agents.cli",
         "tether_gym_agents.evaluation.rollout", "tether_gym_agents.paper.table",
         "tether_gym_agents.training.fanout", "tether_gym_agents.training.sweep"],
        ["tether_gym_agents.files", "tether_gym_agents.files.trained",
         "tether_gym_agents.hybrids.policies"],
    ]
    assert _cycles({"a": {"b"}, "b": {"a"}, "c": {"c", "a"}, "d": set()}) == [["a", "b"]]


# ---------------------------------------------------------------------------
# Short signatures, in tether_gym and agents/
# ---------------------------------------------------------------------------

def _long_signatures(source: str) -> list[str]:
    """Functions of ``source`` with more than MAX_PARAMETERS parameters (self/cls not counted)."""
    bad = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            a = node.args
            params = [*a.posonlyargs, *a.args, *a.kwonlyargs]
            count = len(params) + bool(a.vararg) + bool(a.kwarg)
            if params and params[0].arg in ("self", "cls"):
                count -= 1
            if count > MAX_PARAMETERS:
                bad.append((node.lineno, f"{node.lineno} {node.name} takes {count}"))
    return [text for _, text in sorted(bad)]


@pytest.mark.parametrize("path", _modules() + _agent_modules(),
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_no_function_takes_more_than_ten_parameters(path):
    """Named records, not long positional lists (self and cls not counted)."""
    assert _long_signatures(path.read_text()) == [], path.name


def test_the_parameter_check_catches_long_signatures():
    """The check is not vacuous: 11 parameters are reported, 10 (+ self) are not."""
    ten = ", ".join(f"a{i}" for i in range(10))
    source = (f"def ok({ten}): pass\n"
              f"def bad({ten}, b): pass\n"
              f"class C:\n    def m(self, {ten}): pass\n"
              f"    def n(self, {ten}, *rest): pass\n"
              f"async def k(*, {ten}, **kw): pass\n"
              f"def outer():\n    def inner(x, /, {ten}): pass\n")
    assert _long_signatures(source) == [
        "2 bad takes 11", "5 n takes 11", "6 k takes 11", "8 inner takes 11"]
