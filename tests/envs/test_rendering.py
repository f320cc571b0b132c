"""ChainRenderer and the env's render(): frames, geometry, slack marking, modes."""

from __future__ import annotations

import importlib
import math
import sys
import time

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import DependencyNotInstalled

import tether_gym.envs as envs_pkg
from tether_gym.envs import EnvConfig
from tether_gym.envs.rendering import FRAME_SIZE, ChainRenderer

from .conftest import no_unexpected_warnings

TAB_BLUE = np.array([31, 119, 180])  # subsatellites
TAB_RED = np.array([214, 39, 40])  # slack tethers


def _info(theta=(0.0, 0.0), length=(0.5, 0.5), tension=(3.0, 2.4), nu=0.0, theta_ref=0.0,
          failure=None):
    n = len(theta)
    return {"nu": nu, "theta": np.array(theta, float), "dtheta": np.zeros(n),
            "length": np.array(length, float), "dlength": np.zeros(n),
            "tension": np.array(tension, float), "tension_min": np.array(tension, float),
            "theta_ref": theta_ref, "dtheta_ref": 0.0, "failure": failure}


def _count(frame, colour, tol=12):
    return int(np.all(np.abs(frame.astype(int) - colour) <= tol, axis=-1).sum())


def _pixel(renderer, axes, x, y):
    """Row, column of data point (x, y) of ``axes`` in a frame."""
    px, py = axes.transData.transform((x, y))
    return int(round(FRAME_SIZE - py)), int(round(px))


@pytest.fixture
def renderer():
    r = ChainRenderer(EnvConfig.from_kwargs(), "rgb_array")
    yield r
    r.close()


def test_rgb_frame_shape_dtype_and_motion(make_env):
    env = make_env(render_mode="rgb_array")
    env.reset(seed=0)
    with no_unexpected_warnings(allowed=()):
        first = env.render()
        again = env.render()
        assert first.shape == (FRAME_SIZE, FRAME_SIZE, 3) and first.dtype == np.uint8
        assert np.array_equal(first, again)  # same state, same frame
        assert len(np.unique(first.reshape(-1, 3), axis=0)) > 20  # not blank
        for _ in range(40):
            env.step(np.array([0.5, -0.5], np.float32))
        moved = env.render()
    changed = np.any(first != moved, axis=-1).mean()
    assert changed > 0.002, changed  # the chain, text and orbit marker moved


def test_chain_geometry_trailing_is_left(renderer):
    """theta > 0 (body trails) puts the bodies left of the local vertical, and back."""
    cx = _pixel(renderer, renderer.ax, 0.0, 0.0)[1]
    for sign in (1.0, -1.0):
        frame = renderer.draw(_info(theta=(0.4 * sign, 0.4 * sign)), 0.2)
        rows, cols = np.nonzero(np.all(np.abs(frame.astype(int) - TAB_BLUE) <= 12, axis=-1))
        assert cols.size > 50
        assert np.sign(cx - cols.mean()) == sign
        # the lower body sits where paper Eq. 1 puts it: -sum l (sin th, cos th)
        x2, y2 = -np.sin(0.4 * sign), -np.cos(0.4 * sign)
        r, c = _pixel(renderer, renderer.ax, x2, y2)
        assert np.all(np.abs(frame[r, c].astype(int) - TAB_BLUE) <= 12)


def test_tension_colour_and_slack_marking(renderer):
    import matplotlib

    norm = matplotlib.colors.Normalize(0.0, renderer.tension_max)
    viridis = matplotlib.colormaps["viridis"]
    theta = (0.5, 0.5)
    mid1 = (-0.25 * math.sin(0.5), -0.25 * math.cos(0.5))  # middle of tether 1
    mid2 = (-0.75 * math.sin(0.5), -0.75 * math.cos(0.5))
    taut = renderer.draw(_info(theta=theta, tension=(1.0, 5.0)), 0.2)
    for mid, tension in ((mid1, 1.0), (mid2, 5.0)):
        r, c = _pixel(renderer, renderer.ax, *mid)
        want = np.array(viridis(norm(tension))[:3]) * 255
        assert np.all(np.abs(taut[r, c] - want) <= 3), (taut[r, c], want)
    assert _count(taut, TAB_RED) < 20
    slack = renderer.draw(_info(theta=theta, tension=(1.0, -0.5)), 0.2)
    assert _count(slack, TAB_RED) > 80  # tether 2 red and dashed (122 px measured)
    assert "SLACK" in renderer._text.get_text()
    # slack during the step (tension_min) is marked even if T^ recovered at its end
    info = _info(theta=theta, tension=(1.0, 0.8))
    info["tension_min"] = np.array([1.0, -0.1])
    assert _count(renderer.draw(info, 0.2), TAB_RED) > 80


def test_orbit_inset_marks_true_anomaly(renderer):
    for ecc in (0.0, 0.2):
        for nu in (0.0, 0.5 * math.pi, math.pi, 4.0):
            frame = renderer.draw(_info(nu=nu), ecc)
            radius = 1.0 / (1.0 + ecc * math.cos(nu))  # r / p
            inset = renderer.fig.axes[-1]
            r, c = _pixel(renderer, inset, radius * math.cos(nu), radius * math.sin(nu))
            assert frame[r, c].max() < 80, (ecc, nu, frame[r, c])  # the dark marker
    # text reports nu in orbits
    renderer.draw(_info(nu=math.pi), 0.2)
    assert "0.500 orbits" in renderer._text.get_text()


