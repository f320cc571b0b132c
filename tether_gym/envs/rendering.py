"""Matplotlib rendering of the tethered chain (``render_mode`` "rgb_array" or "human").

matplotlib is optional (``pip install -e ".[plot]"``) and is imported only when
a :class:`ChainRenderer` is built, so this module imports without it.

One frame shows

* the chain in the orbital frame of the main satellite: the main satellite (square)
  at the top, the local vertical (dashed, pointing down to Earth), the along-track
  direction (flight direction) to the right, so a positive theta (body trailing) puts
  the body to the left; the subsatellites are dots joined by tether segments coloured
  by the dimensionless tension T^ [-] (``viridis``, fixed scale); a slack tether
  (T^ <= 0 now or at a substep of the last step, ``info["tension_min"]``) is drawn
  red and dashed;
* the reference direction theta_d (dashed, orange);
* a text with nu [orbits], theta [rad], theta_d [rad], l [-] and T^ [-] (and the
  failure, if any);
* an inset of the orbit ellipse r = p / (1 + e cos nu) in units of p, Earth at the
  focus, with the main satellite at the current true anomaly.

Axis limits and the colour scale depend only on the configuration, so frames of
one environment are comparable. The figure and its artists are built once and
updated in place for every frame; off-screen, the static part is rendered once (per
eccentricity) and the moving artists are blitted onto it.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.error import DependencyNotInstalled

from .config import EnvConfig

__all__ = ["ChainRenderer", "FRAME_SIZE"]

FRAME_SIZE = 480
"""Width and height of an ``rgb_array`` frame [px]."""

_DPI = 100
_INSTALL_HINT = ('matplotlib is needed for rendering: pip install -e ".[plot]" in a clone of '
                 'tether_gym (or pip install matplotlib)')
_SLACK_COLOUR = "tab:red"
_REF_COLOUR = "tab:orange"


def _import_matplotlib():
    """Import matplotlib or raise DependencyNotInstalled naming the pip command."""
    try:
        import matplotlib  # noqa: F401
    except ImportError as exc:
        raise DependencyNotInstalled(_INSTALL_HINT) from exc


def _has_display() -> bool:
    """True when pyplot's backend can open a window."""
    import matplotlib

    interactive: list[str]
    try:
        from matplotlib.backends import BackendFilter, backend_registry

        interactive = backend_registry.list_builtin(BackendFilter.INTERACTIVE)
    except ImportError:  # matplotlib < 3.9
        from matplotlib import rcsetup

        interactive = list(rcsetup.interactive_bk)  # type: ignore[attr-defined]
    return matplotlib.get_backend().lower() in {name.lower() for name in interactive}


def _fmt(values) -> str:
    return "(" + ", ".join(f"{v:+.3f}" for v in np.atleast_1d(values)) + ")"


