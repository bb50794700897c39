"""Watch a run live in MuJoCo's passive viewer, with the video's overlays where it allows.

The viewer needs a display (X11 or Wayland; under CI, Xvfb). Markers drawn in
the viewer's user scene: each robot's desired slot (a flat disc) and a sphere
above each robot coloured by its state, as in the video (``render/display.py``: blue healthy,
amber compensating a fault estimate, red flagged by a teammate, grey excluded). It steps a
:class:`~dftc_mujoco.closed_loop.loop.Simulation`, so it lives beside the loop, not in ``render/``
(which reads records only).
"""

from __future__ import annotations

import os
import threading
import time

import mujoco
import numpy as np

from ..closed_loop.loop import Simulation
from ..render.display import COLOURS, robot_state

#: [m/s] a robot compensates a fault estimate (amber) while ‖φ̂‖ exceeds this
COMPENSATING = 0.05


class ViewerUnavailable(RuntimeError):
    """No display to open MuJoCo's viewer on (the message says what to do)."""


def has_display() -> bool:
    """A display to open a window on (X11 or Wayland)."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


#: an overlay marker: (geom type, size, position, RGBA), as ``mjv_initGeom`` takes them
Marker = tuple[int, np.ndarray, np.ndarray, np.ndarray]

#: the colour of a desired slot's disc
SLOT = (0.2, 0.4, 0.9, 0.5)


def snapshot_states(snap) -> list[str]:
    """Each robot's state (``render/display.py``) in a
    :class:`~dftc_mujoco.closed_loop.loop.Snapshot`."""
    return [
        robot_state(
            bool(snap.active[i]),
            bool(snap.flagged[i]),
            bool(np.linalg.norm(snap.phi_hat[i]) > COMPENSATING),
        )
        for i in range(len(snap.x))
    ]


def markers(x: np.ndarray, states: list[str], x_d: np.ndarray, halo: float = 0.0) -> list[Marker]:
    """The overlays of robots at ``x`` (N, 2) in ``states``, with desired slots ``x_d``
    (N, 2; NaN: none): a sphere above each robot in its state's colour (and, if ``halo`` >
    0, a disc of that radius under it: the browser, ``watch/web.py``, cannot repaint the robot),
    a flat disc at each slot. The passive viewer and the browser draw the same."""
    out: list[Marker] = []
    sphere, cylinder = int(mujoco.mjtGeom.mjGEOM_SPHERE), int(mujoco.mjtGeom.mjGEOM_CYLINDER)
    for p, state in zip(x, states, strict=True):
        if np.all(np.isfinite(p)):
            out.append(_spec(sphere, (0.035, 0, 0), (p[0], p[1], 0.32), COLOURS[state]))
            if halo > 0:
                out.append(_spec(cylinder, (halo, 0.002, 0), (p[0], p[1], 0.003), COLOURS[state]))
    for p in x_d:
        if np.all(np.isfinite(p)):
            out.append(_spec(cylinder, (0.03, 0.03, 0.001), (p[0], p[1], 0.002), SLOT))
    return out


def _spec(kind: int, size, pos, rgba) -> Marker:
    return (kind, np.asarray(size, float), np.asarray(pos, float), np.asarray(rgba, np.float32))


def init_geom(geom: mujoco.MjvGeom, marker: Marker) -> None:
    """Make ``geom`` the ``marker``."""
    kind, size, pos, rgba = marker
    mujoco.mjv_initGeom(geom, kind, size, pos, np.eye(3).ravel(), rgba)


def draw_overlays(scn, snap, x_d: np.ndarray) -> None:
    """State spheres and desired slots of a
    :class:`~dftc_mujoco.closed_loop.loop.Snapshot` into ``scn``."""
    scn.ngeom = 0
    for marker in markers(snap.x, snapshot_states(snap), x_d):
        if scn.ngeom >= scn.maxgeom:
            return
        init_geom(scn.geoms[scn.ngeom], marker)
        scn.ngeom += 1


def watch(sim: Simulation, speed: float = 1.0, fps: float = 30.0, max_seconds: float | None = None):
    """Step ``sim`` in real time (times ``speed``) in a passive viewer until the run ends or
    the window is closed (the caller then finishes the run with ``sim.run()``).

    Raises :class:`ViewerUnavailable` without a display.
    """
    if not has_display():
        raise ViewerUnavailable(
            "--viewer needs a display (DISPLAY is not set): run it on a desktop, over "
            "ssh -X, or under Xvfb (xvfb-run python -m dftc_mujoco.run ... --viewer)"
        )
    import mujoco.viewer

    before = set(threading.enumerate())
    try:
        handle = mujoco.viewer.launch_passive(
            sim.model, sim.data, show_left_ui=False, show_right_ui=False
        )
    except Exception as exc:  # GLFW could not open a window on this display
        raise ViewerUnavailable(f"MuJoCo's viewer could not open a window: {exc}") from None
    # the viewer renders in a daemon thread: wait for it after closing, or a process that
    # exits right away tears down GL under it (a crash at exit under Xvfb)
    ui_threads = [t for t in threading.enumerate() if t not in before]
    periods = max(1, round(1.0 / (fps * sim.dt)))
    start = time.perf_counter()
    shown = 0
    with handle as viewer:
        while viewer.is_running() and not sim.done:
            snap = sim.step(periods)
            with viewer.lock():
                draw_overlays(viewer.user_scn, snap, sim.team.outputs()["x_d"])
            viewer.sync()
            shown += 1
            ahead = snap.t / speed - (time.perf_counter() - start)
            if ahead > 0:
                time.sleep(ahead)
            if max_seconds is not None and time.perf_counter() - start > max_seconds:
                break
    for thread in ui_threads:
        thread.join(timeout=10.0)
    return shown
