"""Scene composition with ``mujoco.MjSpec``: arena + N robots + cylinders (docs/notes.md, 17).

Each robot's MJCF is attached as it is (``attach_body`` with the prefix ``robotK/``):
its compiler settings, default classes and assets come along, and the robot keeps its
own keyframe pose. What the scene adds:

* **Collision filtering by body membership.** Every colliding geom of a robot (any
  group, named or not) meets the cylinders; the geoms of a robot on a free joint that
  would touch a default geom in their own model (contype or conaffinity bit 1) also
  meet the floor (wheels, casters, a chassis that drops: the floor bit is in their
  contype and the floor's conaffinity only, so it never pairs two robot geoms); a robot
  on slide joints never touches the floor. With ``physics.robot_contacts`` the robots keep their own
  contype/conaffinity bits (so a robot collides with itself, and with its teammates,
  as in its own model) and their base bodies always meet each other; without it those
  bits are cleared (no robot-robot and no self contacts). The arena's bits sit above
  bit 16, clear of the robots' own.
* **The initial state**: each robot at its keyframe (or its model's default pose),
  moved so that its control point starts at the scenario's initial position; a base on a
  free joint is set down on the floor (its lowest floor contact at height 0, wherever its
  MJCF puts it); the actuators hold their keyframe ``ctrl``.
* **Options** stay the arena's (timestep, integrator from the scenario; a robot file may
  ask for MuJoCo's ``implicit`` integrator); a robot file whose ``<option>`` sets
  something else is reported (:attr:`Scene.notes`), as is what the inspection of each
  robot found (wheels its drive leaves braked).

The composed ``MjSpec`` stays with the scene (:attr:`Scene.spec`): ``sim/mjcf.py`` writes
it as MJCF text that loads without this package (dm_control's ``Physics``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import mujoco
import numpy as np

from ..runtime.paths import MODELS
from ..scenario import Obstacle, Scenario
from .fleet import Fleet, Group
from .robots import CONTROL_SITE, OPTION_NAMES, RobotModel, option_value
from .tree import actuator_bodies, owners, qpos_addresses, qpos_widths, ranges

# Collision bits of the arena, above the 16 bits the robots' own models use
FLOOR, OBSTACLE, HULL, ROBOT = 1 << 16, 1 << 17, 1 << 18, 1 << 19
OWN_BITS = 0xFFFF
INTEGRATOR = "implicitfast"
#: [m] a free base whose lowest floor contact is further than this from the floor is set on it
FLOOR_TOLERANCE = 0.005


@dataclass(frozen=True)
class Scene:
    """A compiled scene and the index arrays the plant needs (robots 0-based)."""

    model: mujoco.MjModel
    robot: RobotModel
    body: np.ndarray  # (N,) base body id of each robot
    site: np.ndarray  # (N,) control-point site of each robot
    actuator: np.ndarray  # (N, A) driven actuator ids, in the drive's role order
    held: np.ndarray  # (N, H) held actuator ids (a holonomic base's yaw)
    obstacle_geom: np.ndarray  # (O,) geom ids of the cylinders
    root_qpos: np.ndarray  # (N, 3): x, y, yaw qpos of slide/hinge joints (-1: none), or (N, 1)
    origin: np.ndarray  # (N, 4): base x, y, z, yaw with its root joints at zero (+ 3 senses)
    qpos_init: np.ndarray  # (nq,) the initial state: keyframes, robots at their positions
    ctrl_init: np.ndarray  # (nu,) keyframe commands of every actuator
    notes: tuple[str, ...] = field(default_factory=tuple)  # warnings about the composition
    groups: tuple[Group, ...] = ()  # the robots of each model (one group: a single model)
    ctrl_index: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))  # (Σ A + H,)
    spec: mujoco.MjSpec | None = None  # what ``model`` was compiled from (sim/mjcf.py writes it)


PREFIX = "robot"  # every robot's names start with it (robot_prefix)
GROUP = 32  # robots attached into one small spec before it joins the arena
FREE_ROW = -2  # root_qpos of a base on a free joint beside slide-jointed ones (mixed team)


def robot_prefix(i: int) -> str:
    """Name prefix of robot i (0-based) in the scene: robot 1 is ``robot1/``."""
    return f"{PREFIX}{i + 1}/"


def build(scenario: Scenario, robot: RobotModel | Fleet) -> Scene:
    """Compose and compile the scene for ``scenario`` with ``robot`` as every team member,
    or each robot with its own model (a :class:`~.fleet.Fleet`)."""
    return compose(
        robot.models if isinstance(robot, Fleet) else robot,
        np.asarray(scenario.team.initial_positions),
        scenario.obstacles,
        scenario.physics.timestep,
        scenario.physics.robot_contacts,
    )


def compose(
    robot: RobotModel | Sequence[RobotModel],
    positions: np.ndarray,
    obstacles: tuple[Obstacle, ...] = (),
    timestep: float = 0.002,
    robot_contacts: bool = True,
) -> Scene:
    """Arena + one robot per row of ``positions`` (N, 2) (where each control point starts)
    + cylinders, compiled: ``robot`` for every row, or each row's own model (a sequence)."""
    n = len(positions)
    models = [robot] * n if isinstance(robot, RobotModel) else list(robot)
    spec = mujoco.MjSpec.from_file(str(MODELS / "arena.xml"))
    spec.copy_during_attach = True
    spec.option.timestep = timestep
    implicit = any(m.integrator == "implicit" for m in models)
    spec.option.integrator = (
        mujoco.mjtIntegrator.mjINT_IMPLICIT if implicit else mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    )
    floor = spec.geom("floor")
    floor.contype, floor.conaffinity = FLOOR, FLOOR
    kinds = {m.path: m for m in models}  # each model's spec, made once
    bases, robot_specs = {}, []
    for path, m in kinds.items():
        robot_spec = m.spec()
        for name in OPTION_NAMES:  # the arena's options apply; differences are in Scene.notes
            setattr(robot_spec.option, name, getattr(spec.option, name))
        bases[path] = robot_spec.body(m.base)
        _filter(bases[path], m, robot_contacts)  # once: every attached copy carries the bits
        robot_specs.append(robot_spec)
    shift = np.array([m.init_point for m in models]).reshape(n, 2)  # control points, own frames
    # attach_body costs in proportion to the spec it attaches into (3.7 ms per robot at
    # N = 1000, 1.8 s in all): robots go into groups of GROUP small specs first, each group
    # then into the arena through a frame. Frames vanish at compilation and the prefixes
    # compose ("robot" + "7/"), so the model is the one robot-by-robot attaching gives.
    for g0 in range(0, n, GROUP):
        group = mujoco.MjSpec()
        group.copy_during_attach = True
        for name in OPTION_NAMES:  # the arena's options throughout (nothing to reconcile)
            setattr(group.option, name, getattr(spec.option, name))
        for i in range(g0, min(g0 + GROUP, n)):
            x, y = positions[i]
            drop = models[i].floor_offset if abs(models[i].floor_offset) > FLOOR_TOLERANCE else 0.0
            frame = group.worldbody.add_frame(pos=[x - shift[i, 0], y - shift[i, 1], -drop])
            frame.attach_body(bases[models[i].path], robot_prefix(i).removeprefix(PREFIX), "")
        spec.attach(group, frame=spec.worldbody.add_frame(), prefix=PREFIX, suffix="")
    _add_obstacles(spec, obstacles)
    model = spec.compile()
    body, site, groups, act, held, ctrl_index = _indices(model, models, list(kinds.values()))
    obs = np.array([model.geom(f"obstacle{k + 1}").id for k in range(len(obstacles))], dtype=int)
    qpos, ctrl = _initial_state(model, models, body, positions - shift)
    root, origin = _roots(model, body)
    notes = tuple(
        line
        for m, rs in zip(kinds.values(), robot_specs, strict=True)
        for line in (*_notes(m, rs), *m.notes)
    )
    return Scene(
        model,
        models[0],
        body,
        site,
        act,
        held,
        obs,
        root,
        origin,
        qpos,
        ctrl,
        notes,
        tuple(groups),
        ctrl_index,
        spec,
    )


