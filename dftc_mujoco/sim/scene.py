"""Scene composition with ``mujoco.MjSpec``: arena + N robots + cylinders (NOTES 17)."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from ..paths import MODELS
from ..scenario import Scenario
from .robots import RobotModel

# Collision bits: floor 1, robots 2, obstacles 4. Robots never touch the floor
# (they ride on slide joints), always touch obstacles, and touch each other
# when physics.robot_contacts is true.
FLOOR, ROBOT, OBSTACLE = 1, 2, 4


@dataclass(frozen=True)
class Scene:
    """A compiled scene and the index arrays the plant needs (robots 0-based)."""

    model: mujoco.MjModel
    robot: RobotModel
    body: np.ndarray  # (N,) root body id of each robot
    site: np.ndarray  # (N,) position site of each robot
    actuator: np.ndarray  # (N, A) actuator ids, in the adapter's order
    obstacle_geom: np.ndarray  # (O,) geom ids of the cylinders
    joint_qpos: np.ndarray  # (N, 2) qpos addresses of each robot's x and y slide joints


def robot_prefix(i: int) -> str:
    """Name prefix of robot i (0-based) in the scene: robot 1 is ``robot1/``."""
    return f"robot{i + 1}/"


def build(scenario: Scenario, robot: RobotModel) -> Scene:
    """Compose and compile the scene for ``scenario`` with ``robot`` as every team member."""
    spec = mujoco.MjSpec.from_file(str(MODELS / "arena.xml"))
    spec.copy_during_attach = True
    spec.option.timestep = scenario.physics.timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    robot_spec = robot.spec()
    base = robot_spec.body("base")
    robot_affinity = OBSTACLE | (ROBOT if scenario.physics.robot_contacts else 0)
    for i, (x, y) in enumerate(scenario.team.initial_positions):
        frame = spec.worldbody.add_frame(pos=[x, y, 0.0])
        frame.attach_body(base, robot_prefix(i), "")
    for g in spec.geoms:
        if g.name.startswith("robot") and (g.contype or g.conaffinity):
            g.contype, g.conaffinity = ROBOT, robot_affinity
    for k, ob in enumerate(scenario.obstacles):
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
    n = scenario.team.robots
    adapter = robot.adapter
    body = np.array([model.body(robot_prefix(i) + "base").id for i in range(n)])
    site = np.array([model.site(robot_prefix(i) + "center").id for i in range(n)])
    act = np.array(
        [[model.actuator(robot_prefix(i) + a).id for a in adapter.actuators] for i in range(n)]
    )
    obs = np.array(
        [model.geom(f"obstacle{k + 1}").id for k in range(len(scenario.obstacles))], dtype=int
    )
    qpos = np.array(
        [
            [model.jnt_qposadr[model.joint(robot_prefix(i) + j).id] for j in ("x", "y")]
            for i in range(n)
        ]
    )
    return Scene(model, robot, body, site, act, obs, qpos)
