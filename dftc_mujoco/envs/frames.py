"""Frames of a live run for an environment's ``render()``: MuJoCo's offscreen renderer on
the simulation's own model, an orthographic camera looking down on the team, each robot
marked above in its state's colour (:mod:`dftc_mujoco.render.display`) and each desired slot on
the floor, as the video and the viewer show them."""

from __future__ import annotations

import warnings

import mujoco
import numpy as np

from ..closed_loop.loop import Simulation
from ..render import gl
from ..render.display import COLOURS, robot_state
from ..watch.viewer import COMPENSATING

#: [m] the view's least height, and the margin around the team and its slots
VIEW_MIN, VIEW_MARGIN = 1.5, 0.6


class Frames:
    """Renders ``sim`` as it is now into (height, width, 3) uint8 frames."""

    def __init__(self, sim: Simulation, width: int = 480, height: int = 360) -> None:
        model = sim.model
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
        model.vis.global_.offheight = max(model.vis.global_.offheight, height)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # glfw warns before it fails
                self.renderer = mujoco.Renderer(model, height, width)
        except Exception as exc:
            raise gl.explain(exc) from None
        self.sim, self.width, self.height = sim, width, height
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        self.camera.orthographic = 1
        self.camera.azimuth, self.camera.elevation = 90.0, -90.0
        self.camera.distance = 20.0

    def close(self) -> None:
        """Free the GL context."""
        if self.renderer is not None:
            self.renderer.close()
            self.renderer = None

    def frame(self) -> np.ndarray:
        """The run as it is after the last period."""
        sim, team = self.sim, self.sim.team
        x, x_d = sim.positions, team.x_d
        active = team.active
        pts = np.concatenate([x[active], x_d])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        aspect = self.width / self.height
        half = max((hi - lo)[1] / 2, (hi - lo)[0] / 2 / aspect) + VIEW_MARGIN
        centre = (lo + hi) / 2
        self.camera.lookat[:] = [centre[0], centre[1], 0.0]
        sim.model.vis.global_.fovy = max(2 * half, VIEW_MIN)  # orthographic: the view height
        self.renderer.update_scene(sim.data, self.camera)
        scn = self.renderer.scene
        flagged = np.zeros(sim.n, bool)
        flagged[team.members] = np.asarray(team.flag, bool).any(axis=0)
        for i, p in enumerate(x):
            state = robot_state(
                bool(active[i]),
                bool(flagged[i]),
                bool(np.linalg.norm(team.phi_hat[i]) > COMPENSATING),
            )
            _marker(scn, (p[0], p[1], 0.32), (0.05, 0, 0), COLOURS[state])
        for p in x_d:
            _marker(scn, (p[0], p[1], 0.003), (0.04, 0.04, 0.001), (0.2, 0.4, 0.9, 0.5), True)
        return self.renderer.render()


def _marker(scn, pos, size, rgba, disc: bool = False) -> None:
    """A sphere (or a flat disc) into ``scn``, where it has room."""
    if scn.ngeom >= scn.maxgeom:
        return
    kind = mujoco.mjtGeom.mjGEOM_CYLINDER if disc else mujoco.mjtGeom.mjGEOM_SPHERE
    mujoco.mjv_initGeom(
        scn.geoms[scn.ngeom],
        int(kind),
        np.asarray(size, float),
        np.asarray(pos, float),
        np.eye(3).ravel(),
        np.asarray(rgba, np.float32),
    )
    scn.ngeom += 1