def _add_obstacles(spec: mujoco.MjSpec, obstacles: tuple[Obstacle, ...]) -> None:
    """The cylinders, named ``obstacle1``, ``obstacle2``, ... (touched by the robots' hulls)."""
    for k, ob in enumerate(obstacles):
        spec.worldbody.add_geom(
            name=f"obstacle{k + 1}",
            type=mujoco.mjtGeom.mjGEOM_CYLINDER,
            size=[ob.radius, ob.height / 2, 0.0],
            pos=[ob.position[0], ob.position[1], ob.height / 2],
            rgba=[0.55, 0.55, 0.6, 1.0],
            contype=OBSTACLE,
            conaffinity=HULL,
        )


def _indices(
    model: mujoco.MjModel, models: list[RobotModel], kinds: list[RobotModel]
) -> tuple[np.ndarray, np.ndarray, list[Group], np.ndarray, np.ndarray, np.ndarray]:
    """Each robot's base body and control site in the compiled ``model``, its model's group
    (``kinds``: each model once), and the actuators the drive commands: (body, site,
    groups, actuator, held, ctrl_index)."""
    n = len(models)

    def ids(obj: mujoco.mjtObj, rows: Sequence[int], names: list[str]) -> np.ndarray:
        found = [[mujoco.mj_name2id(model, obj, robot_prefix(i) + s) for s in names] for i in rows]
        return np.array(found, dtype=np.int64).reshape(len(rows), len(names))

    every = list(range(n))
    body = np.array(
        [
            mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, robot_prefix(i) + models[i].base)
            for i in every
        ],
        dtype=np.int64,
    )
    site = ids(mujoco.mjtObj.mjOBJ_SITE, every, [CONTROL_SITE])[:, 0]
    groups = []
    for m in kinds:
        mine = [i for i in every if models[i].path == m.path]
        act = ids(mujoco.mjtObj.mjOBJ_ACTUATOR, mine, list(m.actuators.values()))
        held = ids(mujoco.mjtObj.mjOBJ_ACTUATOR, mine, list(m.held.values()))
        rows = np.array(mine, dtype=np.int64)
        groups.append(Group(model, rows, body[rows], act, held))
    if len(groups) == 1:  # one model: the drive's columns, robot by robot
        act, held = groups[0].actuator, groups[0].held
        ctrl_index = np.hstack([act, held]).ravel()
    else:  # a mixed team: each model's robots in turn (MixedDrive's order)
        act = held = np.zeros((n, 0), dtype=int)
        ctrl_index = np.concatenate([np.hstack([g.actuator, g.held]).ravel() for g in groups])
    return body, site, groups, act, held, ctrl_index


