"""Drives: the planar velocity each robot's DFTC stack asks for, as joint velocities.

A drive maps the desired velocity ū (N, 2) of each robot's controlled point to the
velocities of its driven joints (N, A); :class:`~.actuators.Actuation` turns those into
actuator commands for whichever actuator kind the model has (velocity servo, position
servo, torque motor). The same mapping shifts a planar bias fault φ into joint offsets.

* :class:`Holonomic`: x / y slide joints of the base, driven directly; an optional yaw
  hinge is held at its initial angle.
* :class:`Omni`: three or more omni wheels on a base with a free joint, the heading held
  (the map from the base's planar velocity and turn rate to each wheel).
* :class:`Swerve`: two or more steered wheels on a base with a free joint, the heading
  held (each module steers to its contact's velocity and drives along it).
* :class:`DiffDrive`: offset-point feedback linearisation of a differential drive. The
  controlled point p lies b ahead of the axle centre c (and l to its left) on the
  robot's heading θ: ṗ = (v − lω) f + bω g with f = (cos θ, sin θ), g = (−sin θ, cos θ),
  inverted exactly (b ≠ 0): ω = g·ū/b, v = f·ū + lω; wheel rim speeds v ∓ ωa (a half
  the axle width), wheel joint velocities ±(v ∓ ωa)/r by each wheel's axis direction.
  The heading is the robot's own (its compass or odometry), read from its base body.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from .actuators import Actuation

DEFAULT_MAX_SPEED = 1.0  # m/s per axis, where neither the robot file nor the actuators limit it


class Drive:
    """What every drive shares: the actuation of its driven and held joints."""

    pose_dependent = False  # joint velocities depend on the robot's heading
    planar_joints = False  # joint_velocity(u) is u itself (slides along +x and +y)

    def __init__(self, robot: Any, scene: Any, data: mujoco.MjData, dt: float) -> None:
        self.robot, self.scene, self.data = robot, scene, data
        self.n = len(scene.body)
        joints = moment = None
        if robot.moment:  # the drive's joints under a transmission (a diffdrive's tendons)
            first = scene.model.body_jntadr[scene.body]
            joints = first[:, None] + np.asarray(robot.joint_offsets, dtype=int)[None, :]
            moment = np.asarray(robot.moment, float)
        self.actuation = Actuation(
            scene.model, data, scene.actuator, robot.driven_infos, dt, robot.motor_time_constant,
            joints, moment,
        )  # fmt: skip
        self.held = (
            Actuation(
                scene.model, data, scene.held, robot.held_infos, dt, robot.motor_time_constant
            )
            if scene.held.shape[1]
            else None
        )
        self.hold_target = None if self.held is None else data.qpos[self.held.qpos_adr].copy()
        width = scene.actuator.shape[1] + scene.held.shape[1]
        self._ctrl = np.zeros((self.n, width))
        servos = [i.velocity_limit for i in robot.driven_infos if i.kind == "velocity"]
        limit = self._planar_limit(min(servos, default=np.inf))
        cap = robot.max_speed
        if cap is None:  # position servos and motors do not limit the speed themselves
            cap = limit if np.isfinite(limit) else DEFAULT_MAX_SPEED
        # ... but a motor's force does, where its joint's damping takes all of it
        motors = [i.velocity_limit for i in robot.driven_infos if i.kind == "motor"]
        cap = min(cap, self._planar_limit(min(motors, default=np.inf)))
        self.command_limit = min(limit, cap)
        self._clip = cap < limit  # then the drive clips the planar command
        # velocity servos that take the planar command as it is (the disk): ctrl = ū
        self._identity = (
            self.held is None and not self._clip and self.actuation.plain and self.planar_joints
        )

    def _planar_limit(self, joint_limit: float) -> float:
        raise NotImplementedError

    def reset(self) -> None:
        """Position servos' targets at the robots' current pose (start of a run)."""
        self.actuation.reset()
        if self.held is not None:
            self.held.reset()
            self.hold_target = self.data.qpos[self.held.qpos_adr].copy()

    def joint_velocity(self, u: np.ndarray, heading: np.ndarray | None = None) -> np.ndarray:
        """Driven joint velocities (N, A) for planar velocities ``u`` (N, 2)."""
        raise NotImplementedError

    def wheel_speeds(self, u: np.ndarray) -> np.ndarray:
        """The driven joints' velocities :meth:`command` sends for ``u``: the linear map of
        :meth:`joint_velocity` (which a bias fault also goes through), plus what the drive
        adds of its own (an omni base's heading hold)."""
        return self.joint_velocity(u)

    def command(self, u: np.ndarray) -> np.ndarray:
        """Actuator commands (N, A + H): driven joints for ``u`` (N, 2), then held joints."""
        if self._identity:
            return u
        if self._clip:
            u = np.clip(u, -self.command_limit, self.command_limit)
        driven = self.actuation.command(self.wheel_speeds(u))
        if self.held is None or self.hold_target is None:
            return driven  # no held joint: the driven commands are all of them
        a = driven.shape[1]
        self._ctrl[:, :a] = driven
        self._ctrl[:, a:] = self.held.hold(self.hold_target)
        return self._ctrl

    def controlled(self) -> np.ndarray:
        """Scene actuator ids (N, A + H) that :meth:`command` writes, in its column order."""
        return np.hstack([self.scene.actuator, self.scene.held])


class Holonomic(Drive):
    """Slide joints along the world x and y axes (each may point either way)."""

    def __init__(self, robot: Any, scene: Any, data: mujoco.MjData, dt: float) -> None:
        self.sign = np.array([robot.params.get("sign_x", 1.0), robot.params.get("sign_y", 1.0)])
        self._plain = bool((self.sign == 1.0).all())  # both slides point along +x, +y
        self.planar_joints = self._plain
        super().__init__(robot, scene, data, dt)

    def _planar_limit(self, joint_limit: float) -> float:
        return joint_limit

    def joint_velocity(self, u: np.ndarray, heading: np.ndarray | None = None) -> np.ndarray:
        return u if self._plain else u * self.sign


class DiffDrive(Drive):
    """Two wheels on hinges: offset-point feedback linearisation (module docstring)."""

    pose_dependent = True

    def __init__(self, robot: Any, scene: Any, data: mujoco.MjData, dt: float) -> None:
        p = robot.params
        wheels = range(int(p.get("wheels", 2)))
        # a skid steer's wheels slip as it turns: its calibrated track, else the geometric one
        track = robot.calibration.get("track", p["axle_width"])
        self.half = track / 2
        self.b, self.lat = p["offset"], p.get("lateral", 0.0)
        self.psi = p.get("forward_angle", 0.0)  # the forward axis in the base frame
        if "wheels" in p:  # each wheel: its side (−1 left, +1 right), sense and radius
            self.side = np.array([p[f"wheel{k}_side"] for k in wheels])
            self.sign = np.array([p[f"wheel{k}_sign"] for k in wheels])
            self.r = np.array([p.get("wheel_radius", p[f"wheel{k}_r"]) for k in wheels])
        else:  # the older contract's two wheels
            self.side = np.array([-1.0, 1.0])
            self.sign = np.array([p.get("sign_left", 1.0), p.get("sign_right", 1.0)])
            self.r = np.full(2, p["wheel_radius"])
        self.body = scene.body
        super().__init__(robot, scene, data, dt)

    def _planar_limit(self, joint_limit: float) -> float:
        # the per-axis planar speed reachable in every heading: a rim speed is
        # u_f + (l ∓ a) u_l / b (forward and lateral parts of u), at most
        # sqrt(1 + K²) ‖u‖ with K = (|l| + a)/|b|, and ‖u‖ <= sqrt(2) × the per-axis bound
        k = (abs(self.lat) + self.half) / abs(self.b)
        return joint_limit * float(self.r.min()) / (np.sqrt(2) * np.sqrt(1.0 + k * k))

    def _heading(self) -> tuple[np.ndarray, np.ndarray]:
        mat = self.data.xmat[self.body]  # (N, 9), row-major
        c, s = mat[:, 0], mat[:, 3]
        norm = np.hypot(c, s)
        unset = norm == 0.0  # kinematics not computed yet: heading 0
        norm[unset] = 1.0
        c, s = np.where(unset, 1.0, c / norm), s / norm
        if self.psi:
            cp, sp = np.cos(self.psi), np.sin(self.psi)
            c, s = c * cp - s * sp, s * cp + c * sp
        return c, s

    def _cs(self, heading: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        if heading is None:
            return self._heading()
        return np.cos(heading + self.psi), np.sin(heading + self.psi)

    def joint_velocity(self, u: np.ndarray, heading: np.ndarray | None = None) -> np.ndarray:
        c, s = self._cs(heading)
        w = (-s * u[:, 0] + c * u[:, 1]) / self.b
        v = c * u[:, 0] + s * u[:, 1] + self.lat * w
        rim = v[:, None] + (w * self.half)[:, None] * self.side  # left v − ωa, right v + ωa
        return rim * (self.sign / self.r)


class Omni(Drive):
    """Omni wheels (free rollers along the rim) on a base with a free joint.

    Wheel k sits at p_k in the base frame (from the base's origin), rolls the base along
    d_k (a positive turn), has radius r_k and its roller at the floor turns about ρ_k
    (omni: ρ_k = d_k; mecanum: 45° from it), all read from the model (``wheels.omni``).
    The floor's velocity along a free roller's axis is the wheel's own, so for a velocity ū
    of the control point c and a turn rate ω, the base's origin moves at v = Rᵀū − ω ẑ × c
    (base frame) and wheel k turns at ρ_k · (v + ω ẑ × p_k) / (r_k ρ_k · d_k).
    The heading is held: ω = −:data:`YAW_GAIN` (ψ − ψ₀), ψ₀ the heading at the start (the
    robot's own compass or odometry, read from its base body); a bias fault φ goes through
    the same map with ω = 0.
    """

    pose_dependent = True

    def __init__(self, robot: Any, scene: Any, data: mujoco.MjData, dt: float) -> None:
        p = robot.params
        k = range(int(p["wheels"]))
        self.pos = np.array([[p[f"wheel{i}_x"], p[f"wheel{i}_y"]] for i in k])
        self.roll = np.array([[p[f"wheel{i}_dx"], p[f"wheel{i}_dy"]] for i in k])
        self.free = np.array([[p[f"wheel{i}_rx"], p[f"wheel{i}_ry"]] for i in k])  # ρ_k
        # wheel k turns at ρ_k · (contact velocity) / (r_k ρ_k · d_k)
        self.radius = np.array([p[f"wheel{i}_r"] for i in k]) * (self.free * self.roll).sum(1)
        self.point = np.asarray(robot.control_point, float)
        self.body = scene.body
        self.data = data
        self.yaw0 = self._yaw()
        super().__init__(robot, scene, data, dt)

    def _planar_limit(self, joint_limit: float) -> float:
        # |d_k · v| <= ‖v‖ <= sqrt(2) × the per-axis bound; a tenth kept for the heading hold
        return 0.9 * joint_limit * float(self.radius.min()) / np.sqrt(2)

    def _yaw(self) -> np.ndarray:
        mat = self.data.xmat[self.body]
        return np.arctan2(mat[:, 3], mat[:, 0])  # all zero before the kinematics: heading 0

    def reset(self) -> None:
        super().reset()
        self.yaw0 = self._yaw()

    def joint_velocity(self, u: np.ndarray, heading: np.ndarray | None = None) -> np.ndarray:
        return self._speeds(u, np.zeros(len(u)), self._yaw() if heading is None else heading)

    def wheel_speeds(self, u: np.ndarray) -> np.ndarray:
        yaw = self._yaw()
        turn = -YAW_GAIN * np.angle(np.exp(1j * (yaw - self.yaw0)))  # wrapped to ±π
        return self._speeds(u, turn, yaw)

    def _speeds(self, u: np.ndarray, w: np.ndarray, yaw: np.ndarray) -> np.ndarray:
        c, s = np.cos(yaw), np.sin(yaw)
        ub = np.stack([c * u[:, 0] + s * u[:, 1], -s * u[:, 0] + c * u[:, 1]], axis=1)  # Rᵀū
        v = ub - w[:, None] * np.array([-self.point[1], self.point[0]])  # the origin's
        spin = np.stack([-self.pos[:, 1], self.pos[:, 0]], axis=1)  # ẑ × p_k
        contact = v[:, None, :] + w[:, None, None] * spin[None]
        return np.einsum("nkd,kd->nk", contact, self.free) / self.radius


#: [1/s] how fast an omni base turns back to its initial heading
YAW_GAIN = 5.0


class Swerve(Omni):
    """Swerve modules on a base with a free joint: each module steers its wheel about a
    vertical axis at p_k and drives it.

    Module k's contact must move at v_k = v + ω ẑ × p_k (base frame; v and ω as for
    :class:`Omni`, the heading held). Its wheel rolls along angle α_k + s_k q_k (q_k the
    steering joint, s_k its sense about +z). It steers to the direction of v_k or its
    opposite, whichever is nearer (turning at most 90°), and drives at ±‖v_k‖/r_k times
    the cosine of what it has still to turn (no push sideways while it turns); where the
    nearer angle lies beyond its steering joint's range, it takes the other one and drives
    the other way (a module limited to ±90° turns within its range). A position
    servo steers to the angle; a velocity servo at (angle error)/:data:`STEER_TIME`. A bias
    fault φ goes through the wheels as they point (the drive speed along each wheel).
    """

    def __init__(self, robot: Any, scene: Any, data: mujoco.MjData, dt: float) -> None:
        p = robot.params
        k = range(int(p["modules"]))
        self.pos = np.array([[p[f"module{i}_x"], p[f"module{i}_y"]] for i in k])
        self.alpha = np.array([p[f"module{i}_alpha"] for i in k])
        self.sense = np.array([p[f"module{i}_sense"] for i in k])
        self.radius = np.array([p[f"module{i}_r"] for i in k])
        self.point = np.asarray(robot.control_point, float)
        self.body = scene.body
        self.data = data
        self.yaw0 = self._yaw()
        Drive.__init__(self, robot, scene, data, dt)
        self.steer_cols = np.arange(0, 2 * len(self.alpha), 2)
        self.steer_adr = self.actuation.qpos_adr[:, self.steer_cols]
        self.steer_pos = self.actuation.pos[self.steer_cols]
        steer = robot.driven_infos[0::2]  # the steering joints' ranges (±inf: unlimited)
        self.steer_lo = np.array([i.joint_range[0] for i in steer])
        self.steer_hi = np.array([i.joint_range[1] for i in steer])
        self._out = np.zeros((self.n, 2 * len(self.alpha)))

    def _planar_limit(self, joint_limit: float) -> float:
        drive = min(i.velocity_limit for i in self.robot.driven_infos[1::2])
        return 0.9 * drive * float(self.radius.min()) / np.sqrt(2)

    def _contact(self, u: np.ndarray, w: np.ndarray, yaw: np.ndarray) -> np.ndarray:
        c, s = np.cos(yaw), np.sin(yaw)
        ub = np.stack([c * u[:, 0] + s * u[:, 1], -s * u[:, 0] + c * u[:, 1]], axis=1)
        v = ub - w[:, None] * np.array([-self.point[1], self.point[0]])
        spin = np.stack([-self.pos[:, 1], self.pos[:, 0]], axis=1)
        return v[:, None, :] + w[:, None, None] * spin[None]  # (N, K, 2)

    def joint_velocity(self, u: np.ndarray, heading: np.ndarray | None = None) -> np.ndarray:
        contact = self._contact(u, np.zeros(len(u)), self._yaw() if heading is None else heading)
        angle = self.alpha + self.sense * self.data.qpos[self.steer_adr]
        along = contact[..., 0] * np.cos(angle) + contact[..., 1] * np.sin(angle)
        self._out[:] = 0.0
        self._out[:, self.steer_cols + 1] = along / self.radius
        return self._out.copy()

    def wheel_speeds(self, u: np.ndarray) -> np.ndarray:
        yaw = self._yaw()
        turn = -YAW_GAIN * np.angle(np.exp(1j * (yaw - self.yaw0)))
        contact = self._contact(u, turn, yaw)
        q = self.data.qpos[self.steer_adr]
        now = self.alpha + self.sense * q
        want = np.arctan2(contact[..., 1], contact[..., 0])
        err = np.angle(np.exp(1j * (want - now)))
        back = np.abs(err) > np.pi / 2  # the opposite direction is nearer: drive backwards
        err = np.where(back, err - np.pi * np.sign(err), err)
        other = err - np.pi * np.sign(err)  # the same line, the wheel driven the other way
        near, far = q + self.sense * err, q + self.sense * other
        lo, hi = self.steer_lo, self.steer_hi
        turn_back = ((near < lo) | (near > hi)) & (lo <= far) & (far <= hi)  # past its range
        err = np.where(turn_back, other, err)
        back = back ^ turn_back
        speed = np.hypot(contact[..., 0], contact[..., 1]) * np.where(back, -1.0, 1.0)
        moving = np.abs(speed) > 1e-6
        err = np.where(moving, err, 0.0)  # at rest a module keeps its angle
        goal = q + self.sense * err
        out = self._out
        target = self.actuation.target[:, self.steer_cols]
        out[:, self.steer_cols] = np.where(
            self.steer_pos, (goal - target) / self.actuation.dt, (goal - q) / STEER_TIME
        )
        out[:, self.steer_cols + 1] = speed * np.maximum(np.cos(err), 0.0) / self.radius
        return out


#: [s] how fast a module steered by a velocity servo turns to its angle
STEER_TIME = 0.05

DRIVES: dict[str, type[Drive]] = {
    "holonomic": Holonomic,
    "diffdrive": DiffDrive,
    "omni": Omni,
    "swerve": Swerve,
}
