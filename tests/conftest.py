"""Test-suite set-up shared by every folder: the physics helpers are importable by name."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent / "physics"))
