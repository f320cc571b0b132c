"""Paper reproduction: :func:`reproduce` (every study, figures, table) and its command line.

``evaluate.py paper`` is dispatched by the agents' command line, which builds its
options with :func:`add_arguments` and runs them with :func:`run`; :func:`main` is the
same command on its own.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from ..common.atomic_write import write_text_atomic
from ..common.jsonio import to_jsonable
from .figures import FigureInputs, draw, figure_class
from .settings import DEFAULT_SMC_SETTINGS, PAPER_SMC_SETTINGS
from .studies import (
    fig5_study,
    fig6_study,
    l0_sweep,
    positivity_study,
    smc_study,
    swing_scan,
    zero_state_study,
)
from .table import build_rows, markdown

__all__ = ["reproduce", "add_arguments", "run", "main"]


def _silent(*args, **kwargs) -> None:
    """A ``log`` that prints nothing."""


def _run_studies(orbits: float | None, quick: bool, log) -> tuple[dict, FigureInputs]:
    """Every study in the table's order: their numbers and the runs the figures show."""

    def dur(default: float) -> float:
        return default if orbits is None else min(default, float(orbits))

    res: dict = {"orbits": orbits, "quick": quick}
    log("zero state (Figs. 2-4) ...")
    zero, res["zero_state"] = zero_state_study(dur(3.0))
    log("periodic solutions (Fig. 5) ...")
    fig5, res["fig5"] = fig5_study(dur(3.0))
    log("Fig. 6 (e = 0.7) ...")
    fig6 = fig6_study(dur(1.0))
    res["fig6"] = fig6.numbers
    log("swing minimiser scans (Eq. 11b) ...")
    step = 0.1 if quick else 0.025
    res["scans"] = [
        swing_scan(0.2, np.round(np.arange(0.05, 0.4 + 1e-9, step), 6), dur(1.0), not quick),
        swing_scan(0.5, np.round(np.arange(0.25, 0.65 + 1e-9, step), 6), dur(1.0), not quick),
    ]
    log("tension positivity (Sec. 3.2) ...")
    if quick:
        res["positivity"] = positivity_study((0.2, 0.7), (0.5, 0.7), dur(1.0), False)
    else:
        res["positivity"] = positivity_study((0.1, 0.2, 0.3, 0.5, 0.7),
                                             (0.3, 0.5, 0.6, 0.65, 0.66, 0.7, 0.8),
                                             dur(1.0), True)
    log("sliding mode (Figs. 7-9) at h = 0.001 and h_c = 0.025 ...")
    smc_paper, res["smc_paper"] = smc_study(dur(3.0), PAPER_SMC_SETTINGS)
    smc_default, res["smc_default"] = smc_study(dur(3.0), DEFAULT_SMC_SETTINGS)
    log("L0 sweep (docs/model.md) ...")
    res["l0_sweep"] = l0_sweep(dur(3.0))
    inputs = FigureInputs(zero=zero, fig5=fig5, fig6=fig6.runs,
                          fig6_quadrature=fig6.quadrature, scans=res["scans"],
                          smc_paper=smc_paper, smc_default=smc_default)
    return res, inputs


def reproduce(out_dir, orbits: float | None = None, quick: bool = False, log=print) -> dict:
    """Run every study, write the figures and ``paper_vs_tether_gym.md/.json`` to out_dir.

    Parameters
    ----------
    out_dir : str or Path
        Output directory (created if missing).
    orbits : float or None
        Cap on every run's duration [orbits] (None: the paper's durations, 3 orbits
        for Figs. 2-5 and 7-9, 1 orbit for Fig. 6 and the scans). Metrics that need
        more than the capped run reads "n/a".
    quick : bool
        Coarser scans (A step 0.1, no refinement) and a small positivity grid.
    log : callable
        Progress messages (``print`` by default; ``None`` for silence).

    Returns
    -------
    dict
        All numbers (as written to the JSON file), the table rows and the file names.

    Raises
    ------
    ImportError
        When matplotlib is missing (before any run).
    ValueError
        When ``orbits`` is not a number > 0 (or None).
    """
    figure_class()  # fail before the runs if matplotlib is missing
    log = log or _silent
    if orbits is not None and not (isinstance(orbits, (int, float)) and orbits > 0):
        raise ValueError(f"orbits={orbits!r} must be a number > 0 (or None)")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    res, inputs = _run_studies(orbits, quick, log)
    log("figures ...")
    res["figures"] = draw(inputs, out)
    res["runtime_s"] = time.perf_counter() - t0
    rows = build_rows(res)
    res["table"] = rows
    write_text_atomic(out / "paper_vs_tether_gym.md", markdown(res, rows))
    write_text_atomic(out / "paper_vs_tether_gym.json",
                      json.dumps(to_jsonable(res), indent=1, allow_nan=False))
    res["files"] = res["figures"] + ["paper_vs_tether_gym.md", "paper_vs_tether_gym.json"]
    log(f"wrote {len(res['files'])} files to {out} in {res['runtime_s']:.1f} s")
    return res


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text!r} must be > 0")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the options of ``evaluate.py paper`` (shared by :func:`main`).

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The parser (or sub-parser) to extend with ``--out``, ``--orbits`` and ``--quick``.

    Returns
    -------
    argparse.ArgumentParser
        The same parser.
    """
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument("--orbits", type=_positive, default=None,
                        help="cap every run at this many orbits (for quick checks)")
    parser.add_argument("--quick", action="store_true",
                        help="coarse A scans and a small positivity grid")
    return parser


def run(args: argparse.Namespace) -> int:
    """Run the reproduction for parsed arguments.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed options of :func:`add_arguments` (``out``, ``orbits``, ``quick``).

    Returns
    -------
    int
        The exit code: 0, or 2 after one ``error:`` line on stderr when ``--out`` is
        empty, a file or not writable (checked before any study runs).
    """
    from ..evaluation.benchmark import check_out_dir

    try:
        check_out_dir(args.out)
    except ValueError as exc:
        print(f"evaluate.py paper: error: {exc}", file=sys.stderr)
        return 2
    reproduce(args.out, orbits=args.orbits, quick=args.quick)
    return 0


def main(argv=None) -> int:
    """``evaluate.py paper``: reproduce the paper's figures and table into --out.

    Parameters
    ----------
    argv : list of str or None
        The options (without the ``paper`` word); None reads ``sys.argv``.

    Returns
    -------
    int
        The exit code (bad options exit 2 through argparse).
    """
    parser = argparse.ArgumentParser(
        prog="evaluate.py paper",
        description="Reproduce Shi, Zhu & Zhu (2019), Figs. 2-9, from tether_gym and write "
                    "paper_vs_tether_gym.md/.json beside the PNG figures.")
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
