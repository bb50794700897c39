"""Which joints a wheeled drive turns, and through what, read from the compiled model.

A differential drive names its wheels, ``left`` and ``right``: each an actuator on a wheel
joint, the wheel's joint itself (the actuators that turn it are found in the model), or an
actuator on a fixed tendon that couples the wheels (MuJoCo Menagerie's Stretch drives its
base with ``forward = ½ q_L + ½ q_R`` and ``turn = −½ q_L + ½ q_R``); a list of them a side
is a skid steer. :func:`diffdrive_wheels` returns the actuators, the wheel joints, each
wheel's side and the transmission matrix M (actuators × joints, L = M q) that the
actuation inverts (:mod:`.actuators`); wheels under coupled tendons are told left from
right by the base frame (its +y side is the left, as ROS's REP 103 has it).

:func:`idle_wheels` says which wheels the drive leaves alone: wheel joints that touch the
floor but are not driven, braked by the servos that hold them, or free to roll.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NoReturn

import mujoco
import numpy as np

from . import actuators as act
from .actuators import ActuatorInfo
from .tree import _surface_points, colliding, subtree

Fail = Callable[[str, str], NoReturn]
#: [m] a wheel touches the floor when its lowest point is this close to the robot's lowest
ON_FLOOR = 0.01


def _actuated_by(model: mujoco.MjModel) -> tuple[dict[int, list[int]], dict[int, Any]]:
    """Which actuators move each joint (joint or fixed-tendon transmissions), and what
    each actuator is (:func:`.actuators.classify`)."""
    kinds = {a: act.classify(model, a) for a in range(model.nu)}
    by: dict[int, list[int]] = {}
    for a, info in kinds.items():
        if isinstance(info, ActuatorInfo):
            for j, _ in info.moment:
                by.setdefault(j, []).append(a)
    return by, kinds


def _name(model: mujoco.MjModel, obj: mujoco.mjtObj, i: int) -> str:
    return mujoco.mj_id2name(model, obj, i) or f"#{i}"


def diffdrive_wheels(
    model: mujoco.MjModel, data: mujoco.MjData, body: int, robot: Any, fail: Fail, role_key: Any
) -> tuple[list[int], list[int], list[int], np.ndarray | None]:
    """(actuators, wheel joints, each wheel's side: −1 left, +1 right, transmission M or None
    when each actuator drives its own wheel in order) of a differential drive's roles."""
    by, kinds = _actuated_by(model)
    chosen: list[int] = []
    joints: list[int] = []
    sides: list[int] = []
    coupled = False
    for role, name in robot.actuators.items():
        side = -1 if role.startswith("left") else 1
        a = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
        if a >= 0:
            info = kinds[a]
            if isinstance(info, str):
                fail(role_key(role), f"actuator {name!r} {info}")
            chosen.append(a)
            if info.tendon:
                coupled = True
            else:
                joints.append(info.moment[0][0])
                sides.append(side)
            continue
        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if j < 0:
            acts = [_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, i) for i in range(model.nu)]
            fail(
                role_key(role),
                f"no actuator or wheel joint {name!r} in {robot.mjcf.name} (actuators: "
                f"{', '.join(acts[:12]) or 'none'})",
            )
        found = by.get(j, [])
        if not found:
            fail(
                role_key(role),
                f"no actuator of {robot.mjcf.name} turns joint {name!r}: nothing drives this "
                "wheel (name a driven wheel, or the actuator that turns it)",
            )
        joints.append(j)
        sides.append(side)
        chosen += [a for a in found if a not in chosen]
    if coupled:  # the coupled wheels: the tendons' joints, told apart by the base frame
        rot, origin = data.xmat[body].reshape(3, 3), data.xpos[body]
        for a in chosen:
            for j, _ in kinds[a].moment:
                if j not in joints:
                    joints.append(j)
                    y = float((rot.T @ (data.xanchor[j] - origin))[1])
                    sides.append(-1 if y > 0 else 1)
    moment = np.zeros((len(chosen), len(joints)))
    for r, a in enumerate(chosen):
        for j, c in kinds[a].moment:
            if j not in joints:
                fail(
                    role_key(next(iter(robot.actuators))),
                    f"actuator {_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a)!r} also moves "
                    f"joint {_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)!r}, which is not a wheel "
                    "of the drive",
                )
            moment[r, joints.index(j)] += c
    listed = ", ".join(_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in chosen)
    if len(chosen) != len(joints) or np.linalg.matrix_rank(moment) < len(joints):
        wheels = ", ".join(_name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in joints)
        fail(
            role_key(next(iter(robot.actuators))),
            f"wheels {wheels} are turned by {len(chosen)} actuators ({listed}): expected one "
            "actuator per wheel, or as many coupled ones that set each wheel's speed",
        )
    if -1 not in sides or 1 not in sides:
        fail(role_key("left"), "every wheel named is on one side: cannot steer")
    unnamed = [a for a in chosen if not mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a)]
    if unnamed:
        fail(role_key("left"), f"actuator #{unnamed[0]} turns a wheel but has no name to drive")
    diagonal = all(
        len(kinds[a].moment) == 1 and kinds[a].moment[0][0] == j
        for a, j in zip(chosen, joints, strict=True)
    )
    return chosen, joints, sides, None if diagonal else moment


