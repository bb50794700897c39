"""Watch a run in a web browser, live or replayed from its records: MuJoCo Studio's web
viewer (``mujoco.studio``, in the mujoco-studio package that mujoco 4 installs).

The viewer serves one HTTP port: the page, a WebAssembly client that draws the scene with
WebGL in the browser, and two WebSockets that carry the state and a small interface.
Nothing is drawn on this machine, so it needs no display and no OpenGL (a remote cluster:
``ssh -L PORT:localhost:PORT`` and open the page on your own machine). The browser keeps
the model it was sent once, so a robot's state is not shown by repainting its body: the
markers of the live viewer (``watch/viewer.py``: a sphere above each robot in its state's colour,
``render/display.py``; a disc at each desired slot) go with every state, and a panel says the time,
each robot's state and the latest faults, flags and exclusions (``events.describe``).

- live (``python -m dftc_mujoco.run SCENARIO --web``): :func:`serve_live` steps the
  :class:`~dftc_mujoco.closed_loop.loop.Simulation` in real time once a browser has opened the page;
- replay (``python -m dftc_mujoco.plot RUN --web``): :func:`serve_replay` poses a copy of
  the run's scene from its log (``render/video.py``'s :class:`RecordedScene`), in a loop.

The page is served to every interface of this machine (the web viewer binds them all), with
no password: anyone who can reach the port sees the run. Where the viewer cannot serve
(not installed, the port taken, it stopped), :class:`~dftc_mujoco.errors.ServeError` says
why in one line.
"""

import contextlib
import copy
import dataclasses
import io
import socket
import sys
import threading
import time
from collections.abc import Callable, Sequence
from types import SimpleNamespace
from typing import Any

import mujoco
import numpy as np

from ..core.events import Kind, describe
from ..errors import ServeError
from ..render.display import COLOURS, STATES
from .viewer import Marker, init_geom, markers, snapshot_states

#: frames per second sent to the browser (the browser draws at its own rate between them)
FPS = 30.0
#: the latest events the panel lists
RECENT = 6
#: up to this many robots the panel lists each one; beyond, how many are in each state
LISTED = 12

INSTALL = "pip install 'mujoco-studio>=4.0.1' (mujoco>=4.0.1 installs it)"


def studio() -> SimpleNamespace:
    """MuJoCo Studio's modules that serve the browser, or ServeError saying how to get them."""
    try:
        from mujoco.studio import launch_thread, messages, plugin, viewer_protocol, web_viewer
        from mujoco.studio.dear_imgui import dear_imgui as imgui
    except Exception as exc:  # not installed, too old, or its compiled part does not load
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise ServeError(
            f"--web needs MuJoCo Studio's web viewer (mujoco.studio.web_viewer), which cannot "
            f"be imported here ({type(exc).__name__}: {first}): {INSTALL}"
        ) from None
    return SimpleNamespace(
        launch_thread=launch_thread,
        messages=messages,
        plugin=plugin,
        viewer_protocol=viewer_protocol,
        web_viewer=web_viewer,
        imgui=imgui,
    )


def check(port: int) -> None:
    """Fail now, before a run is built, where ``--web`` could not serve: the viewer is not
    installed, or ``port`` (0: the first free one from 8080) is taken."""
    studio()
    if port:
        _port_free(port)


def _port_free(port: int) -> None:
    """ServeError when ``port`` cannot be bound as the web viewer binds it (every interface)."""
    for family, host in ((socket.AF_INET6, "::"), (socket.AF_INET, "0.0.0.0")):
        try:
            sock = socket.socket(family, socket.SOCK_STREAM)
        except OSError:
            continue  # no IPv6 here: the viewer binds IPv4 only
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if family == socket.AF_INET6:
                sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 0)
            sock.bind((host, port))
            return
        except OSError as exc:
            raise ServeError(
                f"--web: port {port} cannot be used ({exc.strerror or exc}): another program "
                f"(another viewer?) holds it; choose another with --port, or --port 0 for the "
                f"first free one from 8080"
            ) from None
        finally:
            sock.close()


def _camera(points: np.ndarray) -> mujoco.MjvCamera:
    """A camera that follows the team (the centre of mass of everything that moves) from
    55° above, far enough to hold a team as wide as ``points`` (…, 2) in view."""
    pts = np.asarray(points, float).reshape(-1, 2)
    pts = pts[np.isfinite(pts).all(axis=1)]
    wide = float(np.hypot(*(pts.max(axis=0) - pts.min(axis=0)))) if len(pts) else 0.0
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_TRACKING
    cam.trackbodyid = 0  # the world: its subtree's centre of mass is the team's
    cam.distance = 2.5 * max(wide, 0.8) + 1.0
    cam.azimuth, cam.elevation = 90.0, -55.0
    return cam


