"""Real offscreen rendering (EGL on the CPU), real ffmpeg, real matplotlib."""

import json
import os
import subprocess
import sys

import imageio.v3 as iio
import numpy as np
import pytest
from PIL import Image

from dftc_mujoco import plot, run, scenario
from dftc_mujoco.render import figures
from tests.conftest import needs_gl


@pytest.fixture(scope="module")
def paper_run(tmp_path_factory):
    """The full paper case, records and figures, no video (the video tests render their own)."""
    out = tmp_path_factory.mktemp("paper_case")
    assert run.main(["paper_case", "--out", str(out), "--no-video", "--no-progress"]) == 0
    with np.load(out / "log.npz") as f:
        log = {k: f[k] for k in f.files}
    return out, log, json.loads((out / "summary.json").read_text())


@needs_gl
def test_two_second_clip_decodes_to_the_expected_frames(tmp_path, capsys):
    code = run.main(["paper_case", "--duration", "2", "--out", str(tmp_path), "--no-progress"])
    assert code == 0
    frames = list(iio.imiter(tmp_path / "video.mp4"))
    assert len(frames) == 2 * 30 + 1
    assert frames[0].shape == (480, 640, 3)
    assert "rendered and encoded at" in capsys.readouterr().out
    # other sizes and rates
    code = run.main(
        [
            "paper_case",
            "--duration",
            "2",
            "--out",
            str(tmp_path / "small"),
            "--fps",
            "10",
            "--size",
            "320x240",
            "--no-progress",
        ]
    )
    assert code == 0
    frames = list(iio.imiter(tmp_path / "small" / "video.mp4"))
    assert len(frames) == 21 and frames[0].shape == (240, 320, 3)


def _chroma(rgb):
    v = np.asarray(rgb, float)
    return v / np.linalg.norm(v)


def _state_at(img, pixel):
    from dftc_mujoco.render.video import STATES

    c, r = np.round(pixel).astype(int)
    patch = img[r - 1 : r + 2, c - 1 : c + 2].reshape(-1, 3).mean(axis=0)
    scores = {name: _chroma(patch) @ _chroma(rgba[:3]) for name, rgba in STATES}
    return max(scores, key=scores.get), patch


@needs_gl
def test_robot_colours_sit_where_the_camera_projects_them_and_follow_them(paper_run):
    from dftc_mujoco.render.video import FrameRenderer

    _, log, summary = paper_run
    s = scenario.load("paper_case")
    with FrameRenderer(s, log, summary) as fr:
        seen = {}
        for t in (5.0, 15.0, 30.0):
            img = fr.frame(t)
            pix = fr.project(fr.positions(t), t)
            seen[t] = pix
            for i, st in enumerate(fr.states(t)):
                found, patch = _state_at(img, pix[i])
                assert found == st, (t, i + 1, patch)
                # the robot's colour is really there: not the floor's grey
                assert np.ptp(patch) > 60 or st == "excluded"
        # the robots moved, and so did their pixels (beyond a hull radius of ~14 px)
        world = np.linalg.norm(fr.positions(30.0) - fr.positions(5.0), axis=1)
        assert world.min() > 1.0
        # robot 2 is amber while it compensates its bias
        assert fr.states(30.0)[1] == "compensating"
        assert np.linalg.norm(seen[15.0] - seen[5.0], axis=1).min() > 0.0
        # where robot 1 was at 5 s there is floor at 30 s, seen in the 30 s frame's own pixels
        img30 = fr.frame(30.0)
        old = fr.project(fr.positions(5.0)[:1], 30.0)[0]
        h, w = img30.shape[:2]
        if 0 <= old[0] < w and 0 <= old[1] < h:
            c, r = np.round(old).astype(int)
            assert np.ptp(img30[r, c]) < 40  # grey floor or trail, not a robot


