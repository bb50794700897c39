"""A planar base for a model published without one (``planar_base = true`` in a robot file).

A mobile manipulator is often published fixed to the world (MuJoCo Menagerie's Google
Robot: its ``base_link`` has no joint). To join a team it is given, in memory, what the
built-in disk has: x and y slide joints and a yaw hinge on its base body, each driven by a
velocity servo whose gain makes it follow its command with a :data:`LAG` lag (kv = the
inertia the joint moves / LAG) within ±:data:`RANGE` (m/s, rad/s). The MJCF is not edited.
Like every base on slide joints it never touches the floor; it is driven as a holonomic
base, its yaw held at its initial heading.
"""

from __future__ import annotations

import mujoco
import numpy as np

#: the joints and actuators added (x, y, yaw), prefixed like nothing a model names itself
PLANAR_JOINTS = ("dftc_planar_x", "dftc_planar_y", "dftc_planar_yaw")
PLANAR_ACTUATORS = PLANAR_JOINTS
LAG = 0.01  # s, as the built-in disk's velocity servos
RANGE = 1.0  # m/s (and rad/s for the yaw), as the built-in disk's command range


def add(spec: mujoco.MjSpec, base_name: str) -> None:
    """Give body ``base_name`` of ``spec`` its x, y and yaw joints and their velocity servos."""
    base = spec.body(base_name)
    axes = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0])
    kinds = (mujoco.mjtJoint.mjJNT_SLIDE, mujoco.mjtJoint.mjJNT_SLIDE, mujoco.mjtJoint.mjJNT_HINGE)
    for name, axis, kind in zip(PLANAR_JOINTS, axes, kinds, strict=True):
        base.add_joint(name=name, type=kind, axis=axis)  # in order: the slides carry the hinge
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    for name in PLANAR_ACTUATORS:
        dof = int(model.jnt_dofadr[model.joint(name).id])
        kv = float(full[dof, dof]) / LAG
        act = spec.add_actuator(name=name, target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_velocity(kv=kv)
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = [-RANGE, RANGE]