def test_figure_reused_and_limits_fixed(renderer):
    limits = (renderer.ax.get_xlim(), renderer.ax.get_ylim())
    counts = (len(renderer.ax.lines), len(renderer.ax.texts), len(renderer.fig.axes))
    fig = renderer.fig
    for k in range(10):
        renderer.draw(_info(theta=(0.1 * k, -0.1 * k), length=(0.3 + 0.05 * k, 0.6)), 0.1 * k)
    assert renderer.fig is fig
    assert (renderer.ax.get_xlim(), renderer.ax.get_ylim()) == limits
    assert (len(renderer.ax.lines), len(renderer.ax.texts), len(renderer.fig.axes)) == counts


def test_blitted_frames_equal_full_redraws(renderer):
    """The cached background (static part) is exact and follows a change of e."""
    states = [(_info(theta=(0.3, -0.2), tension=(2.0, -1.0), nu=1.0), 0.2),
              (_info(theta=(-0.1, 0.4), length=(0.7, 0.4), nu=3.0, failure="slack"), 0.45),
              (_info(nu=5.0), 0.45)]
    for info, ecc in states:
        blitted = renderer.draw(info, ecc)
        fresh = ChainRenderer(EnvConfig.from_kwargs(), "rgb_array")
        for artist in fresh._dynamic:  # render everything in one full draw
            artist.set_animated(False)
        fresh.draw(info, ecc)
        fresh.fig.canvas.draw()
        full = np.asarray(fresh.fig.canvas.buffer_rgba())[:, :, :3]
        fresh.close()
        assert np.array_equal(blitted, full), np.any(blitted != full, axis=-1).sum()


def test_frame_time(renderer):
    """Frames are cheap: the figure is reused and blitted (~10 ms measured; loose bound)."""
    renderer.draw(_info(), 0.2)
    times = []
    for k in range(20):
        start = time.perf_counter()
        renderer.draw(_info(theta=(0.01 * k, 0.0), nu=0.1 * k), 0.2)
        times.append(time.perf_counter() - start)
    assert np.median(times) < 0.1, np.median(times)


def test_four_bodies_and_failure_text():
    r = ChainRenderer(EnvConfig.from_kwargs(n_bodies=4), "rgb_array")
    frame = r.draw(_info(theta=(0.1, 0.2, 0.3), length=(0.3, 0.3, 0.3), tension=(3, 2, 1),
                         failure="tumble"), 0.2)
    assert frame.shape == (FRAME_SIZE, FRAME_SIZE, 3)
    assert len(r._segments) == 3
    assert r._fail_text.get_text() == "failure: tumble"
    r.close()
    r.close()  # idempotent


def test_render_without_mode_warns_and_returns_none(make_env):
    env = make_env()
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None


def test_human_mode_without_display(make_env):
    with pytest.warns(UserWarning, match="no interactive backend") as record:
        env = make_env(render_mode="human")
        env.reset(seed=0)  # renders
        assert env.render() is None
        env.step(np.zeros(2, np.float32))
    assert sum("no interactive backend" in str(w.message) for w in record) == 1  # once
    env.close()
    env.close()


def test_missing_matplotlib(monkeypatch):
    """The module imports without matplotlib; using it names the pip command."""
    monkeypatch.setattr(envs_pkg, "rendering", envs_pkg.rendering)  # restored afterwards
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    monkeypatch.delitem(sys.modules, "tether_gym.envs.rendering")
    module = importlib.import_module("tether_gym.envs.rendering")
    hint = r'pip install -e "\.\[plot\]"'
    with pytest.raises(DependencyNotInstalled, match=hint):
        module.ChainRenderer(EnvConfig.from_kwargs(), "rgb_array")
    env = gym.make("tether_gym/TetherLibration-v2", render_mode="rgb_array")
    env.reset(seed=0)
    with pytest.raises(DependencyNotInstalled, match=hint):
        env.render()


def test_bad_render_mode():
    with pytest.raises(ValueError, match="render_mode='ansi'"):
        ChainRenderer(EnvConfig.from_kwargs(), "ansi")


def test_record_video(make_env, tmp_path):
    pytest.importorskip("moviepy")
    from gymnasium.wrappers import RecordVideo

    folder = tmp_path / "videos"  # a new folder: RecordVideo warns when it exists
    env = RecordVideo(make_env(render_mode="rgb_array", orbits_per_episode=0.05),
                      str(folder), episode_trigger=lambda _: True, disable_logger=True)
    env.reset(seed=0)
    steps = 0
    while True:
        steps += 1
        _, _, terminated, truncated, _ = env.step(np.zeros(2, np.float32))
        if terminated or truncated:
            break
    env.close()
    assert steps == math.ceil(0.05 * 2 * math.pi / 0.025)
    videos = list(folder.glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000
    from moviepy import VideoFileClip

    with VideoFileClip(str(videos[0])) as clip:
        assert tuple(clip.size) == (FRAME_SIZE, FRAME_SIZE)
        assert clip.duration == pytest.approx((steps + 1) / 30, abs=2 / 30)
