"""Paper reproduction: entry points."""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from tether_gym.tasks.reference import (
    desired_libration,
    periodic_length_small_amplitude,
    periodic_reel_rate,
)

from ..common.jsonio import to_jsonable
from .figures import _draw, _figure_class
from .measures import smc_metrics, swing
from .runs import make_env, run_periodic, run_smc
from .settings import (
    DEFAULT_SMC_SETTINGS,
    FIG5_AMPLITUDES,
    FIG6_AMPLITUDES,
    FIG6_ECCENTRICITY,
    ORBIT,
    PAPER_SMC_SETTINGS,
    TABLE1_LENGTH,
)
from .studies import _positivity_study, _swing_scan, _zero_state_study
from .table import _build_rows, _markdown


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
    """
    figure_cls = _figure_class()  # fail before the runs if matplotlib is missing
    del figure_cls
    log = log or (lambda *a, **k: None)
    if orbits is not None and not (isinstance(orbits, (int, float)) and orbits > 0):
        raise ValueError(f"orbits={orbits!r} must be a number > 0 (or None)")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()

    def dur(default: float) -> float:
        return default if orbits is None else min(default, float(orbits))

    res: dict = {"orbits": orbits, "quick": quick}
    figs: dict = {}
    log("zero state (Figs. 2-4) ...")
    figs["zero"], res["zero_state"] = _zero_state_study(dur(3.0))

    log("periodic solutions (Fig. 5) ...")
    nu_q = np.linspace(0.0, ORBIT, 4001)
    figs["fig5"], res["fig5"] = {}, {}
    for a in FIG5_AMPLITUDES:
        traj = run_periodic(0.2, a, dur(3.0))
        one = traj.orbits <= 1.0 + 1e-9
        sw = swing(traj.length[one], TABLE1_LENGTH)
        figs["fig5"][a] = traj
        closed = periodic_length_small_amplitude(nu_q, TABLE1_LENGTH, 0.2, a)
        res["fig5"][f"{a:g}"] = {
            "swing": float(sw.max()),
            "peak_out": float(traj.length[one].max() / TABLE1_LENGTH - 1.0),
            "half_swing_abs": float(0.5 * (traj.length[one].max() - traj.length[one].min())),
            "eq11a_swing": float(np.ptp(closed) / TABLE1_LENGTH),
            "max_tracking_error": float(traj.tracking_error.max()),
            "failure": traj.failure, "duration_orbits": traj.duration}

    log("Fig. 6 (e = 0.7) ...")
    e6 = FIG6_ECCENTRICITY
    figs["fig6"], figs["fig6_quadrature"], res["fig6"] = {}, {}, {}
    from scipy.integrate import cumulative_trapezoid

    for a in FIG6_AMPLITUDES:
        traj = run_periodic(e6, a, dur(1.0), semi_latus_rectum=7.1e6 * (1.0 + e6))
        th, dth, _ = desired_libration(nu_q, a, 1.0)
        rate = periodic_reel_rate(nu_q, th, dth, 1.0, e6, a)
        quad = TABLE1_LENGTH * np.exp(cumulative_trapezoid(rate, nu_q, initial=0.0))
        figs["fig6"][a] = traj
        figs["fig6_quadrature"][a] = (nu_q, quad)
        res["fig6"][f"{a:g}"] = {
            "failure": traj.failure, "duration_orbits": traj.duration,
            "env_swing_abs": float(np.ptp(traj.length[:, 0])),
            "swing_abs_quadrature": float(np.ptp(quad)),
            "max_dev_abs_quadrature": float(np.abs(quad - TABLE1_LENGTH).max()),
            "env_vs_quadrature_max_dev": float(np.abs(
                traj.length[:, 0] - np.interp(traj.nu, nu_q, quad)).max()),
            "min_tension": float(traj.tension_min.min())}

    log("swing minimiser scans (Eq. 11b) ...")
    step = 0.1 if quick else 0.025
    res["scans"] = [
        _swing_scan(0.2, np.round(np.arange(0.05, 0.4 + 1e-9, step), 6), dur(1.0), not quick),
        _swing_scan(0.5, np.round(np.arange(0.25, 0.65 + 1e-9, step), 6), dur(1.0), not quick),
    ]
    figs["scans"] = res["scans"]

    log("tension positivity (Sec. 3.2) ...")
    if quick:
        res["positivity"] = _positivity_study((0.2, 0.7), (0.5, 0.7), dur(1.0), False)
    else:
        res["positivity"] = _positivity_study((0.1, 0.2, 0.3, 0.5, 0.7),
                                              (0.3, 0.5, 0.6, 0.65, 0.66, 0.7, 0.8),
                                              dur(1.0), True)

    log("sliding mode (Figs. 7-9) at h = 0.001 and h_c = 0.025 ...")
    figs["smc_paper"] = run_smc(dur(3.0), PAPER_SMC_SETTINGS)
    figs["smc_default"] = run_smc(dur(3.0), DEFAULT_SMC_SETTINGS)
    res["smc_paper"] = smc_metrics(figs["smc_paper"])
    res["smc_default"] = smc_metrics(figs["smc_default"])
    res["smc_paper"]["settings"] = figs["smc_paper"].settings
    res["smc_default"]["settings"] = figs["smc_default"].settings

    log("L0 sweep (docs/model.md) ...")
    res["l0_sweep"] = []
    for l0_km, notes_bound in ((1.0, "15.5"), (10.0, "1.55"), (20.0, "0.78"), (30.0, "—")):
        traj = run_smc(dur(3.0), DEFAULT_SMC_SETTINGS, total_tether_length=l0_km * 1e3)
        env = make_env(1.0, total_tether_length=l0_km * 1e3)
        cfg = env.unwrapped.config
        env.close()
        m = smc_metrics(traj)
        res["l0_sweep"].append({"L0_km": l0_km, "notes_bound": notes_bound,
                                "accel_bound": cfg.scales.accel_bound(cfg.accel_limit),
                                "mean_total_length": m["mean_total_length_after_orbit_1"],
                                "convergence_orbits": m["convergence_orbits"],
                                "min_length": m["min_length"], "failure": m["failure"],
                                "duration_orbits": m["duration_orbits"]})

    log("figures ...")
    res["figures"] = _draw(figs, out)
    res["runtime_s"] = time.perf_counter() - t0
    rows = _build_rows(res)
    res["table"] = rows
    (out / "paper_vs_tether_gym.md").write_text(_markdown(res, rows))
    (out / "paper_vs_tether_gym.json").write_text(json.dumps(to_jsonable(res), indent=1,
                                                             allow_nan=False))
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
    """The options of ``evaluate.py paper`` (shared by :func:`main`)."""
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument("--orbits", type=_positive, default=None,
                        help="cap every run at this many orbits (for quick checks)")
    parser.add_argument("--quick", action="store_true",
                        help="coarse A scans and a small positivity grid")
    return parser


def run(args: argparse.Namespace) -> int:
    """Run the reproduction for parsed arguments; returns the exit code."""
    reproduce(args.out, orbits=args.orbits, quick=args.quick)
    return 0


def main(argv=None) -> int:
    """``evaluate.py paper``: reproduce the paper's figures and table into --out."""
    parser = argparse.ArgumentParser(
        prog="evaluate.py paper",
        description="Reproduce Shi, Zhu & Zhu (2019), Figs. 2-9, from tether_gym and write "
                    "paper_vs_tether_gym.md/.json beside the PNG figures.")
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