def _types(st: SimpleNamespace) -> tuple[type, type]:
    """The overlay message and the viewer-side panel, on MuJoCo Studio's base classes."""
    messages, imgui = st.messages, st.imgui

    @dataclasses.dataclass(frozen=True, eq=False)
    class Overlay(messages.Snapshot):  # type: ignore[name-defined]
        """What goes with a state: the markers, the panel's title and its rows (a row is
        its text, with the RGBA of a square before it or None)."""

        markers: tuple
        title: str
        rows: tuple

    class Panel(st.plugin.ViewerPlugin):  # type: ignore[name-defined]
        """On the viewer's thread: the markers into the scene sent to the browser, and the
        panel into the interface (drawn while a browser controls the page)."""

        def __init__(self, opened: threading.Event) -> None:
            self.opened = opened
            self.title = "dftc-mujoco"
            self.rows: tuple = ()

        @messages.handler
        def _dftc_overlay(self, overlay: Overlay) -> None:
            geoms = []
            for marker in overlay.markers:
                geom = mujoco.MjvGeom()
                init_geom(geom, marker)
                geoms.append(geom)
            self.viewer.extra_geoms[:] = geoms
            self.title, self.rows = overlay.title, overlay.rows

        @messages.handler
        def _dftc_panel(self, event: messages.BuildGuiEvent) -> None:  # type: ignore[name-defined]
            self.opened.set()
            imgui.SetNextWindowPos(imgui.Vec2(10, 10))
            imgui.SetNextWindowBgAlpha(0.85)
            imgui.Begin(self.title, None, int(imgui.WindowFlags.AlwaysAutoResize))
            for k, (text, rgba) in enumerate(self.rows):
                if rgba is not None:
                    flags = int(imgui.ColorEditFlags.NoTooltip)
                    imgui.ColorButton(f"##dftc{k}", imgui.Vec4(*rgba), flags, imgui.Vec2(12, 12))
                    imgui.SameLine()
                imgui.Text(text)
            imgui.End()

    return Overlay, Panel


class WebView:
    """MuJoCo Studio's web viewer serving ``model`` on ``port`` (0: the first free one from
    8080) in a thread of its own; :meth:`show` sends it a state with its overlay."""

    def __init__(self, model: mujoco.MjModel, port: int, title: str, camera: mujoco.MjvCamera):
        st = studio()
        self._overlay, panel_type = _types(st)
        self.opened = threading.Event()  # a browser has opened the page
        panel = panel_type(self.opened)
        config = st.viewer_protocol.ViewerConfig(title=title, gfx="web", http_port=port)
        made: dict[str, Any] = {}
        ready = threading.Event()

        def target(endpoint: Any) -> None:  # the viewer's thread
            try:
                viewer = st.web_viewer.WebViewer(
                    config, endpoint, model=model, plugins=[panel], camera=camera
                )
                made["port"] = viewer.port
            except Exception as exc:
                made["error"] = exc
                return
            finally:
                ready.set()
            st.viewer_protocol.run_viewer_loop(viewer)

        # the viewer prints its own box of addresses: one line of ours says the same
        with contextlib.redirect_stdout(io.StringIO()):
            self._handle = st.launch_thread.launch_thread(target)
            ready.wait()
        if "error" in made:
            self._handle.close()
            exc = made["error"]
            raise ServeError(f"--web: MuJoCo Studio's web viewer did not start: {_line(exc)}")
        self.port: int = made["port"]
        self.url = f"http://localhost:{self.port}/"
        # the viewer streams the state of this copy, not the caller's data: what a browser
        # asks of it (a reset, a drag) changes the copy only
        self._model = copy.deepcopy(model)
        self._data = mujoco.MjData(self._model)
        self._handle.model, self._handle.data = self._model, self._data
        self._sig = int(mujoco.mjtState.mjSTATE_INTEGRATION)
        self._state = np.empty(mujoco.mj_stateSize(model, self._sig))

    @property
    def running(self) -> bool:
        """The viewer still serves (ServeError if it stopped on an error)."""
        try:
            return bool(self._handle.is_running())
        except Exception as exc:
            raise ServeError(f"--web: the web viewer stopped: {_line(exc)}") from None

    def show(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        overlay: Sequence[Marker],
        title: str,
        rows: Sequence[tuple[str, Any]],
    ) -> None:
        """Send the state of ``data`` (of a model like the one served), the markers and
        the panel."""
        mujoco.mj_getState(model, data, self._state, self._sig)
        mujoco.mj_setState(self._model, self._data, self._state, self._sig)
        try:
            self._handle.send_to_viewer(self._overlay(tuple(overlay), title, tuple(rows)))
            self._handle.sync()
        except Exception as exc:
            raise ServeError(f"--web: the web viewer stopped: {_line(exc)}") from None

    def wait_opened(self, stop: Callable[[], bool]) -> bool:
        """Wait until a browser opens the page (True) or ``stop()`` (False)."""
        while not self.opened.wait(0.2):
            if stop() or not self.running:
                return False
            self._handle.sync()
        return True

    def close(self) -> None:
        """Stop serving (the page says the viewer closed)."""
        with contextlib.suppress(Exception):
            self._handle.close()