def _filter(body: mujoco.MjsBody, robot: RobotModel, robot_contacts: bool) -> None:
    """Collision bits of the robot whose base is ``body``, by membership (module
    docstring); set on the robot's own spec before it is attached N times."""
    for g in body.find_all(mujoco.mjtObj.mjOBJ_GEOM):
        ct, ca = int(g.contype), int(g.conaffinity)
        if not (ct or ca):
            continue  # visual only
        ground = robot.root == "free" and bool((ct | ca) & 1)
        own_ct, own_ca = (ct & OWN_BITS, ca & OWN_BITS) if robot_contacts else (0, 0)
        floor = FLOOR if ground else 0  # contype only: the floor's conaffinity has it, and
        hull = ROBOT if robot_contacts and g.parent.name == body.name else 0  # two robot
        g.contype = own_ct | HULL | floor | hull  # geoms must not match on it
        g.conaffinity = own_ca | OBSTACLE | hull


def _initial_state(
    model: mujoco.MjModel, robots: Sequence[RobotModel], body: np.ndarray, frames: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """qpos and ctrl of the whole scene with every robot at its own initial pose.

    A robot's joints in the scene are those of its base's subtree, in the same order as
    in its own model; a free joint keeps the base's MJCF pose in the scene (its robot's
    frame included), whatever the keyframe says of it. Each robot's attached actuators
    take their initial ctrl, in order. Every robot at once: its joints' qpos addresses
    and its actuators grouped by robot, its keyframe's values laid after one another.
    """
    n = len(body)
    qpos = model.qpos0.copy()
    ctrl = np.zeros(model.nu)
    # which robot each body, joint and actuator belongs to: one pass, not one per robot
    owner = owners(model, body)
    joint_owner = owner[model.jnt_bodyid]
    on = actuator_bodies(model)
    actuator_owner = np.where(on >= 0, owner[np.maximum(on, 0)], -1)
    joints, joint_count = _grouped(joint_owner, n)  # robot 0's joints, then robot 1's, ...
    acts, act_count = _grouped(actuator_owner, n)
    qpos_count = np.bincount(
        np.repeat(np.arange(n), joint_count), weights=qpos_widths(model, joints), minlength=n
    ).astype(np.int64)
    key_q = [np.asarray(r.init_qpos, float).ravel() for r in robots]
    key_c = [np.asarray(r.init_ctrl, float).ravel() for r in robots]
    _same_counts(qpos_count, key_q, act_count, key_c)
    if len(joints):
        qpos[qpos_addresses(model, joints)] = np.concatenate(key_q)
    # a keyframe's root pose is ignored: the base sits where its MJCF puts it, at its
    # planned place on the floor (a keyframe 1 m under the floor flung robots 8 m up);
    # only the other joints come from the keyframe
    free = joints[model.jnt_type[joints] == mujoco.mjtJoint.mjJNT_FREE]
    at = ranges(model.jnt_qposadr[free], np.full(len(free), 7))
    qpos[at] = model.qpos0[at]
    if len(acts):
        ctrl[acts] = np.concatenate(key_c)
    return qpos, ctrl


def _grouped(owner: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The indices owned by each of ``n`` owners, owner by owner and in order within each
    (-1: nobody's, left out), and how many each owner has."""
    order = np.argsort(owner, kind="stable")
    bounds = np.searchsorted(owner[order], np.arange(n + 1))
    return order[bounds[0] : bounds[n]], np.diff(bounds)


def _same_counts(
    qpos_count: np.ndarray, key_q: list[np.ndarray], act_count: np.ndarray, key_c: list[np.ndarray]
) -> None:
    """Refuse the first robot whose scene has other than its keyframe's number of joint
    coordinates (``qpos_count``, ``key_q``) or of actuators (``act_count``, ``key_c``)."""
    want_q, want_c = np.array([len(k) for k in key_q]), np.array([len(k) for k in key_c])
    wrong = np.flatnonzero((qpos_count != want_q) | (act_count != want_c))
    if len(wrong):
        i = int(wrong[0])
        found, what, want = (
            (qpos_count[i], "joint coordinates", want_q[i])
            if qpos_count[i] != want_q[i]
            else (act_count[i], "actuators", want_c[i])
        )
        raise ValueError(f"robot {i + 1}: {found} {what}, expected {want}")


def _roots(model: mujoco.MjModel, body: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How to put each base back at a logged pose (:func:`place`): the qpos address of its
    free joint, or of its x, y slides and yaw hinge (-1: none); and where the base sits
    with those joints at zero (x, y, z, yaw), with each slide's sense along its axis.
    Every base at once: its own joints laid robot after robot, the last joint of each
    role kept (as a walk through them in order would)."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)  # every joint at zero: where the base frame sits
    n = len(body)
    count = model.body_jntnum[body]
    joints = ranges(model.body_jntadr[body], count)
    row = np.repeat(np.arange(n), count)
    kind = model.jnt_type[joints]
    is_free = kind == mujoco.mjtJoint.mjJNT_FREE
    first_free = np.full(n, len(model.jnt_type))
    np.minimum.at(first_free, row[is_free], joints[is_free])
    free = first_free < len(model.jnt_type)
    root = np.full((n, 3), -1, dtype=int)
    sense = np.ones((n, 3))
    root[free] = FREE_ROW
    root[free, 0] = model.jnt_qposadr[first_free[free]]
    axis = data.xaxis[joints]
    hinge = kind == mujoco.mjtJoint.mjJNT_HINGE
    col = np.where(hinge, 2, np.argmax(np.abs(axis[:, :2]), axis=1))
    use = ~free[row] & ~(hinge & (np.abs(axis[:, 2]) < 0.999))  # a hinge not about z: none
    last = np.full((n, 3), -1)
    np.maximum.at(last, (row[use], col[use]), joints[use])  # the last joint of each role
    held = last >= 0
    root[held] = model.jnt_qposadr[last[held]]
    sense[held] = np.sign(data.xaxis[last[held], np.nonzero(held)[1]])
    mat = data.xmat[body]
    origin = np.hstack([data.xpos[body], np.arctan2(mat[:, 3], mat[:, 0])[:, None]])
    if free.all():  # free joints
        return root[:, :1], origin
    return root, np.hstack([origin, sense])


def _notes(robot: RobotModel, spec: mujoco.MjSpec) -> tuple[str, ...]:
    """One warning for the <option> settings of the robot file that the arena overrides,
    and one for the step its calibration asks for."""
    clash = [
        f"{name}={value}"
        for name, value in robot.options
        if option_value(spec.option, name) != value
    ]
    step: tuple[str, ...] = ()
    if robot.timestep < np.inf:
        step = (
            f"the {robot.name} drive runs away or chatters at longer steps "
            f"(calibration.timestep = {robot.timestep:g} s): the scene steps at "
            f"{spec.option.timestep:g} s",
        )
    if not clash:
        return step
    return (
        *step,
        f"{robot.mjcf.name} sets <option {' '.join(clash)}>: the arena's options apply "
        f"(timestep {spec.option.timestep:g} s and integrator "
        f"{option_value(spec.option, 'integrator')} from the scenario and the robot files, "
        "MuJoCo's defaults otherwise)",
    )


def state_geoms(model: mujoco.MjModel, body: int) -> list[int]:
    """The geoms of a robot's base that show its state colour in a video: those that are
    drawn (groups 0-2) and collide; where the collision geoms are hidden (published models
    keep them in group 3), every drawn geom of the base."""
    drawn = [
        g for g in range(model.ngeom) if model.geom_bodyid[g] == body and model.geom_group[g] < 3
    ]
    hull = [g for g in drawn if model.geom_contype[g] or model.geom_conaffinity[g]]
    return hull or drawn


def place(scene: Scene, data: mujoco.MjData, pose: np.ndarray) -> None:
    """Put every robot's base at ``pose`` (N, 3): x, y, heading (for re-posing a scene);
    every other joint at the initial state."""
    data.qpos[:] = scene.qpos_init
    root, origin = scene.root_qpos, scene.origin
    free = np.arange(len(root))
    if root.shape[1] == 3:  # slide joints (and a yaw hinge): offsets from the zero pose
        slides = root[:, 1] != FREE_ROW  # a mixed team's free bases are placed below
        for col in range(3):
            rows = np.flatnonzero(slides & (root[:, col] >= 0))
            zero = origin[rows, 3 if col == 2 else col]
            data.qpos[root[rows, col]] = (pose[rows, col] - zero) * origin[rows, 4 + col]
        free = np.flatnonzero(~slides)
    for adr, (x, y, yaw), z in zip(
        root[free, 0], pose[free], scene.qpos_init[root[free, 0] + 2], strict=True
    ):
        data.qpos[adr : adr + 3] = [x, y, z]
        data.qpos[adr + 3 : adr + 7] = [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]
