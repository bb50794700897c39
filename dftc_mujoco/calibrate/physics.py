"""Calibrate checks its own physics: a calibration is worth storing only if the robot stayed
a planar robot while it was measured.

:class:`Watch` follows the robot through the programme after its start-up: its base may
neither rise nor sink more than a run allows (``premises.HEIGHT_TOLERANCE``) nor tilt
beyond ``premises.TILT_TOLERANCE``, and no part of it that was not near the floor at the
start may touch it (an arm swinging down, a gripper dragging): the wheels that touched it
then, with everything they carry (rollers, a swerve module), and whatever was within
:data:`NEAR_FLOOR` of it (casters, a bumper) may. The first breach is
kept (:class:`Trouble`): when, what and how much.

A breach is usually a drive that runs away at the physics step (stiff velocity servos on
light wheels: MuJoCo Menagerie's TIAGo++ at 2 ms spins its wheels at 500 rad/s within
0.1 s and throws the base). :data:`STEPS` are the shorter steps calibrate then tries, each
a whole number of steps per control period; the first at which the robot stays on the
plane is the fix, stored as ``[calibration] timestep``.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from ..closed_loop.premises import HEIGHT_TOLERANCE, TILT_TOLERANCE
from ..sim.tree import _surface_points, subtree

#: [s] the physics steps tried after a breach at the scene's (10 ms control period: 10, 20,
#: 40, 80 and 100 steps a period)
STEPS = (0.001, 0.0005, 0.00025, 0.000125, 0.0001)
#: a drive whose mismatch on smooth commands takes more than this share of its command range
#: is measured again at the shorter steps: its servos may chatter at the scene's step
CHATTER_SHARE = 0.25
#: [s] the shortest step tried for a chattering drive (a run at it costs 8 times the
#: scene's physics)
CHATTER_STEPS_DOWN_TO = 0.00025
#: [m] a part this close to the floor at the start may touch it as the base pitches
NEAR_FLOOR = 0.02


@dataclass(frozen=True)
class Trouble:
    """The first time the robot left the plane in calibration."""

    t: float  # [s] into the programme
    what: str  # the breach, in words ("the base rose 0.195 m and tilted 41°")

    def line(self, step: float) -> str:
        return f"at t = {self.t:.2f} s of the programme (step {step * 1000:g} ms) {self.what}"


class OffPlane(Exception):
    """The robot left the plane while it was measured."""

    def __init__(self, trouble: Trouble) -> None:
        super().__init__(trouble.what)
        self.trouble = trouble


class Watch:
    """Watches one robot's base (body ``body`` of ``model``) from the state in ``data``."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, body: int, floor: int) -> None:
        self.model, self.data, self.body, self.floor = model, data, body, floor
        inside = subtree(model, body)
        # each body's branch: the child of the base it hangs from (the base: itself)
        branch = np.full(model.nbody, -1)
        for b in np.flatnonzero(inside):
            up = int(b)
            while up != body and model.body_parentid[up] != body:
                up = int(model.body_parentid[up])
            branch[b] = up
        self.branch = branch
        touching = {int(branch[b]) for b in self._touching()}
        self.allowed = np.isin(branch[model.geom_bodyid], list(touching))
        for g in np.flatnonzero(inside[model.geom_bodyid]):
            if float(_surface_points(model, data, int(g))[:, 2].min()) < NEAR_FLOOR:
                self.allowed[g] = True
        self.z0 = float(data.xpos[body][2])
        self.trouble: Trouble | None = None

    def _touching(self, geoms: bool = False) -> set[int]:
        """The robot's bodies (or geoms) that touch the floor now."""
        return {int(x) for x in self._on_floor(geoms)}

    def _on_floor(self, geoms: bool) -> np.ndarray:
        """The robot's geoms (or their bodies) in the contacts with the floor now (as arrays:
        this runs every period of the programme)."""
        pair = self.data.contact.geom[: self.data.ncon]
        pair = pair[(pair == self.floor).any(axis=1)]
        other = np.where(pair[:, 0] == self.floor, pair[:, 1], pair[:, 0])
        body = self.model.geom_bodyid[other]
        mine = self.branch[body] >= 0
        return other[mine] if geoms else body[mine]

    def check(self, t: float) -> None:
        """Keep the first breach at ``t`` (s into the programme)."""
        if self.trouble is not None:
            return
        said = []
        dz = float(self.data.xpos[self.body][2]) - self.z0
        if abs(dz) > HEIGHT_TOLERANCE:
            said.append(f"{'rose' if dz > 0 else 'sank'} {abs(dz):.3f} m")
        level = float(self.data.xmat[self.body][8])
        tilt = float(np.arccos(min(max(level, -1.0), 1.0)))
        if tilt > TILT_TOLERANCE:
            said.append(f"tilted {np.degrees(tilt):.0f}°")
        if said:
            self.trouble = Trouble(t, "the base " + " and ".join(said))
            return
        touched = self._on_floor(geoms=True)
        touched = touched[~self.allowed[touched]]
        if touched.size:
            stray = np.unique(self.model.geom_bodyid[touched]).tolist()
            names = ", ".join(self.model.body(b).name.split("/")[-1] or f"body {b}" for b in stray)
            self.trouble = Trouble(
                t, f"{names} touched the floor (at the start only its wheels were near it)"
            )


def limits() -> str:
    """What a run allows, in words."""
    return f"{HEIGHT_TOLERANCE * 100:g} cm up or down, {np.degrees(TILT_TOLERANCE):.0f}° of tilt"
