"""Paper reproduction: the figures (Figs. 2-9 and the swing scan) as PNG files."""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..common.atomic_write import save_figure
from .runs import Trajectory
from .settings import PLOT_EXTRA, TABLE1_LENGTH

__all__ = ["FigureInputs", "figure_class", "draw"]

_ORBITS_LABEL = "orbits (nu / 2 pi)"
_TETHERS = ("1", "2")


class FigureInputs(NamedTuple):
    """What the figures show: the studies' runs (see :mod:`.studies`)."""

    zero: Trajectory
    """Eq. 7 from the zero state (Figs. 2-4)."""
    fig5: dict
    """A [rad] -> Eq. 10 run at e = 0.2 (Fig. 5)."""
    fig6: dict
    """A [rad] -> Eq. 10 run at e = 0.7 (Fig. 6)."""
    fig6_quadrature: dict
    """A [rad] -> (nu [rad], l [-]), Eq. 10 integrated over one orbit (Fig. 6, dashed)."""
    scans: list
    """The swing scans (:func:`~.studies.swing_scan` results)."""
    smc_paper: Trajectory
    """Sliding mode at the paper's step (Figs. 7-9)."""
    smc_default: Trajectory
    """Sliding mode at the env's default control step (Figs. 7-9, dashed)."""


def figure_class():
    """``matplotlib.figure.Figure``, or an ImportError that names the pip command.

    Returns
    -------
    type
        The matplotlib Figure class (no pyplot, no global state).

    Raises
    ------
    ImportError
        When matplotlib is not installed.
    """
    try:
        from matplotlib.figure import Figure
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("the paper figures need matplotlib, which is not installed; "
                          f"install it with: {PLOT_EXTRA}") from exc
    return Figure


def _save(fig, out_dir: Path, name: str, written: list) -> None:
    fig.tight_layout()
    path = out_dir / name
    save_figure(fig, path, dpi=110)  # a link or FIFO there is replaced, not written to
    written.append(path.name)


def _new_axes(figure_cls, title: str, xlabel: str, ylabel: str):
    fig = figure_cls(figsize=(6.4, 4.0))
    ax = fig.add_subplot()
    ax.set_title(title, fontsize=10)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    return fig, ax


def _mark_end(ax, traj: Trajectory, x, y, color) -> None:
    if traj.failure is not None:
        ax.plot([x[-1]], [y[-1]], "x", color=color, ms=8)


def _draw_zero_state(figure_cls, zero: Trajectory, out_dir: Path, written: list) -> None:
    """Figs. 2-4: angles, lengths and tensions of the zero-state run."""
    xo, labels = _ORBITS_LABEL, _TETHERS
    fig, ax = _new_axes(figure_cls, "Fig. 2: libration angles, zero state (Eq. 7)\n(paper: 0; "
                        "residual of the control step's zero-order hold and the reel lag)",
                        xo, "theta [rad]")
    for j in range(2):
        ax.plot(zero.orbits, zero.theta[:, j], label=f"theta_{labels[j]}")
    ax.legend()
    _save(fig, out_dir, "fig2_zero_state_angles.png", written)

    fig, ax = _new_axes(figure_cls, "Fig. 3: tether lengths, zero state", xo, "l [-]")
    for j, style in enumerate(("-", "--")):
        ax.plot(zero.orbits, zero.length[:, j], style, label=f"l_{labels[j]}")
    ax.legend()
    _save(fig, out_dir, "fig3_zero_state_lengths.png", written)

    fig, ax = _new_axes(figure_cls, "Fig. 4: tensions, zero state", xo, "T^ [-]")
    k = 1.0 + zero.settings["eccentricity"] * np.cos(zero.nu)
    for j, coef in enumerate((3.0, 2.4)):
        ax.plot(zero.orbits, zero.tension[:, j], label=f"T^_{labels[j]} (env)")
        ax.plot(zero.orbits, coef / k**2, "k:", lw=1.0,
                label="3 / k^2, 2.4 / k^2 (docs/model.md)" if j == 0 else None)
    ax.set_ylim(top=1.15 * float(zero.tension.max()))
    ax.legend(fontsize=8, ncol=3, loc="upper center")
    _save(fig, out_dir, "fig4_zero_state_tensions.png", written)