def _line(exc: BaseException) -> str:
    text = (str(exc).strip().splitlines() or [""])[0]
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _rows(t: float, states: Sequence[str], captions: Sequence[tuple[float, str]]) -> list:
    """The panel: the time, each robot's state (or how many are in each), the latest events."""
    rows: list[tuple[str, Any]] = [(f"t = {t:7.2f} s", None)]
    if len(states) <= LISTED:
        rows += [(f"robot {i + 1}: {s}", COLOURS[s]) for i, s in enumerate(states)]
    else:
        rows += [(f"{states.count(s)} {s}", rgba) for s, rgba in STATES]
    recent = [c for c in captions if c[0] <= t + 1e-9][-RECENT:]
    rows += [(f"{te:7.2f} s  {text}", None) for te, text in recent]
    return rows


def live_captions(events: Sequence[dict[str, Any]], seen: set[int]) -> list[tuple[float, str]]:
    """The events the panel lists, as the video's captions do: faults, each robot's first
    flag (``seen``: the robots flagged before, updated) and exclusions."""
    out = []
    for e in events:
        if e["kind"] == Kind.DETECTION:
            if e["robot"] in seen:
                continue
            seen.add(e["robot"])
            out.append((e["t"], describe(e) + " (first detection)"))
        elif e["kind"] in (Kind.FAULT, Kind.EXCLUSION):
            out.append((e["t"], describe(e)))
    return out


def serve_live(sim: Any, port: int, speed: float = 1.0, announce: Callable[[str], None] = print):
    """Serve ``sim`` (a :class:`~dftc_mujoco.closed_loop.loop.Simulation`) to a browser and
    step it in real time (times ``speed``) once a browser opens the page, until the run ends, stops
    (Ctrl-C: ``sim.request_stop``) or the viewer closes; ``announce`` gets the one line
    with the address. Returns the frames sent; the caller finishes the run (``sim.run()``).
    ServeError when the viewer cannot start; if it stops later, the run goes on without it
    (a note on stderr)."""
    s = sim.scenario
    camera = _camera(np.asarray(s.team.initial_positions))
    view = WebView(sim.model, port, f"{s.name} (dftc-mujoco)", camera)
    halo = 1.3 * sim.robot.footprint_radius
    shown = 0
    try:
        announce(
            f"web:          {view.url} (open it in a browser: the run starts then; Ctrl-C stops "
            "it, keeping its records)"
        )
        if not view.wait_opened(lambda: sim.done):
            return shown
        periods = max(1, round(1.0 / (FPS * sim.dt)))
        seen: set[int] = set()
        captions: list[tuple[float, str]] = []
        start, t0 = time.perf_counter(), sim.t
        while not sim.done and view.running:
            snap = sim.step(periods)
            captions += live_captions(snap.events, seen)
            states = snapshot_states(snap)
            overlay = markers(snap.x, states, sim.team.outputs()["x_d"], halo)
            view.show(sim.model, sim.data, overlay, s.name, _rows(snap.t, states, captions))
            shown += 1
            ahead = (snap.t - t0) / speed - (time.perf_counter() - start)
            if ahead > 0:
                time.sleep(ahead)
            elif ahead < -0.25:  # a slow period (compiling, a busy machine): no rush after it
                start -= ahead
    except ServeError as exc:
        said = str(exc).removeprefix("--web: ")
        print(f"note: {said}; the run goes on without it", file=sys.stderr)
    finally:
        view.close()
    return shown


def serve_replay(
    run: Any,
    port: int,
    stop: Callable[[], bool],
    speed: float = 1.0,
    announce: Callable[[str], None] = print,
) -> int:
    """Replay the records of ``run`` (:func:`~dftc_mujoco.reporting.results.open_run`) to a
    browser in real time (times ``speed``), over and over, from when a browser opens the page until
    ``stop()`` (Ctrl-C) or the viewer closes; returns the frames sent."""
    from ..render.video import RecordedScene

    rec = RecordedScene(run.scenario, run.log, run.summary)
    name = run.scenario.name
    spread = run.log["x"] - np.nanmean(run.log["x"], axis=1, keepdims=True)
    view = WebView(rec.model, port, f"{name} (dftc-mujoco)", _camera(spread))
    halo = 1.3 * rec.footprint
    shown = 0
    try:
        announce(
            f"web:          {view.url} (open it in a browser: the replay starts then and "
            "loops; Ctrl-C stops it)"
        )
        if not view.wait_opened(stop):
            return shown
        end = float(rec.t[-1])
        start = time.perf_counter()
        while not stop() and view.running:
            # the run, then its last instant held for a second, again and again
            t = min(((time.perf_counter() - start) * speed) % (end + speed), end)
            _, _, x = rec.pose(t)
            states = rec.states(t)
            rows = _rows(t, states, rec.captions)
            overlay = markers(x, states, rec.desired(t), halo)
            view.show(rec.model, rec.data, overlay, name, rows)
            shown += 1
            time.sleep(1.0 / FPS)
    finally:
        view.close()
    return shown