class ChainRenderer:
    """Draws frames of a :class:`~tether_gym.envs.TetherLibrationEnv`.

    Parameters
    ----------
    config : EnvConfig
        The environment's configuration (fixes the axis limits and colour scale).
    render_mode : {"rgb_array", "human"}
        ``"rgb_array"``: :meth:`draw` returns an (H, W, 3) uint8 array, drawn off-screen
        with the Agg canvas (no pyplot state). ``"human"``: a pyplot window updated
        with ``plt.pause``; without a display a warning is given once and frames are
        drawn off-screen only.

    Raises
    ------
    gymnasium.error.DependencyNotInstalled
        If matplotlib is not installed.
    """

    def __init__(self, config: EnvConfig, render_mode: str):
        if render_mode not in ("rgb_array", "human"):
            raise ValueError(f"render_mode={render_mode!r} must be 'rgb_array' or 'human'")
        _import_matplotlib()
        self.config = config
        self.render_mode = render_mode
        self.n = config.n_tethers
        self._last_ecc: float | None = None
        self._plt: Any = None
        self._show = False
        if render_mode == "human":
            import matplotlib.pyplot as plt

            self._plt = plt
            self._show = _has_display()
            if not self._show:
                gym.logger.warn("render_mode='human' but matplotlib has no interactive "
                                f"backend (backend {plt.get_backend()!r}, no display?); "
                                "frames are not shown. Use render_mode='rgb_array'.")
            fig = plt.figure(figsize=(FRAME_SIZE / _DPI, FRAME_SIZE / _DPI), dpi=_DPI)
        else:
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure

            fig = Figure(figsize=(FRAME_SIZE / _DPI, FRAME_SIZE / _DPI), dpi=_DPI)
            FigureCanvasAgg(fig)
        self.fig: Any = fig
        self._build()

    # ------------------------------------------------------------------ #
    def _build(self) -> None:
        import matplotlib
        from matplotlib.cm import ScalarMappable
        from matplotlib.colors import Normalize

        cfg = self.config
        fig = self.fig
        n = self.n
        # Chain axes: the chain can reach 1.6 x its initial total length (the zero
        # state's apogee length is (1+e)/(1-e) = 1.5 x at e = 0.2), within the bounds.
        reach = min(1.6 * sum(cfg.initial_lengths), n * cfg.length_bounds[1])
        self.reach = reach
        ax = fig.add_axes((0.02, 0.12, 0.96, 0.86))
        ax.set_xlim(-0.75 * reach, 0.75 * reach)
        ax.set_ylim(-1.35 * reach, 0.15 * reach)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.text(0.98, 0.02, "along-track (flight) \u2192", transform=ax.transAxes,
                ha="right", va="bottom", fontsize=7, color="0.4")
        self.ax = ax
        # local vertical (to Earth) and reference direction theta_d
        (self._vertical,) = ax.plot([0.0, 0.0], [0.0, -1.25 * reach], ls="--", lw=0.8,
                                    color="0.5")
        ax.text(0.0, -1.27 * reach, "local vertical, Earth \u2193", ha="center", va="top",
                fontsize=7, color="0.4")
        (self._ref_line,) = ax.plot([], [], ls="--", lw=1.0, color=_REF_COLOUR)
        # tension colour scale: the zero state's T^_1 = 3 / k^2 (Table 1,
        # docs/model.md#zero-state-eq-7)
        # peaks at apogee at 3 / (1-e)^2; the scale runs to 4 / (1-e)^2 for the
        # largest eccentricity of the configuration
        e_hi = cfg.eccentricity_range[1] if cfg.eccentricity_range else cfg.eccentricity
        e_lo = cfg.eccentricity_range[0] if cfg.eccentricity_range else cfg.eccentricity
        self.tension_max = float(min(50.0, 4.0 / (1.0 - e_hi) ** 2))
        self._norm = Normalize(0.0, self.tension_max)
        self._cmap = matplotlib.colormaps["viridis"]
        self._segments = [ax.plot([], [], lw=2.5, solid_capstyle="round")[0]
                          for _ in range(n)]
        masses = np.asarray(cfg.masses) / max(cfg.masses)
        self._bodies = ax.scatter(np.zeros(n), -np.arange(1, n + 1, dtype=float),
                                  s=30.0 + 50.0 * masses, color="tab:blue")
        (self._main,) = ax.plot([0.0], [0.0], "s", ms=10, color="0.2")
        self._text = ax.text(0.02, 0.98, "", transform=ax.transAxes, ha="left", va="top",
                             fontsize=7.5, family="monospace", zorder=1,
                             bbox={"fc": "white", "alpha": 0.75, "lw": 0})
        self._fail_text = ax.text(0.5, 0.45, "", transform=ax.transAxes, ha="center",
                                  fontsize=14, color=_SLACK_COLOUR, weight="bold")
        # colour bar of T^ at the bottom
        cax = fig.add_axes((0.15, 0.055, 0.7, 0.025))
        bar = fig.colorbar(ScalarMappable(self._norm, self._cmap), cax=cax,
                           orientation="horizontal")
        bar.ax.tick_params(labelsize=7, length=2, pad=1)
        bar.set_label("tension T^ [-]  (red dashed: slack, T^ \u2264 0)", fontsize=7,
                      labelpad=1)
        # orbit inset, in units of p, Earth at the focus; limits fixed by the
        # configuration's eccentricity range
        a_hi = 1.0 / (1.0 - e_hi**2)
        r_peri = 1.0 / (1.0 + e_lo)
        half = 0.5 * (a_hi * (1.0 + e_hi) + r_peri) * 1.15
        centre = 0.5 * (r_peri - a_hi * (1.0 + e_hi))
        inset = fig.add_axes((0.71, 0.7, 0.26, 0.26))
        inset.set_xlim(centre - half, centre + half)
        inset.set_ylim(-half, half)
        inset.set_aspect("equal", adjustable="box")
        inset.set_xticks([])
        inset.set_yticks([])
        inset.set_title("orbit", fontsize=7, pad=2)
        inset.plot([0.0], [0.0], "o", ms=5, color="tab:cyan")
        (self._ellipse,) = inset.plot([], [], lw=0.8, color="0.3")
        (self._radius,) = inset.plot([], [], lw=0.6, color="0.6")
        (self._sat,) = inset.plot([], [], "s", ms=4, color="0.1")
        self._anomaly_grid = np.linspace(0.0, 2.0 * math.pi, 181)
        # Artists that change every frame, in drawing order (the text box lowest, the
        # rest above the axes spines, 2.5). Off-screen they are "animated": canvas.draw()
        # renders the rest once into a cached background (redone when e changes), and
        # each frame blits them onto a copy of it.
        self._dynamic = [self._text, self._vertical, self._ref_line, *self._segments,
                         self._bodies, self._main, self._fail_text, self._radius, self._sat]
        for i, artist in enumerate(self._dynamic[1:]):
            artist.set_zorder(2.6 + 0.01 * i)
        self._background = None
        if self.render_mode == "rgb_array":
            for artist in self._dynamic:
                artist.set_animated(True)

    # ------------------------------------------------------------------ #
    def draw(self, info: dict, eccentricity: float) -> np.ndarray | None:
        """Update the frame from the env's ``info`` dict and the episode's e [-].

        Returns an (H, W, 3) uint8 array in "rgb_array" mode, None in "human" mode.
        """
        nu = float(info["nu"])
        theta = np.asarray(info["theta"], dtype=float)
        length = np.asarray(info["length"], dtype=float)
        tension = np.asarray(info["tension"], dtype=float)
        # a tether counts as slack if T^ <= 0 now or at any substep of the last step
        tension_min = np.asarray(info.get("tension_min", tension), dtype=float)
        slack = np.minimum(tension, tension_min) <= 0.0
        theta_ref = float(info["theta_ref"])
        # body positions (x along-track, y radial outward), paper Eq. 1
        x = np.concatenate([[0.0], -np.cumsum(length * np.sin(theta))])
        y = np.concatenate([[0.0], -np.cumsum(length * np.cos(theta))])
        for j, seg in enumerate(self._segments):
            seg.set_data(x[j:j + 2], y[j:j + 2])
            if not slack[j]:
                seg.set_color(self._cmap(self._norm(tension[j])))
                seg.set_linestyle("-")
            else:
                seg.set_color(_SLACK_COLOUR)
                seg.set_linestyle("--")
        self._bodies.set_offsets(np.column_stack([x[1:], y[1:]]))
        r = 1.25 * self.reach
        self._ref_line.set_data([0.0, -r * math.sin(theta_ref)], [0.0, -r * math.cos(theta_ref)])
        lines = [
            f"nu    = {nu / (2.0 * math.pi):7.3f} orbits",
            f"theta = {_fmt(theta)} rad",
            f"ref   = {theta_ref:+.3f} rad (orange)",
            f"l     = {_fmt(length)}",
            f"T^    = {_fmt(tension)}" + (" SLACK" if slack.any() else ""),
        ]
        self._text.set_text("\n".join(lines))
        failure = info.get("failure")
        self._fail_text.set_text("" if failure is None else f"failure: {failure}")
        # orbit inset
        ecc = float(eccentricity)
        if ecc != self._last_ecc:
            grid = self._anomaly_grid
            radii = 1.0 / (1.0 + ecc * np.cos(grid))
            self._ellipse.set_data(radii * np.cos(grid), radii * np.sin(grid))
            self._last_ecc = ecc
            self._background = None
        rad = 1.0 / (1.0 + ecc * math.cos(nu))
        px, py = rad * math.cos(nu), rad * math.sin(nu)
        self._sat.set_data([px], [py])
        self._radius.set_data([0.0, px], [0.0, py])

        if self.render_mode == "human":
            if self._show:
                self.fig.canvas.draw_idle()
                self._plt.pause(1.0 / 30.0)
            else:
                self.fig.canvas.draw()
            return None
        canvas: Any = self.fig.canvas
        if self._background is None:
            canvas.draw()
            self._background = canvas.copy_from_bbox(self.fig.bbox)
        else:
            canvas.restore_region(self._background)
        for artist in self._dynamic:
            self.fig.draw_artist(artist)
        return np.asarray(canvas.buffer_rgba())[:, :, :3].copy()

    def close(self) -> None:
        """Release the figure (closes the window in "human" mode); safe to call twice."""
        if self._plt is not None and self.fig is not None:
            self._plt.close(self.fig)
        self.fig = None
