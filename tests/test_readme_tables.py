"""The README's benchmark tables are what the shipped results.json files say.

``experiments/issue35/readme_tables.py`` prints each suite's tables from the shipped
results (the main job's, mpc's and the rows evaluated in their own calls); every table
line it prints must be a line of the README (for ``beyond`` the policy table alone: the
README links its per-scenario tables), so a results.json regenerated without its table
(or a table edited by hand) fails here.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SUITES = {
    "default": ["docs/eval", "docs/eval_mpc"],
    "robust": ["docs/eval_robust", "docs/eval_robust/mpc", "docs/eval_robust/distill",
               "docs/eval_robust/sac_residual", "docs/eval_robust/filtered_distill_ppo",
               "docs/eval_robust/ppo_accel"],
    "beyond": ["docs/eval_beyond", "docs/eval_beyond/mpc", "docs/eval_beyond/distill",
               "docs/eval_beyond/sac_residual", "docs/eval_beyond/filtered_distill_ppo",
               "docs/eval_beyond/ppo_accel"],
}


POLICY_TABLE_ONLY = ("beyond",)


def _tables(folders: list[str]) -> list[str]:
    spec = importlib.util.spec_from_file_location(
        "readme_tables", ROOT / "experiments" / "issue35" / "readme_tables.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert module.main([str(ROOT / f) for f in folders]) == 0
    return [line for line in out.getvalue().splitlines() if line.startswith("|")]


@pytest.mark.parametrize("suite", sorted(SUITES))
def test_every_table_line_is_in_the_readme(suite):
    readme = set((ROOT / "README.md").read_text().splitlines())
    lines = _tables(SUITES[suite])
    policies = [line for line in lines
                if any(f" | {kind} | " in line for kind in ("rl", "hybrid", "baseline"))]
    assert len(policies) >= 10  # the policy table was printed, not an empty one
    if suite in POLICY_TABLE_ONLY:
        lines = policies
    missing = [line[:80] for line in lines if line not in readme]
    assert not missing, f"{suite}: README lacks {len(missing)} table line(s): {missing[:3]}"