def _draw_periodic(figure_cls, inputs: FigureInputs, out_dir: Path, written: list) -> None:
    """Figs. 5-6: lengths under Eq. 10 at e = 0.2 and length change at e = 0.7."""
    fig, ax = _new_axes(figure_cls, "Fig. 5: tether length under Eq. 10, e = 0.2",
                        _ORBITS_LABEL, "l_i [-]")
    for a, traj in inputs.fig5.items():
        line, = ax.plot(traj.orbits, traj.length[:, 0], label=f"A = {a:g}")
        _mark_end(ax, traj, traj.orbits, traj.length[:, 0], line.get_color())
    ax.legend()
    _save(fig, out_dir, "fig5_periodic_lengths.png", written)

    fig, ax = _new_axes(figure_cls, "Fig. 6: length change over one orbit, e = 0.7\n"
                        "(x: env run ends in slack; dashed: quadrature of Eq. 10)",
                        "true anomaly nu [rad]", "l - l(0) [-]")
    for a, traj in inputs.fig6.items():
        line, = ax.plot(traj.nu, traj.length[:, 0] - TABLE1_LENGTH, label=f"A = {a:g}")
        color = line.get_color()
        _mark_end(ax, traj, traj.nu, traj.length[:, 0] - TABLE1_LENGTH, color)
        quad = inputs.fig6_quadrature[a]
        ax.plot(quad[0], quad[1] - TABLE1_LENGTH, "--", color=color, lw=0.8)
    ax.legend(fontsize=8)
    _save(fig, out_dir, "fig6_length_change_e07.png", written)


def _draw_smc(figure_cls, smc: Trajectory, smc_def: Trajectory, out_dir: Path,
              written: list) -> None:
    """Figs. 7-9: angles, lengths and tensions of the sliding mode at both steps."""
    xo, labels = _ORBITS_LABEL, _TETHERS
    fig, ax = _new_axes(figure_cls, "Fig. 7: libration angles, sliding mode (accel limit on)",
                        xo, "theta [rad]")
    for j in range(2):
        ax.plot(smc.orbits, smc.theta[:, j], label=f"theta_{labels[j]} (h = 0.001)")
    ax.plot(smc.orbits, smc.theta_ref, "k:", label="theta_d")
    for j in range(2):
        ax.plot(smc_def.orbits, smc_def.theta[:, j], "--", lw=0.8,
                label=f"theta_{labels[j]} (h_c = 0.025)")
    ax.legend(fontsize=8, loc="lower left")
    _save(fig, out_dir, "fig7_smc_angles.png", written)

    fig, ax = _new_axes(figure_cls, "Fig. 8: tether lengths, sliding mode", xo, "l [-]")
    for j in range(2):
        ax.plot(smc.orbits, smc.length[:, j], label=f"l_{labels[j]}")
    ax.plot(smc.orbits, smc.length.sum(axis=1), "k", label="l_1 + l_2")
    ax.plot(smc_def.orbits, smc_def.length.sum(axis=1), "k--", lw=0.8,
            label="l_1 + l_2 (h_c = 0.025)")
    ax.axhline(0.9, color="grey", lw=0.6, ls=":")
    ax.legend(fontsize=8)
    _save(fig, out_dir, "fig8_smc_lengths.png", written)

    fig, ax = _new_axes(figure_cls, "Fig. 9: tensions, sliding mode", xo, "T^ [-]")
    for j in range(2):
        ax.plot(smc.orbits, smc.tension[:, j], label=f"T^_{labels[j]} (h = 0.001)")
    for j in range(2):
        ax.plot(smc_def.orbits, smc_def.tension[:, j], "--", lw=0.8,
                label=f"T^_{labels[j]} (h_c = 0.025)")
    ax.legend(fontsize=8)
    _save(fig, out_dir, "fig9_smc_tensions.png", written)


def _draw_swing_scan(figure_cls, scans: list, out_dir: Path, written: list) -> None:
    """The extra figure: swing vs A from the env scans and from Eq. 11a."""
    fig, ax = _new_axes(figure_cls,
                        "Swing vs A (Eq. 11b check): env (dots) and Eq. 11a (lines)",
                        "A [rad]", "(max l - min l) / l(0) over one orbit")
    for scan in scans:
        dots, = ax.plot(scan["grid"], scan["swing"], "o", ms=3,
                        label=f"env, e = {scan['eccentricity']:g}")
        ax.plot(scan["eq11a_grid"], scan["eq11a_swing"], "-", lw=0.8, color=dots.get_color(),
                label=f"Eq. 11a, e = {scan['eccentricity']:g}")
        ax.axvline(scan["argmin"], color=dots.get_color(), lw=0.6, ls=":")
    ax.legend(fontsize=8)
    _save(fig, out_dir, "fig_extra_swing_scan.png", written)


def draw(inputs: FigureInputs, out_dir: Path) -> list:
    """Write every figure as a PNG file into ``out_dir``.

    Parameters
    ----------
    inputs : FigureInputs
        The studies' runs.
    out_dir : Path
        An existing directory.

    Returns
    -------
    list of str
        The file names written, in order (Figs. 2-9, then the swing scan).

    Raises
    ------
    ImportError
        When matplotlib is not installed (see :func:`figure_class`).
    """
    figure_cls = figure_class()
    written: list = []
    _draw_zero_state(figure_cls, inputs.zero, out_dir, written)
    _draw_periodic(figure_cls, inputs, out_dir, written)
    _draw_smc(figure_cls, inputs.smc_paper, inputs.smc_default, out_dir, written)
    _draw_swing_scan(figure_cls, inputs.scans, out_dir, written)
    return written
