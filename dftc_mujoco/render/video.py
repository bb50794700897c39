"""Offscreen video of a run, drawn from its records (``log.npz``, ``summary.json``).

A private copy of the run's scene (:class:`RecordedScene`, which is also what
``python -m dftc_mujoco.plot RUN --web`` replays in a browser) is re-posed from the
logged positions at each video frame (linear interpolation between log samples) and
rendered with
``mujoco.Renderer`` through an orthographic top-down camera that follows the
team. On top of the MuJoCo scene: each robot's trail, the desired centroid
path, a ghost of the desired formation, a ring while a robot avoids an
obstacle, robot colours by state, and a text overlay (time, latest events,
robot numbers, legend) drawn with Pillow.
"""

from __future__ import annotations

import errno
import shutil
import warnings
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from ..core.events import Kind, describe
from ..errors import RenderError
from ..scenario import Scenario
from ..sim import fleet
from ..sim import scene as scene_mod
from . import gl
from .display import LINKS, STATES, link_state, robot_state
from .options import VideoOptions, frame_times

AVOIDING = (0.1, 0.75, 0.3, 0.55)
GHOST_ALPHA = 0.28
SAFE = (0.35, 0.35, 0.4, 0.9)
PATH = (0.15, 0.3, 0.95, 0.8)


class RecordedScene:
    """A private copy of a run's scene, posed from its records at any time (no GL): what
    the video draws and what ``python -m dftc_mujoco.plot RUN --web`` replays."""

    def __init__(
        self, scenario: Scenario, log: dict[str, np.ndarray], summary: dict[str, Any]
    ) -> None:
        self.log = log
        self.summary = summary
        self.t = log["t"]
        if len(self.t) < 2:
            raise RenderError("the log has fewer than two samples: nothing to render")
        team = fleet.load(scenario.team.models, "team.robot_model", scenario.directory)
        self.footprint = team.envelope.footprint_radius
        self.scene = scene_mod.build(scenario, team if team.mixed else team.envelope)
        self.model = self.scene.model
        self.data = mujoco.MjData(self.model)
        self.n = log["x"].shape[1]
        self.hull_geoms = [scene_mod.state_geoms(self.model, b) for b in self.scene.body]
        self.captions = captions(summary)
        self._bias_from = _bias_start(summary, self.n)

    def _index(self, t: float) -> tuple[int, float]:
        j = int(np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self.t) - 2))
        a = float(np.clip((t - self.t[j]) / (self.t[j + 1] - self.t[j]), 0.0, 1.0))
        return j, a

    def _lerp(self, name: str, j: int, a: float) -> np.ndarray:
        v = self.log[name]
        return (1 - a) * v[j] + a * v[j + 1]

    def positions(self, t: float) -> np.ndarray:
        """Logged robot positions interpolated at ``t``, (N, 2)."""
        j, a = self._index(t)
        return self._lerp("x", j, a)

    def states(self, t: float) -> list[str]:
        """Each robot's state at ``t``: healthy, compensating, flagged or excluded."""
        j, a = self._index(t)
        k = j + 1 if a >= 1.0 else j
        active, flagged = self.log["active"][k], self.log["flagged"][k]
        return [
            robot_state(bool(active[i]), bool(flagged[i]), t >= self._bias_from[i])
            for i in range(self.n)
        ]

    def desired(self, t: float) -> np.ndarray:
        """Each member's desired slot (N, 2) at the log sample before ``t`` (NaN: none)."""
        return self.log["x_d"][self._index(t)[0]]

    def pose(self, t: float) -> tuple[int, float, np.ndarray]:
        """Put the scene's robots where the log has them at ``t`` (``data.qpos``, and the
        kinematics); the log sample before ``t``, the fraction of the way to the next and
        the robots' positions (N, 2)."""
        j, a = self._index(t)
        x = self._lerp("x", j, a)
        pose = self._lerp("pose", j, a)
        yaw0, yaw1 = self.log["pose"][j, :, 2], self.log["pose"][j + 1, :, 2]
        pose[:, 2] = yaw0 + a * np.angle(np.exp(1j * (yaw1 - yaw0)))  # shortest turn
        scene_mod.place(self.scene, self.data, pose)
        self.data.time = t
        mujoco.mj_kinematics(self.model, self.data)
        return j, a, x


