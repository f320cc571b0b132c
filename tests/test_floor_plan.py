"""docs/architecture.md's diagram is the one list of the modules, and it is complete.

The package docstrings and the README name the subpackages and link to the diagram
instead of listing modules (five lists drifted apart before). Every module of
``tether_gym`` and ``tether_gym_agents`` must be named in the diagram's section of its
own (sub)package, so a module added without a line there fails here.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ARCHITECTURE = ROOT / "docs" / "architecture.md"


def _sections(text: str) -> dict[str, str]:
    """``{"agents/<sub>" or "tether_gym.<name>": its text}`` of the diagram's blocks."""
    diagram = text[text.index("```\n train.py / evaluate.py"):]
    diagram = diagram[:diagram.index("\n```")]
    sections: dict[str, str] = {}
    current = None
    for line in diagram.splitlines():
        agents = re.match(r"\s+\|\s+(\w+)/\s+\d\s", line)
        package = re.match(r" (tether_gym\.\w+)\s", line)
        if agents:
            current = f"agents/{agents.group(1)}"
        elif package:
            current = package.group(1)
        if current is not None:
            sections[current] = sections.get(current, "") + line + "\n"
    return sections


def _missing(sections: dict[str, str], root: Path) -> list[str]:
    missing = []
    for path in sorted(root.glob("agents/*/*.py")) + sorted(root.glob("tether_gym/*/*.py")):
        if path.name == "__init__.py":
            continue
        package, name = path.parent.name, path.name
        key = f"agents/{package}" if path.parts[-3] == "agents" else f"tether_gym.{package}"
        if not re.search(rf"(?<![\w.]){re.escape(name)}", sections.get(key, "")):
            missing.append(str(path.relative_to(root)))
    for path in sorted(root.glob("tether_gym/*.py")):
        if path.name != "__init__.py" and f"tether_gym.{path.stem}" not in sections:
            missing.append(str(path.relative_to(root)))
    return missing


def test_every_module_is_named_in_its_section_of_the_diagram():
    assert _missing(_sections(ARCHITECTURE.read_text()), ROOT) == []


def test_the_check_reports_a_module_missing_from_the_diagram(tmp_path):
    """Not vacuous: a module that is not in the diagram, or in another section, is named."""
    for rel in ("agents/training/brand_new.py", "agents/common/run.py",
                "tether_gym/envs/config.py", "tether_gym/novel.py"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("")
    # run.py is named in training's section, not common's; config.py in envs' section
    assert _missing(_sections(ARCHITECTURE.read_text()), tmp_path) == [
        "agents/common/run.py", "agents/training/brand_new.py", "tether_gym/novel.py"]


@pytest.mark.parametrize("path", ["agents/training/__init__.py", "agents/files/__init__.py",
                                  "agents/evaluation/__init__.py",
                                  "agents/common/__init__.py", "agents/__init__.py"])
def test_package_docstrings_link_to_the_diagram_instead_of_listing_modules(path):
    source = (ROOT / path).read_text()
    assert "docs/architecture.md" in source
    assert not re.search(r":mod:`\.\w+`", source), "a module list: link to the diagram"
