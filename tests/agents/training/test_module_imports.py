"""No import cycle among the modules of agents/training and agents/files (an AST check,
function-level imports included), and files never imports training."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

AGENTS = Path(__file__).resolve().parents[3] / "agents"
PACKAGES = ("training", "files")


def _module_name(path: Path) -> str:
    rel = path.relative_to(AGENTS).with_suffix("")
    parts = [p for p in rel.parts if p != "__init__"]
    return ".".join(parts)


def _imports(path: Path) -> set[str]:
    """Modules of agents/ that ``path`` imports (``training.run``, ``files``, ...)."""
    package = _module_name(path).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            base = package[: len(package) - node.level + 1]
            target = ".".join(base + ([node.module] if node.module else []))
            found.add(target)
            found.update(f"{target}.{a.name}" for a in node.names)  # from . import run
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith(
                "tether_gym_agents."):
            found.add(node.module.removeprefix("tether_gym_agents."))
    return found


def _graph() -> dict[str, set[str]]:
    paths = [p for pkg in PACKAGES for p in (AGENTS / pkg).glob("*.py")]
    names = {_module_name(p) for p in paths}
    return {_module_name(p): {m for m in _imports(p) if m in names} - {_module_name(p)}
            for p in paths}


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}

    def visit(node, stack):
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt] if nxt in stack else [node, nxt]
            if nxt not in state:
                found = visit(nxt, stack + [nxt])
                if found:
                    return found
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node, [node])
            if found:
                return found
    return None


def test_no_import_cycle():
    graph = _graph()
    assert "training.fanout" in graph["training.sweep"]  # the graph is not empty
    assert "training.settings" in graph["training.run"]
    assert _cycle(graph) is None


@pytest.mark.parametrize("module", ["training.settings", "training.run", "training.fanout"])
def test_lower_modules_never_import_upper_ones(module):
    order = ["training.settings", "training.run", "training.fanout", "training.sweep",
             "training.train"]
    upper = set(order[order.index(module) + 1:])
    assert not _graph()[module] & upper


def test_files_never_import_training():
    graph = _graph()
    assert not any(dep.startswith("training") for mod, deps in graph.items()
                   if mod.startswith("files") for dep in deps)


def test_the_cycle_check_finds_a_cycle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None