class FrameRenderer(RecordedScene):
    """Renders frames of a recorded run; use as a context manager (it owns a GL context)."""

    def __init__(
        self,
        scenario: Scenario,
        log: dict[str, np.ndarray],
        summary: dict[str, Any],
        options: VideoOptions | None = None,
    ) -> None:
        options = options or VideoOptions()
        self.options = options
        super().__init__(scenario, log, summary)
        m = self.model
        m.vis.global_.offwidth = max(m.vis.global_.offwidth, options.width)
        m.vis.global_.offheight = max(m.vis.global_.offheight, options.height)
        if options.quality:
            m.vis.quality.shadowsize = 4096
            m.vis.quality.offsamples = 4
        for geoms in self.hull_geoms:
            m.geom_matid[geoms] = -1  # the state colour replaces the robot's material
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # glfw warns before it fails
                self.renderer = mujoco.Renderer(m, options.height, options.width, max_geom=20000)
        except Exception as exc:
            raise gl.explain(exc) from None
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        self.camera.orthographic = 1
        self.camera.azimuth, self.camera.elevation = 90.0, -90.0
        self._track = self._camera_track()
        self._font = ImageFont.load_default()

    # ------------------------------------------------------------------ resources

    def close(self) -> None:
        """Free the GL context."""
        if getattr(self, "renderer", None) is not None:
            self.renderer.close()
            self.renderer = None

    def __enter__(self) -> FrameRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ geometry

    def _camera_track(self) -> np.ndarray:
        """(T, 3): centre x, y and view height, smoothed so the team stays in view."""
        x = np.where(self.log["active"][..., None], self.log["x"], np.nan)
        x_d = self.log["x_d"]
        pts = np.concatenate([x, x_d], axis=1)
        lo, hi = np.nanmin(pts, axis=1), np.nanmax(pts, axis=1)
        aspect = self.options.width / self.options.height
        margin = 0.6 + 2 * self.footprint
        half = np.maximum((hi - lo)[:, 1] / 2, (hi - lo)[:, 0] / 2 / aspect) + margin
        half = np.maximum(half, 1.5)
        centre = (lo + hi) / 2
        dt = float(np.median(np.diff(self.t)))
        w = max(1, round(2.0 / dt))  # ±2 s
        half = _moving(half, w, np.max)
        half = _moving(half, w, np.mean)
        centre = np.stack([_moving(centre[:, j], w, np.mean) for j in range(2)], axis=1)
        return np.column_stack([centre, 2 * half])

    def view(self, t: float) -> tuple[np.ndarray, float]:
        """Camera centre (x, y) and view height [m] at time ``t``."""
        j, a = self._index(t)
        c = (1 - a) * self._track[j] + a * self._track[j + 1]
        return c[:2], float(c[2])

    def project(self, xy: np.ndarray, t: float) -> np.ndarray:
        """Pixel (column, row) of world points ``xy`` (..., 2) in the frame at time ``t``."""
        centre, height = self.view(t)
        scale = self.options.height / height  # pixels per metre
        col = self.options.width / 2 + (xy[..., 0] - centre[0]) * scale
        row = self.options.height / 2 - (xy[..., 1] - centre[1]) * scale
        return np.stack([col, row], axis=-1)

    # ------------------------------------------------------------------ drawing

    def frame(self, t: float) -> np.ndarray:
        """The frame at time ``t``: (height, width, 3) uint8."""
        j, _, x = self.pose(t)
        colours = dict(STATES)
        states = self.states(t)
        for i, st in enumerate(states):
            self.model.geom_rgba[self.hull_geoms[i]] = colours[st]
        centre, height = self.view(t)
        self.camera.lookat[:] = [centre[0], centre[1], 0.0]
        self.camera.distance = 20.0
        self.model.vis.global_.fovy = height  # orthographic: the view height in metres
        self.renderer.update_scene(self.data, self.camera)
        scn = self.renderer.scene
        self._draw_path(scn, j)
        self._draw_trails(scn, j, x, states)
        self._draw_ghost(scn, j, states)
        self._draw_safe_circles(scn)
        self._draw_rings(scn, j, x)
        self._draw_links(scn, j, x)
        img = self.renderer.render()
        return self._overlay(img, t, x, states)

    def _add(self, scn: mujoco.MjvScene) -> mujoco.MjvGeom | None:
        if scn.ngeom >= scn.maxgeom:
            return None
        g = scn.geoms[scn.ngeom]
        scn.ngeom += 1
        return g

    def _segment(self, scn, p0, p1, width, rgba, z=0.002) -> None:
        """A GL line of ``width`` pixels (lines cost far less than capsule meshes)."""
        g = self._add(scn)
        if g is None:
            return
        mujoco.mjv_initGeom(
            g,
            mujoco.mjtGeom.mjGEOM_LINE,
            np.zeros(3),
            np.zeros(3),
            np.eye(3).ravel(),
            np.asarray(rgba, np.float32),
        )
        mujoco.mjv_connector(
            g,
            mujoco.mjtGeom.mjGEOM_LINE,
            width,
            np.array([p0[0], p0[1], z]),
            np.array([p1[0], p1[1], z]),
        )

    def _disc(self, scn, xy, radius, rgba, z=0.003, thickness=0.001) -> None:
        g = self._add(scn)
        if g is None:
            return
        mujoco.mjv_initGeom(
            g,
            mujoco.mjtGeom.mjGEOM_CYLINDER,
            np.array([radius, thickness, 0.0]),
            np.array([xy[0], xy[1], z]),
            np.eye(3).ravel(),
            np.asarray(rgba, np.float32),
        )

    def _draw_path(self, scn, j) -> None:
        c = self.log["c_d"]
        step = max(1, len(c) // 150)
        pts = c[::step]
        for k in range(0, len(pts) - 1, 2):  # dashed
            self._segment(scn, pts[k], pts[k + 1], 3.0, PATH, z=0.001)

    def _draw_trails(self, scn, j, x_now, states) -> None:
        dt = float(np.median(np.diff(self.t)))
        stride = max(1, round(0.2 / dt))
        start = 0
        if np.isfinite(self.options.trail_seconds):
            start = max(0, j - round(self.options.trail_seconds / dt))
        idx = np.arange(start, j + 1, stride)
        hist = self.log["x"][idx]
        colours = dict(STATES)
        for i in range(self.n):
            rgba = np.array(colours[states[i]])
            rgba[3] = 0.7
            pts = np.vstack([hist[:, i], x_now[i]])
            for k in range(len(pts) - 1):
                self._segment(scn, pts[k], pts[k + 1], 2.0, rgba)

    def _draw_ghost(self, scn, j, states) -> None:
        """Each member's desired slot: a faint disc in the robot's colour."""
        colours = dict(STATES)
        for i, xy in enumerate(self.log["x_d"][j]):
            if np.isfinite(xy).all():
                rgba = np.array(colours[states[i]])
                rgba[3] = GHOST_ALPHA
                self._disc(scn, xy, 0.6 * self.footprint, rgba, z=0.004)

    def _draw_safe_circles(self, scn) -> None:
        """The safe distance d around each cylinder, dashed."""
        ang = np.linspace(0, 2 * np.pi, 49)
        for ox, oy, _, d in self.log["obstacles"]:
            pts = np.c_[ox + d * np.cos(ang), oy + d * np.sin(ang)]
            for k in range(0, len(pts) - 1, 2):
                self._segment(scn, pts[k], pts[k + 1], 1.5, SAFE, z=0.001)

    def _draw_links(self, scn, j, x) -> None:
        """Over a network, each link between members from sender to receiver, coloured by
        the age of the message it holds (live, delayed within the round, dropped beyond it),
        offset to its right so that the two directions of a pair show apart; dashed when
        dropped."""
        if "link_age" not in self.log:
            return
        fresh, whole = (float(b) for b in self.log["link_bounds"])
        colours = dict(LINKS)
        active = self.log["active"][j]
        for (a, b), age in zip(self.log["links"], self.log["link_age"][j], strict=True):
            if not (active[a - 1] and active[b - 1]):
                continue
            p0, p1 = x[a - 1], x[b - 1]
            d = p1 - p0
            length = float(np.hypot(*d))
            if length < 1e-9:
                continue
            side = np.array([d[1], -d[0]]) / length * 0.03
            state = link_state(float(age), fresh, whole)
            pieces = 6 if state == "dropped" else 1
            for k in range(0, pieces, 2 if pieces > 1 else 1):
                q0 = p0 + d * (k / pieces) + side
                q1 = p0 + d * ((k + 1) / pieces) + side
                self._segment(scn, q0, q1, 1.5, colours[state], z=0.0015)

    def _draw_rings(self, scn, j, x) -> None:
        for i in np.flatnonzero(self.log["reactive"][j]):
            self._disc(scn, x[i], self.footprint + 0.03, AVOIDING, z=0.005)

    def _overlay(self, img: np.ndarray, t: float, x: np.ndarray, states: list[str]) -> np.ndarray:
        pil = Image.fromarray(img)
        draw = ImageDraw.Draw(pil)
        font = self._font
        draw.rectangle([0, 0, self.options.width, 18], fill=(255, 255, 255))
        draw.text(
            (6, 3),
            f"{self.summary.get('scenario', '')}   t = {t:6.2f} s",
            fill=(0, 0, 0),
            font=font,
        )
        recent = [e for e in self.captions if e[0] <= t + 1e-9][-4:]
        for k, (te, text) in enumerate(recent):
            draw.text((6, 22 + 13 * k), f"{te:6.2f} s  {text}", fill=(20, 20, 20), font=font)
        pix = self.project(x, t)
        off = self.footprint * self.options.height / self.view(t)[1] * 0.8 + 2
        for i, (c, r) in enumerate(pix):
            if 0 <= c < self.options.width and 0 <= r < self.options.height:
                pos = (c + off, r - off - 10)
                draw.rectangle(draw.textbbox(pos, str(i + 1), font=font), fill=(255, 255, 255))
                draw.text(pos, str(i + 1), fill=(0, 0, 0), font=font)
        y0 = self.options.height - 16
        xpos = 6
        for name, rgba in STATES:
            col = tuple(int(255 * v) for v in rgba[:3])
            draw.rectangle([xpos, y0 + 2, xpos + 9, y0 + 11], fill=col)
            draw.text((xpos + 13, y0), name, fill=(0, 0, 0), font=font)
            xpos += 20 + 7 * len(name)
        ring = tuple(int(255 * v) for v in AVOIDING[:3])
        draw.ellipse([xpos, y0 + 1, xpos + 10, y0 + 11], outline=ring, width=2)
        draw.text((xpos + 14, y0), "avoiding", fill=(0, 0, 0), font=font)
        xpos += 80
        draw.ellipse([xpos, y0 + 1, xpos + 10, y0 + 11], fill=(205, 215, 240))
        draw.text((xpos + 14, y0), "desired slot", fill=(0, 0, 0), font=font)
        if "link_age" in self.log:  # the links' legend, above the robots'
            xpos, y0 = 6, y0 - 15
            for name, rgba in LINKS:
                col = tuple(int(255 * v) for v in rgba[:3])
                draw.line([xpos, y0 + 6, xpos + 12, y0 + 6], fill=col, width=3)
                draw.text((xpos + 16, y0), f"link {name}", fill=(0, 0, 0), font=font)
                xpos += 30 + 7 * len(name) + 28
        return np.asarray(pil)


def _moving(a: np.ndarray, w: int, fn) -> np.ndarray:
    pad = np.pad(a, (w, w), mode="edge")
    win = np.lib.stride_tricks.sliding_window_view(pad, 2 * w + 1)
    return fn(win, axis=1)


def _bias_start(summary: dict[str, Any], n: int) -> np.ndarray:
    start = np.full(n, np.inf)
    for f in summary.get("faults", []):
        if f["kind"] == "bias":
            start[f["robot"] - 1] = min(start[f["robot"] - 1], f["t"])
    return start


def captions(summary: dict[str, Any]) -> list[tuple[float, str]]:
    """Fault injections, each robot's first detection, and exclusions, in time order, in the
    words of :func:`dftc_mujoco.core.events.describe`."""
    ev = [
        (f["t"], describe({"kind": Kind.FAULT, "robot": f["robot"], "fault": f["kind"]}))
        for f in summary.get("faults", [])
    ]
    seen: set[int] = set()
    for d in sorted(summary.get("detections", []), key=lambda d: d["t"]):
        if d["robot"] not in seen:
            seen.add(d["robot"])
            flag = {"kind": Kind.DETECTION, "by": d["by"], "robot": d["robot"]}
            ev.append((d["t"], describe(flag) + " (first detection)"))
    ev += [
        (e["t"], describe({"kind": Kind.EXCLUSION, "flagged_by": [], **e}))
        for e in summary.get("exclusions", [])
    ]
    return sorted(ev)


def write_video(
    path: Path,
    scenario: Scenario,
    log: dict[str, np.ndarray],
    summary: dict[str, Any],
    options: VideoOptions | None = None,
    progress: bool = False,
) -> int:
    """Render the run to an H.264 MP4 at ``path`` (atomically); returns the frame count
    (0, and nothing written, for a run that logged no period: it stopped in its first)."""
    if not len(log["t"]):
        return 0
    options = options or VideoOptions()
    import imageio.v2 as imageio
    from tqdm.auto import tqdm

    duration = float(log["t"][-1])
    times = frame_times(duration, options.fps)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp.mp4")
    params = (
        ["-preset", "slow", "-crf", "18"]
        if options.quality
        else ["-preset", "veryfast", "-crf", "23"]
    )
    try:
        with FrameRenderer(scenario, log, summary, options) as fr:
            writer = imageio.get_writer(
                str(tmp),
                fps=options.fps,
                codec="libx264",
                quality=None,
                pixelformat="yuv420p",
                macro_block_size=8,
                ffmpeg_params=params,
                ffmpeg_log_level="quiet",  # a failure is reported once, by encoder_error
            )
            try:
                try:
                    for t in tqdm(
                        times,
                        disable=not progress,
                        unit="frame",
                        desc="video",
                        leave=False,
                        mininterval=0.5,
                    ):
                        writer.append_data(fr.frame(float(t)))
                finally:
                    writer.close()
            except (OSError, RuntimeError) as exc:
                raise encoder_error(tmp, exc) from None
        tmp.replace(path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return len(times)


def encoder_error(path: Path, exc: BaseException) -> OSError:
    """A one-line OSError for a failed ffmpeg encode into ``path``: ENOSPC when the
    disk is full (ffmpeg itself only shows up as a broken pipe), else what was said."""
    try:
        full = shutil.disk_usage(path.parent).free < 2**20
    except OSError:
        full = False
    if full:
        return OSError(errno.ENOSPC, "No space left on device", str(path))
    first = str(exc).strip().splitlines()
    return OSError(errno.EIO, f"the video encoder (ffmpeg) failed: {first[0] if first else exc}")
