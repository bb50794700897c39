"""The plant's side of a control period: what the loop senses of MuJoCo, the commands it
sends and MuJoCo's step.

A period (:mod:`.loop`) senses first (:meth:`PhysicsStep.sense`, one compiled call): the
robots' true positions and measurements, and the truth the premises' monitor and the log
read after the physics has advanced (each base's pose, height and tilt, each robot's
contact depth, the bumpers), kept in a :class:`Sensed` record. The team's compensated
inputs become actuator commands (:meth:`PhysicsStep.commands`) and MuJoCo advances by a
control period (:meth:`PhysicsStep.step`), which keeps its error for the loop to raise
once the period's records are whole.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from ..sim.bumpers import contacts, geom_owners
from ..sim.plant import Plant


class Sensed(NamedTuple):
    """The truth of a period, sensed at its start (each array (N, ...), rewritten by the
    next period's sensing)."""

    x: np.ndarray  # (N, 2) true positions of the robots' sites
    x_m: np.ndarray  # (N, 2) each robot's measurement x + η (eq. 4)
    pose: np.ndarray  # (N, 3) each base's x, y and heading
    height: np.ndarray  # (N,) each base's height
    level: np.ndarray  # (N,) the z component of each base's z axis (cos of its tilt)
    depth: np.ndarray  # (N,) each robot's deepest contact with a teammate or a cylinder
    touching: np.ndarray  # (N,) bool, each robot's bumper: depth > 0


@njit(cache=True)
def _sense(
    site_xpos, site, xpos, xmat, body, owner, contact_geom, contact_dist, ncon, eta,
    x, x_m, pose, height, level, depth, touching,
):  # fmt: skip  # pragma: no cover - compiled
    """The period's truth into :class:`Sensed`'s arrays; returns the largest |x| coordinate,
    NaN if any is NaN."""
    far, unknown = 0.0, False
    for i in range(site.shape[0]):
        for d in range(2):
            x[i, d] = site_xpos[site[i], d]
            x_m[i, d] = x[i, d] + eta[i, d]  # eq. 4
            a = abs(x[i, d])
            if a > far:
                far = a
            unknown |= a != a
        b = body[i]
        pose[i, 0] = xpos[b, 0]
        pose[i, 1] = xpos[b, 1]
        pose[i, 2] = np.arctan2(xmat[b, 3], xmat[b, 0])
        height[i] = xpos[b, 2]
        level[i] = xmat[b, 8]
    contacts(owner, contact_geom, contact_dist, ncon, depth, touching)  # the bumpers
    return np.nan if unknown else far


class PhysicsStep:
    """The plant's side of the loop: ``plant`` sensed, and driven through ``adapter`` and
    the actuator ``faults`` by the compensated inputs ``u_bar`` (N, 2) the team writes;
    ``nsub`` MuJoCo steps a period."""

    def __init__(self, plant: Plant, u_bar: np.ndarray, adapter: Any, faults: Any, nsub: int):
        self.plant, self.u_bar, self.adapter, self.faults, self.nsub = (
            plant, u_bar, adapter, faults, nsub
        )  # fmt: skip
        n = plant.n
        scene, data = plant.scene, plant.data
        self.sensed = Sensed(
            np.zeros((n, 2)), np.zeros((n, 2)), np.zeros((n, 3)), np.zeros(n),
            np.ones(n), np.zeros(n), np.zeros(n, bool),
        )  # fmt: skip
        # views into MjData's own memory, taken once; the contacts' are read each period
        self._views = (data.site_xpos, np.ascontiguousarray(scene.site, dtype=np.intp),
                       data.xpos, data.xmat, np.ascontiguousarray(scene.body, dtype=np.intp),
                       geom_owners(scene))  # fmt: skip
        self._no_contact = (np.zeros((0, 2), np.int32), np.zeros(0))
        self.far = 0.0  # the largest |x| coordinate sensed last (NaN: some is NaN)
        self.cmd = np.empty((n, 2))  # the planar velocities asked of the drives (log: v_cmd)
        self.override = np.zeros((n, 2))  # Simulation.drive(): commands from outside the team
        self.driven = np.zeros(n, bool)
        self._rows: tuple[int, ...] = ()  # the driven robots (np.flatnonzero(driven))

    def sense(self, eta: np.ndarray) -> Sensed:
        """The truth at the period's start, with the measurement noise ``eta`` (N, 2) (eq. 4)."""
        data = self.plant.data
        ncon = data.ncon
        geom, dist = (data.contact.geom, data.contact.dist) if ncon else self._no_contact
        self.far = float(_sense(*self._views, geom, dist, ncon, eta, *self.sensed))
        return self.sensed

    def drive(self, robot: int, velocity: np.ndarray | Sequence[float] | None) -> None:
        """Robot ``robot`` (0-based) told ``velocity`` (planar, m/s) from outside the team
        from the next period on; None gives it back (:meth:`.loop.Simulation.drive`)."""
        n = len(self.driven)
        if isinstance(robot, bool) or not isinstance(robot, int | np.integer) or not 0 <= robot < n:
            raise ValueError(f"drive(robot): expected a robot in 0..{n - 1}, got {robot!r}")
        if velocity is None:
            self.driven[robot] = False
            self._rows = self._driven_rows()
            return
        if (
            type(velocity) is tuple
            and len(velocity) == 2
            and all(type(v) is float for v in velocity)
        ):
            v0, v1 = velocity  # an environment's step: two floats already
        else:
            try:
                v0, v1 = (float(c) for c in np.asarray(velocity, dtype=float).reshape(2))
            except (TypeError, ValueError):  # numpy's own words named neither argument
                raise ValueError(
                    "drive(velocity): expected a planar velocity of 2 numbers (m/s), got "
                    f"{velocity!r}"
                ) from None
        if not (math.isfinite(v0) and math.isfinite(v1)):
            raise ValueError(f"drive(velocity): expected finite numbers, got {[v0, v1]}")
        override = self.override[robot]
        override[0], override[1] = v0, v1
        if not self.driven[robot]:
            self.driven[robot] = True
            self._rows = self._driven_rows()

    def _driven_rows(self) -> tuple[int, ...]:
        """The robots driven from outside, as Python integers (np.flatnonzero(driven))."""
        return tuple(int(i) for i in np.flatnonzero(self.driven))

    def commands(self, xi: np.ndarray) -> np.ndarray:
        """The actuator commands for the team's ū plus the drives' errors ``xi`` (eq. 2)
        (robots driven from outside: their given velocity plus ``xi``), into :attr:`cmd`."""
        cmd = self.cmd
        np.add(self.u_bar, xi, out=cmd)
        if self._rows:  # robots an outside policy drives (Simulation.drive())
            override = self.override
            for i in self._rows:  # (a robot or two: cheaper than a boolean index)
                cmd[i, 0] = override[i, 0] + xi[i, 0]
                cmd[i, 1] = override[i, 1] + xi[i, 1]
        ctrl = self.adapter.command(cmd)
        if self.faults.any_stuck:  # stuck actuators keep their command of onset
            ctrl = self.faults.hold(ctrl)
        return ctrl

    def step(self, ctrl: np.ndarray) -> BaseException | None:
        """MuJoCo advanced by a control period under ``ctrl``; its error (physics trouble,
        an interrupt) returned, for the loop to raise once the period's records are whole."""
        try:
            self.plant.step(ctrl, self.nsub)
        except BaseException as exc:
            return exc
        return None