def idle_wheels(
    model: mujoco.MjModel, data: mujoco.MjData, body: int, driven: set[int], name: str
) -> str | None:
    """A note on the wheels that touch the floor but that the drive does not turn, or None:
    those held by an actuator (a velocity servo at its keyframe ctrl brakes the base as it
    moves) and those that roll freely on a fixed axle (they skid when the base turns).
    ``driven`` are the joints the drive turns (and holds), ``name`` the robot's."""
    inside = subtree(model, body)
    low = np.inf
    lowest: dict[int, float] = {}
    for g in range(model.ngeom):
        b = int(model.geom_bodyid[g])
        ground = (int(model.geom_contype[g]) | int(model.geom_conaffinity[g])) & 1
        if inside[b] and colliding(model, g) and ground:
            z = float(_surface_points(model, data, g)[:, 2].min())
            lowest[b] = min(lowest.get(b, np.inf), z)
            low = min(low, z)
    by, _ = _actuated_by(model)
    inner = np.zeros(model.nbody, bool)  # rollers of driven wheels, steered modules' parts
    for j in driven:
        inner |= subtree(model, int(model.jnt_bodyid[j]))
    braked, free = [], []
    for j in range(model.njnt):
        b = int(model.jnt_bodyid[j])
        if j in driven or b == body or not inside[b] or inner[b]:
            continue
        hinge = int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_HINGE)
        if not hinge or abs(data.xaxis[j][2]) > 0.2:
            continue
        touching = min((z for k, z in lowest.items() if subtree(model, b)[k]), default=np.inf)
        if touching > low + ON_FLOOR:
            continue
        joint = _name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        if j in by:
            braked.append(f"{joint} ({_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, by[j][0])})")
        elif not _swivels(model, data, b, body):
            free.append(joint)
    said = []
    if braked:
        said.append(
            f"its actuators hold wheels {', '.join(braked)} at their keyframe ctrl: they "
            "brake the base as it moves (name them in the drive, e.g. a skid steer's list)"
        )
    if free:
        said.append(f"wheels {', '.join(free)} roll freely on fixed axles: they skid as it turns")
    if not said:
        return None
    return f"the {name} drive leaves wheels it does not turn: " + "; ".join(said)


def _swivels(model: mujoco.MjModel, data: mujoco.MjData, b: int, base: int) -> bool:
    """A vertical hinge between the base and body ``b``: a caster's swivel."""
    while b != base and b > 0:
        for j in range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b]):
            if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE and abs(data.xaxis[j][2]) > 0.9:
                return True
        b = int(model.body_parentid[b])
    return False
