"""The package's floor plan, checked: imports go downhill only, signatures stay short.

Layers, top to bottom: ``tether_gym_agents`` (agents/) -> ``tether_gym.wrappers`` ->
``tether_gym.safety`` -> ``tether_gym.envs`` -> ``tether_gym.tasks`` ->
``tether_gym.physics`` -> ``tether_gym.params``. The safety filter sits above the env
(it predicts the env's step; nothing below may depend on it) and the wrappers above
both. A module may
import its own layer and the layers below it; ``tether_gym`` never imports
``tether_gym_agents``, stable-baselines3 or torch.
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


def _modules():
    return sorted(p for p in PACKAGE.rglob("*.py"))


def _layer(path: Path) -> str | None:
    rel = path.relative_to(PACKAGE).parts
    name = rel[0].removesuffix(".py")
    return name if name in LAYERS else None


def _imports(source: str, package: str) -> list[str]:
    """Absolute names of every module imported by ``source`` (a module of ``package``)."""
    names = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = parts[: len(parts) - node.level + 1]
                names.append(".".join(base + ([node.module] if node.module else [])))
            else:
                names.append(node.module or "")
    return names


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


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_function_takes_more_than_ten_parameters(path):
    """Named records, not long positional lists (self and cls not counted)."""
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            a = node.args
            params = [*a.posonlyargs, *a.args, *a.kwonlyargs]
            count = len(params) + bool(a.vararg) + bool(a.kwarg)
            if params and params[0].arg in ("self", "cls"):
                count -= 1
            assert count <= MAX_PARAMETERS, f"{path.name}:{node.lineno} {node.name} takes {count}"
