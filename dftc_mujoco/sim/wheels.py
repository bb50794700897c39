"""Wheeled drives' geometry, read from the compiled model (robots.py calls these).

* :func:`diffdrive`: two wheels turning about the line joining them: wheel radius, axle
  width, the control point's offset from the axle, the forward axis, each wheel's sense.
* :func:`omni`: three or more omni or mecanum wheels (free rollers along the rim, at any
  angle to it) on a base with a free joint: each wheel's position, rolling direction, the
  axis of its rollers at the floor and its radius in the base frame; the wheels must move
  the base in x, y and yaw (the map has rank 3).

A positive turn of a wheel about its joint axis a rolls the base along a × z.
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from .tree import _wheel_radius, subtree

#: [°] how far a differential drive's wheel axis may be from the line joining its wheels
AXLE_TOLERANCE_DEG = 5.0
#: rollers closer than this (cos of the angle) to the axle's direction cannot push the base
MIN_ROLLER_COS = 0.2


def diffdrive(model, data, body, joints, sides, robot, fail, keyed, keys) -> dict[str, float]:
    """The wheels' track (the distance between the left and the right wheels' mean axle
    points), their radius, the control point's offset from the middle of the wheels, the
    forward axis and each wheel's sense of rotation and radius, in the base body's frame,
    from the model. ``joints`` are the wheel joints, ``sides`` each one's (−1 left, +1 right),
    ``keyed`` the robot-file key that names each; several a side is a skid steer."""
    key = keyed[0]
    rot = data.xmat[body].reshape(3, 3)  # base frame -> world
    origin = data.xpos[body]
    anchors, axes, radii = [], [], []
    owner = f"a wheel: a hinge of a body inside {robot.base!r}"
    for j, at in zip(joints, keyed, strict=True):
        wheel, axis = _axle(model, data, rot, j, body, fail, at, owner)
        anchors.append(rot.T @ (data.xanchor[j] - origin))
        axes.append(axis)
        radii.append(_wheel_radius(model, data, wheel, data.xanchor[j], data.xaxis[j]))
    side = np.array(sides)
    anchor = np.array(anchors)
    lateral = anchor[side < 0].mean(axis=0) - anchor[side > 0].mean(axis=0)
    lateral[2] = 0.0
    width = float(np.linalg.norm(lateral))
    if width < 1e-3:
        fail(key, "the left and right wheels share one position: cannot tell left from right")
    g = lateral / width  # towards the left wheels
    line = "the two wheels" if len(joints) == 2 else "the left and right wheels"
    for j, axis, at in zip(joints, axes, keyed, strict=True):  # each turns about that line
        cosine = min(1.0, abs(float(axis @ g)) / float(np.linalg.norm(axis)))
        off_axle = math.degrees(math.acos(cosine))
        if off_axle > AXLE_TOLERANCE_DEG:
            fail(
                at,
                f"joint {model.joint(j).name!r} turns about {np.round(axis, 3).tolist()} in the "
                f"base frame, {off_axle:.0f}° from the line joining {line}; a "
                "differential drive's wheels turn about that line (wheels at an angle to it "
                "are an omni or mecanum base, which this drive cannot steer)",
            )
    f = np.cross(g, [0.0, 0.0, 1.0])  # forward
    mid = anchor.mean(axis=0) if len(joints) > 2 else (anchor[0] + anchor[1]) / 2
    cp = np.array([*robot.control_point, 0.0]) - mid
    offset, lateral_offset = float(cp @ f), float(cp @ g)
    if abs(offset) < 0.01:
        fail(
            "control_point" if keys else "site center",
            f"the controlled point is {offset:+.3f} m from the axle along the heading; "
            "a differential drive can steer a point only ahead of or behind its axle "
            "(|offset| >= 0.01 m)",
        )
    out = {
        "axle_width": robot.params.get("axle_width", width),
        "wheel_radius": robot.params.get("wheel_radius", float(min(radii))),
        "offset": robot.params.get("offset", offset),
        "lateral": lateral_offset,
        "forward_angle": float(math.atan2(f[1], f[0])),
        "wheels": float(len(joints)),
    }
    if out["wheel_radius"] <= 0:
        fail(key, "the wheel has no colliding geom to take its radius from; give [diffdrive] "
             "wheel_radius")  # fmt: skip
    for k, (axis, r) in enumerate(zip(axes, radii, strict=True)):
        # a positive turn about axis a rolls the wheel along a × z
        out[f"wheel{k}_sign"] = float(np.sign(np.cross(axis, [0.0, 0.0, 1.0]) @ f))
        out[f"wheel{k}_side"] = float(sides[k])
        out[f"wheel{k}_r"] = robot.params.get("wheel_radius", r) if r > 0 else out["wheel_radius"]
    if len(joints) == 2:
        out["sign_left"], out["sign_right"] = (out[f"wheel{sides.index(s)}_sign"] for s in (-1, 1))
    return out


def omni(model, data, body, infos, robot, fail, role_key, keys) -> dict[str, Any]:
    """Each omni wheel's position (from the base's origin), rolling direction and radius in
    the base frame, as the flat parameters ``wheel{k}_x``, ``_y``, ``_dx``, ``_dy``, ``_r``
    (and ``wheels``), checking that the wheels move the base in every planar direction."""
    rot = data.xmat[body].reshape(3, 3)  # base frame -> world
    origin = data.xpos[body]
    out: dict[str, Any] = {"wheels": float(len(infos))}
    rows = []
    for k, role in enumerate(sorted(infos, key=lambda r: int(r.removeprefix("wheel")))):
        info = infos[role]
        j = info.joint_id
        owner = f"a wheel: a hinge of a body inside {robot.base!r}"
        wheel, axis = _wheel_joint(model, data, rot, info, body, fail, role_key("wheels"), owner)
        axis[2] = 0.0
        axis /= np.linalg.norm(axis)
        roll = np.cross(axis, [0.0, 0.0, 1.0])[:2]
        pos = (rot.T @ (data.xanchor[j] - origin))[:2]
        parts = np.flatnonzero(subtree(model, wheel))  # the wheel and its rollers
        radius = _rim(model, data, parts, j)
        if radius <= 0:
            fail(role_key("wheels"), f"wheel {info.joint!r} has no colliding geom to roll on")
        free = _roller_axis(model, data, rot, parts, wheel)
        if free is None:
            fail(
                role_key("wheels"),
                f"wheel {info.joint!r} has no free rollers (passive hinges of bodies inside "
                "it): a plain wheel cannot slide along its axle, an omni or mecanum one can",
            )
        along = float(free @ roll)
        if abs(along) < MIN_ROLLER_COS:
            fail(
                role_key("wheels"),
                f"wheel {info.joint!r}'s rollers turn about its axle's direction: the wheel "
                "cannot push the base",
            )
        free = free * np.sign(along)  # ρ·d > 0
        out.update(
            {
                f"wheel{k}_x": float(pos[0]),
                f"wheel{k}_y": float(pos[1]),
                f"wheel{k}_dx": float(roll[0]),
                f"wheel{k}_dy": float(roll[1]),
                f"wheel{k}_rx": float(free[0]),
                f"wheel{k}_ry": float(free[1]),
                f"wheel{k}_r": float(radius),
            }
        )
        cos = abs(along)  # wheel k turns at ρ·v / (r ρ·d): its row of the map, times r
        rows.append([free[0] / cos, free[1] / cos, (pos[0] * free[1] - pos[1] * free[0]) / cos])
    if np.linalg.matrix_rank(np.array(rows), tol=1e-6) < 3:
        fail(
            role_key("wheels"),
            "these wheels cannot move the base in every planar direction and turn it (their "
            "rolling directions and positions span less than x, y and yaw): an omni base "
            "needs three or more wheels at different angles",
        )
    return out


def _roller_axis(model, data, rot, parts: np.ndarray, wheel: int) -> np.ndarray | None:
    """The horizontal axis ρ (base frame, unit) of the roller that touches the floor at the
    initial pose (the lowest body with a passive hinge inside the wheel), or None. The
    contact's velocity along ρ is the wheel's: an omni roller turns about the rim's tangent
    (ρ = d), a mecanum roller at 45° to it."""
    best, axis = np.inf, None
    joint_trn = model.actuator_trntype == mujoco.mjtTrn.mjTRN_JOINT
    actuated = set(model.actuator_trnid[joint_trn, 0].tolist())
    for b in parts:
        if b == wheel:
            continue
        for jnt in range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b]):
            if model.jnt_type[jnt] != mujoco.mjtJoint.mjJNT_HINGE:
                continue
            if jnt in actuated:
                continue
            z = float(data.xpos[b][2])
            if z < best:
                best, axis = z, rot.T @ data.xaxis[jnt]
    if axis is None:
        return None
    flat = np.array(axis[:2], dtype=float)
    norm = float(np.linalg.norm(flat))
    return flat / norm if norm > 1e-9 else None


def swerve(model, data, body, infos, robot, fail, role_key, keys) -> dict[str, Any]:
    """Each swerve module's position (its steering axis, from the base's origin), the
    direction its wheel rolls the base at steering angle 0 (α), the sense of its steering
    joint about +z and the wheel's radius, in the base frame: ``module{k}_x``, ``_y``,
    ``_alpha``, ``_sense``, ``_r`` (and ``modules``)."""
    rot = data.xmat[body].reshape(3, 3)
    origin = data.xpos[body]
    inside = subtree(model, body)
    count = len(infos) // 2
    out: dict[str, Any] = {"modules": float(count)}
    for k in range(count):
        steer, drive = infos[f"steer{k}"], infos[f"drive{k}"]
        js, jd = steer.joint_id, drive.joint_id
        steer_body = int(model.jnt_bodyid[js])
        up = rot.T @ data.xaxis[js]
        if steer.joint_type != "hinge" or not inside[steer_body] or steer_body == body:
            fail(
                role_key("modules"),
                f"actuator {steer.name!r} must steer a module: a hinge of "
                f"a body inside {robot.base!r} (it drives {steer.joint!r})",
            )
        if abs(up[2]) < 0.98:
            fail(
                role_key("modules"),
                f"joint {steer.joint!r} turns about "
                f"{np.round(up, 3).tolist()} in the base frame; a module steers about the vertical",
            )
        owner = f"the wheel of module {k}: a hinge of a body inside {steer.joint!r}'s"
        wheel, axle = _wheel_joint(
            model, data, rot, drive, steer_body, fail, role_key("modules"), owner
        )
        roll = np.cross(axle, [0.0, 0.0, 1.0])[:2]
        pos = (rot.T @ (data.xanchor[js] - origin))[:2]
        radius = _rim(model, data, np.flatnonzero(subtree(model, wheel)), jd)
        if radius <= 0:
            fail(role_key("modules"), f"wheel {drive.joint!r} has no colliding geom to roll on")
        out.update(
            {
                f"module{k}_x": float(pos[0]),
                f"module{k}_y": float(pos[1]),
                f"module{k}_alpha": float(math.atan2(roll[1], roll[0])),
                f"module{k}_sense": float(np.sign(up[2])),
                f"module{k}_r": float(radius),
            }
        )
    if count >= 2:
        pts = np.array([[out[f"module{k}_x"], out[f"module{k}_y"]] for k in range(count)])
        if np.ptp(pts, axis=0).max() < 1e-6:
            fail(
                role_key("modules"),
                "the modules share one steering axis: they cannot turn the base",
            )
    return out


def _wheel_joint(model, data, rot, info, parent: int, fail, key: str, owner: str):
    """The body a wheel actuator turns and its axle in the base frame, after checking that
    it drives a hinge of a body inside ``parent`` (``owner`` says what it must drive) whose
    axle is horizontal."""
    wheel = int(model.jnt_bodyid[info.joint_id])
    if (
        info.joint_type != "hinge"
        or info.tendon
        or not subtree(model, parent)[wheel]
        or (wheel == parent)
    ):
        fail(key, f"actuator {info.name!r} must drive {owner} (it drives {info.what})")
    return _axle(model, data, rot, info.joint_id, parent, fail, key, owner)


def _axle(model, data, rot, j: int, parent: int, fail, key: str, owner: str):
    """The body joint ``j`` turns and its axle in the base frame, after checking that it is a
    hinge of a body inside ``parent`` whose axle is horizontal."""
    wheel = int(model.jnt_bodyid[j])
    name = model.joint(j).name or f"joint {j}"
    hinge = model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE
    if not hinge or not subtree(model, parent)[wheel] or wheel == parent:
        fail(key, f"joint {name!r} must be {owner}")
    axis = rot.T @ data.xaxis[j]
    if abs(axis[2]) > 0.2:
        fail(
            key,
            f"joint {name!r} turns about {np.round(axis, 3).tolist()} in the base frame; "
            "a wheel's axle must be horizontal",
        )
    return wheel, axis


def _rim(model, data, parts: np.ndarray, j: int) -> float:
    """The largest distance of the colliding geoms of bodies ``parts`` (a wheel and its
    rollers) from the axle of joint ``j``."""
    anchor, axis = data.xanchor[j], data.xaxis[j]
    return max(_wheel_radius(model, data, int(b), anchor, axis) for b in parts)