@needs_gl
def test_flagged_then_excluded_robot_changes_colour(paper_run):
    from dftc_mujoco.render.video import FrameRenderer

    _, log, summary = paper_run
    t_flag = min(d["t"] for d in summary["detections"] if d["robot"] == 1 and d["by"] != 1)
    t_excl = summary["exclusions"][0]["t"]
    s = scenario.load("paper_case")
    with FrameRenderer(s, log, summary) as fr:
        colours = {}
        for label, t in (("before", 40.0), ("flagged", t_flag + 0.5), ("excluded", t_excl + 2)):
            img = fr.frame(t)
            colours[label] = _state_at(img, fr.project(fr.positions(t), t)[0])[0]
    assert colours == {"before": "healthy", "flagged": "flagged", "excluded": "excluded"}


def test_every_figure_is_a_valid_png(paper_run):
    out, _, _ = paper_run
    paths = sorted((out / "figures").glob("*.png"))
    assert [p.stem for p in paths] == sorted(figures.FIGURES)
    for p in paths:
        assert p.stat().st_size > 10_000
        with Image.open(p) as im:
            im.verify()
        with Image.open(p) as im:
            assert im.format == "PNG" and im.size[0] > 500 and im.size[1] > 300


def test_plot_command_redraws_a_saved_run(paper_run, capsys):
    out, _, _ = paper_run
    for p in (out / "figures").glob("*.png"):
        p.unlink()
    assert plot.main([str(out)]) == 0
    assert len(list((out / "figures").glob("*.png"))) == len(figures.FIGURES)
    assert plot.main([str(out / "nothing_here")]) == 2
    assert "missing" in capsys.readouterr().err


@needs_gl
def test_plot_command_rerenders_the_video(tmp_path):
    assert (
        run.main(
            ["paper_case", "--duration", "1", "--out", str(tmp_path), "--no-video", "--no-progress"]
        )
        == 0
    )
    assert not (tmp_path / "video.mp4").exists()
    assert plot.main([str(tmp_path), "--video", "--fps", "10"]) == 0
    assert len(list(iio.imiter(tmp_path / "video.mp4"))) == 11


def test_figures_adapt_to_other_teams(tmp_path):
    """N = 6, two stops, no bias: every figure still draws."""
    from dftc_mujoco.closed_loop.loop import simulate
    from tests.conftest import make, ring_team, scenario_dict

    d = scenario_dict()
    d["team"] = ring_team(6, 0.5, chord=2)
    d["faults"] = [{"robot": 1, "kind": "stop", "t": 5.0}]
    d["duration"] = 15.0
    d["fdir"]["initial_error_bound"] = "auto"  # paper_case's 1 m is below this start
    r = simulate(make(d))
    paths = figures.draw_all(r.log, r.summary, tmp_path)
    assert len(paths) == len(figures.FIGURES) and all(p.stat().st_size > 10_000 for p in paths)


def _cli(*args, env=None):
    return subprocess.run(
        [sys.executable, "-m", "dftc_mujoco.run", *args],
        capture_output=True,
        text=True,
        timeout=900,
        env={**os.environ, **(env or {})},
    )


@pytest.mark.skipif(
    os.path.exists("/usr/lib/x86_64-linux-gnu/libOSMesa.so.8"),
    reason="OSMesa is installed here, so it cannot be shown missing",
)
def test_missing_backend_is_one_line_with_the_fix_and_no_video_still_runs(tmp_path):
    p = _cli("paper_case", "--gl", "osmesa", "--duration", "1", "--out", str(tmp_path))
    assert p.returncode == 4
    assert p.stderr.count("\n") <= 3 and "Traceback" not in p.stderr
    assert "apt-get install libosmesa6" in p.stderr and "--no-video" in p.stderr
    assert not (tmp_path / "summary.json").exists()  # failed before simulating
    p = _cli(
        "paper_case", "--gl", "osmesa", "--no-video", "--duration", "1", "--out", str(tmp_path)
    )
    assert p.returncode == 0 and (tmp_path / "summary.json").exists()


