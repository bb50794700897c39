"""Scene composition with ``mujoco.MjSpec``: arena + N robots + cylinders (NOTES 17)."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from ..paths import MODELS
from ..scenario import Obstacle, Scenario
from .robots import ADAPTERS, GROUND_GROUP, RobotModel

# Collision bits: floor 1, robot hulls 2, obstacles 4, ground contacts (wheels,
# casters) 8. Hulls never touch the floor, always touch obstacles, and touch
# each other when physics.robot_contacts is true; ground contacts touch only
# the floor.
FLOOR, ROBOT, OBSTACLE, GROUND = 1, 2, 4, 8


@dataclass(frozen=True)
class Scene:
    """A compiled scene and the index arrays the plant needs (robots 0-based)."""

    model: mujoco.MjModel
    robot: RobotModel
    body: np.ndarray  # (N,) root body id of each robot
    site: np.ndarray  # (N,) position site of each robot
    actuator: np.ndarray  # (N, A) actuator ids, in the adapter's order
    obstacle_geom: np.ndarray  # (O,) geom ids of the cylinders
    root_qpos: np.ndarray  # (N, k): x, y slide-joint qpos (k = 2) or free-joint qpos start (k = 1)
    origin: np.ndarray  # (N, 3) where each robot's base was placed


def robot_prefix(i: int) -> str:
    """Name prefix of robot i (0-based) in the scene: robot 1 is ``robot1/``."""
    return f"robot{i + 1}/"


def build(scenario: Scenario, robot: RobotModel) -> Scene:
    """Compose and compile the scene for ``scenario`` with ``robot`` as every team member."""
    return compose(
        robot,
        np.asarray(scenario.team.initial_positions),
        scenario.obstacles,
        scenario.physics.timestep,
        scenario.physics.robot_contacts,
    )


def compose(
    robot: RobotModel,
    positions: np.ndarray,
    obstacles: tuple[Obstacle, ...] = (),
    timestep: float = 0.002,
    robot_contacts: bool = True,
) -> Scene:
    """Arena + one ``robot`` per row of ``positions`` (N, 2) + cylinders, compiled."""
    spec = mujoco.MjSpec.from_file(str(MODELS / "arena.xml"))
    spec.copy_during_attach = True
    spec.option.timestep = timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    robot_spec = robot.spec()
    base = robot_spec.body("base")
    hull_affinity = OBSTACLE | (ROBOT if robot_contacts else 0)
    for i, (x, y) in enumerate(positions):
        frame = spec.worldbody.add_frame(pos=[x, y, 0.0])
        frame.attach_body(base, robot_prefix(i), "")
    for g in spec.geoms:
        if not g.name.startswith("robot") or not (g.contype or g.conaffinity):
            continue
        if g.group == GROUND_GROUP:
            g.contype, g.conaffinity = GROUND, FLOOR
        else:
            g.contype, g.conaffinity = ROBOT, hull_affinity
    for k, ob in enumerate(obstacles):
        spec.worldbody.add_geom(
            name=f"obstacle{k + 1}",
            type=mujoco.mjtGeom.mjGEOM_CYLINDER,
            size=[ob.radius, ob.height / 2, 0.0],
            pos=[ob.position[0], ob.position[1], ob.height / 2],
            rgba=[0.55, 0.55, 0.6, 1.0],
            contype=OBSTACLE,
            conaffinity=ROBOT,
        )
    model = spec.compile()
    n = len(positions)
    names = ADAPTERS[robot.adapter_kind].actuators
    body = np.array([model.body(robot_prefix(i) + "base").id for i in range(n)])
    site = np.array([model.site(robot_prefix(i) + "center").id for i in range(n)])
    act = np.array([[model.actuator(robot_prefix(i) + a).id for a in names] for i in range(n)])
    obs = np.array([model.geom(f"obstacle{k + 1}").id for k in range(len(obstacles))], dtype=int)
    root = []
    for b in body:
        j = model.body_jntadr[b]
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            root.append([model.jnt_qposadr[j]])
        else:
            root.append([model.jnt_qposadr[j], model.jnt_qposadr[j + 1]])
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    return Scene(model, robot, body, site, act, obs, np.array(root), data.xpos[body].copy())


def place(scene: Scene, data: mujoco.MjData, pose: np.ndarray) -> None:
    """Put every robot's base at ``pose`` (N, 3): x, y, heading (for re-posing a scene)."""
    if scene.root_qpos.shape[1] == 2:  # slide joints: qpos is the offset from the origin
        data.qpos[scene.root_qpos[:, 0]] = pose[:, 0] - scene.origin[:, 0]
        data.qpos[scene.root_qpos[:, 1]] = pose[:, 1] - scene.origin[:, 1]
        return
    for (adr,), (x, y, yaw), z in zip(scene.root_qpos, pose, scene.origin[:, 2], strict=True):
        data.qpos[adr : adr + 3] = [x, y, z]
        data.qpos[adr + 3 : adr + 7] = [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]