def test_glfw_without_a_display_says_so(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    p = subprocess.run(
        [
            sys.executable,
            "-m",
            "dftc_mujoco.run",
            "paper_case",
            "--gl",
            "glfw",
            "--duration",
            "1",
            "--out",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        timeout=900,
        env=env,
    )
    assert p.returncode == 4
    assert "GLFW needs a display" in p.stderr and "Traceback" not in p.stderr


def test_large_teams_show_the_robots_worth_showing():
    """N = 16, robot 11 stops: the residual grid's observers are the faulty robot, the first
    and the last teammate to flag it and the healthy robots nearest a false flag; its first
    column is robot 11 (the grid used to show robots 1-6 only, never an observer that
    flagged late); the inputs figure shows robot 11 among eight robots, not all sixteen."""
    from dftc_mujoco.closed_loop.loop import simulate
    from tests.conftest import make, scenario_dict

    d = scenario_dict()
    d["team"] = {
        "robots": 16,
        "initial_positions": {"layout": "formation", "jitter": 0.02},
        "graph": {"family": "ring_chords", "chords": [2, 5]},
    }
    d["mission"]["formation"] = {"shape": "grid", "side": 0.6}
    d["mission"]["centroid"] = {"waypoints": [[0, 0], [20, 0]], "speed": 0.1}
    d["obstacles"], d["duration"] = [], 12.0
    d["faults"] = [{"robot": 11, "kind": "stop", "t": 6.0}]
    d["onboard"] = {"thresholds": "l1"}
    r = simulate(make(d))
    flags = sorted((e for e in r.summary["detections"] if e["robot"] == 11), key=lambda e: e["t"])
    assert len(flags) >= 3
    first, last = flags[0]["by"], flags[-1]["by"]
    figs = figures.make_all(r.log, r.summary)
    grid = figs["fig5_8_residuals"].axes
    observers = [ax.get_ylabel() for ax in grid if ax.get_ylabel()]
    monitored = [ax.get_title() for ax in grid if ax.get_title()]
    assert len(observers) == 6 and len(monitored) == 6
    assert observers[0] == "i = 11" and monitored[0] == "k = 11"
    assert {f"i = {first}", f"i = {last}"} <= set(observers)
    inputs = [ax.get_ylabel() for ax in figs["fig10_inputs"].axes]
    assert len(inputs) == 8 and "u11 [m/s]" in inputs


@needs_gl
def test_a_run_over_a_network_draws_its_links_and_its_timeline(tmp_path):
    """Over a network with robot 3 silent from 10 s: figures/network.png is drawn, the link
    3 -> 4 is dropped (red, dashed) in a frame after it and live (green) before."""
    from dftc_mujoco.render.display import LINK_DROPPED, LINK_LIVE
    from dftc_mujoco.render.video import FrameRenderer

    over = [
        *("--set", "network.latency=0.02", "--set", "onboard.thresholds=l1"),
        *("--set", "gains.ko=3.0", "--set", 'faults=[{robot=3,kind="silent",t=10.0}]'),
    ]
    assert (
        run.main(
            [
                "paper_case",
                "--duration",
                "15",
                "--out",
                str(tmp_path),
                "--no-video",
                "--no-progress",
                *over,
            ]
        )
        == 0
    )
    assert (tmp_path / "figures" / "network.png").stat().st_size > 10_000
    with np.load(tmp_path / "log.npz") as f:
        log = {k: f[k] for k in f.files}
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert [3, 4] in log["links"].tolist()
    s = scenario.load("paper_case")
    with FrameRenderer(s, log, summary) as fr:
        for t, colour in ((8.0, LINK_LIVE), (13.0, LINK_DROPPED)):
            img = fr.frame(t).astype(int)
            a, b = fr.project(fr.positions(t)[[2, 3]], t)
            mid = (a + b) / 2  # near the link's middle (it is offset by 3 cm)
            c, r = np.round(mid).astype(int)
            patch = img[r - 6 : r + 7, c - 6 : c + 7].reshape(-1, 3)
            want = np.array(colour[:3]) * 255
            assert np.abs(patch - want).sum(axis=1).min() < 90, (t, patch.min(0), want)
