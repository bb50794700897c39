"""Robot models: any MJCF as it is, plus a small robot file that says how to drive it.

A robot is given to a scenario (``team.robot_model``) or the command line (``--robot``)
as

* a built-in name (``disk``, ``hexbot``, ``diffdrive``: robot files in ``models/robots/``);
* a robot file ``NAME.robot.toml`` that points at an MJCF used **unchanged**
  (``mjcf``, ``base``, ``control_point``, ``drive``, ``keyframe``, ``[holonomic]`` or
  ``[diffdrive]``, ``[motor]``, ``[calibration]``; the format is in
  ``models/robots/README.md``);
* an MJCF file that follows this project's older contract (a root body ``base``, a site
  ``center`` and ``<custom>`` declarations ``dftc_adapter``, ...), which keeps working.

:func:`get` reads and checks the robot once: the named body, keyframe and actuators
exist, the actuators are of a kind the drive can use (velocity servos, position servos,
torque motors, with their gear), the drive's geometry (wheel radius, axle width, the
control point's offset from the axle) is read from the model unless given, and the
footprint (the horizontal reach of every colliding geom from the control point) is
computed at the initial pose. Every problem is one line naming the file and the key.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, NoReturn

import mujoco
import numpy as np

from ..errors import ScenarioError
from ..runtime.paths import MODELS
from . import actuators as act
from . import wheels
from .actuators import ActuatorInfo
from .robot_file import DRIVE_ROLES, ROBOT_SUFFIX, read, resolved
from .tree import _footprint, _surface_points, attached_actuators, qpos_addresses, subtree

ROBOTS = MODELS / "robots"
CONTROL_SITE = "dftc_control_point"  # the site added (in memory) at the control point
Fail = Callable[[str, str], NoReturn]  # reports a problem with a key of the robot file
LEGACY_ACTUATORS = {"holonomic": ("vx", "vy"), "diffdrive": ("wheel_l", "wheel_r")}
CALIBRATION_KEYS = (
    "xi_bar",  # recommended ξ̄ [m/s]
    "mismatch",  # largest ‖ẋ − u‖ on smooth commands [m/s]
    "startup_mismatch",  # largest ‖ẋ − u‖ while the robot settles at the start [m/s]
    "startup_time",  # how long it settles [s]
    "response_time",  # time to follow a command jump; an exclusion's hold (estimate_alarm) [s]
    "drift_replan",  # ē measured within 5 s of an exclusion (the re-plan's transient) [m]
    "lag",  # first-order lag τ of the drive, modelled onboard when set (onboard/applied.py) [s]
    "fast_lag",  # the best-fitting lag where "lag" is not set: the drive rule models it [s]
    "drift_bound",  # ē: bounded offset of the drift after the start-up (docs/thresholds.md) [m]
    "drift_startup",  # ē including the start-up [m]
    "drift_settle",  # how long the start-up lasts [s]
    "saturation",  # fraction of the programme's commands the actuators clamped
    "compensation_G",  # the smallest G (x I) whose compensation loop does not ring
    "accel",  # a_max the robot holds its nominal input's change to (onboard/applied.py) [m/s²]
    "timestep",  # the largest physics step at which its drive does not run away [s]
    "track",  # a skid steer's effective axle width: its wheels slip when it turns [m]
    "tracking",  # the share of its commands it moves at, stored outside TRACKING
)
#: the shares of its commands a robot may move at before calibrate and the run warn: a drive
#: model that matches the wheels gives 0.98-1.0 on every built-in robot
TRACKING = (0.8, 1.25)
_FREE = int(mujoco.mjtJoint.mjJNT_FREE)
_SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)
_HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)


@dataclass(frozen=True)
class RobotModel:
    """A robot as the simulator uses it: where its MJCF is and how to drive it."""

    name: str
    path: Path  # the robot file (or the MJCF of the older contract)
    mjcf: Path
    base: str  # the body that carries the robot
    control_point: tuple[float, float]  # in the base body's frame [m]
    drive: str  # "holonomic" or "diffdrive"
    actuators: dict[str, str]  # driven role -> actuator name
    held: dict[str, str]  # held role (yaw) -> actuator name
    xi_bar: float  # recommended ξ̄ [m/s], from calibrate
    mismatch: float = 0.0  # measured ‖ẋ − u‖ on smooth commands [m/s], from calibrate
    params: dict[str, float] = field(default_factory=dict)  # drive geometry, mesh data
    calibration: dict[str, float] = field(default_factory=dict)
    keyframe: str | None = None
    max_speed: float | None = None  # per-axis command limit the drive applies [m/s]
    motor_time_constant: float = act.MOTOR_TIME_CONSTANT
    mass: float = 0.0  # from the mesh, for mesh robots (0: MJCF's own)
    inertia: tuple[float, float, float] = (0.0, 0.0, 0.0)
    options: tuple[tuple[str, str], ...] = ()  # <option> (name, value) set by the robot's MJCF
    init_qpos: tuple[float, ...] = ()  # qpos of the base's subtree at the initial pose
    init_ctrl: tuple[float, ...] = ()  # ctrl at the initial pose of the attached actuators
    init_point: tuple[float, float] = (0.0, 0.0)  # the control point there, own world frame
    # found by inspecting the compiled model (_inspect)
    driven_infos: tuple[ActuatorInfo, ...] = ()
    held_infos: tuple[ActuatorInfo, ...] = ()
    root: str = ""  # "planar" (slide joints) or "free" (a free joint)
    footprint_radius: float = 0.0  # horizontal reach of the colliding geoms from the point
    planar_base: bool = False  # a fixed-base model given x, y, yaw joints (planar_base.py)
    integrator: str = "implicitfast"  # what its model needs of the scene (robot_file.py)
    # the drive's joints when they are not each actuator's own (a diffdrive's wheels under
    # tendons): offsets from the base's first joint (J,), and the transmission (A, J)
    joint_offsets: tuple[int, ...] = ()
    moment: tuple[tuple[float, ...], ...] = ()
    floor_offset: float = 0.0  # height of its lowest floor contact at its MJCF pose [m]
    notes: tuple[str, ...] = ()  # what the inspection found that a run should say

    @property
    def drift_bound(self) -> float:
        """ē from calibration (0 when the robot was not calibrated for it)."""
        return float(self.calibration.get("drift_bound", 0.0))

    @property
    def lag(self) -> float:
        """τ of the drive's first-order lag from calibration (0: the robot is taken to move at
        its command, the paper's ẋ = u)."""
        return float(self.calibration.get("lag", 0.0))

    @property
    def fast_lag(self) -> float:
        """τ of the lag that fits the drive best where the paper's rules do not model one
        (they take ẋ = u): the drive rule, whose Φ̄ bounds the fault estimate at every
        period, models it [s]."""
        return float(self.calibration.get("fast_lag", 0.0))

    @property
    def response_time(self) -> float:
        """The time the robot took to follow a command jump in calibration [s] (0: not
        measured): how long a healthy robot's velocity may miss its command."""
        return float(self.calibration.get("response_time", 0.0))

    @property
    def timestep(self) -> float:
        """The largest physics step its drive needs (calibrated; inf: any step)."""
        return float(self.calibration.get("timestep", 0.0)) or math.inf

    @property
    def accel(self) -> float:
        """a_max from calibration: the fastest change of its nominal input the robot's drive
        follows without running its compensation loop away (inf: not limited)."""
        return float(self.calibration.get("accel", 0.0)) or math.inf

    def spec(self) -> mujoco.MjSpec:
        """A fresh MjSpec of the robot's MJCF with, in memory only: file paths made absolute,
        a site at the control point, no keyframes (the initial pose is applied by the
        scene), and the mesh inertia for mesh robots."""
        spec = _robot_spec(self)
        base = spec.body(self.base)
        base.add_site(name=CONTROL_SITE, pos=[*self.control_point, 0.0], group=5)
        for key in list(spec.keys):
            spec.delete(key)
        if "mesh_density" in self.params:
            base.explicitinertial = True
            base.mass = self.mass
            base.inertia = list(self.inertia)
            base.ipos = [0.0, 0.0, self.params.get("mesh_com_z", 0.0)]
        return spec

    def adapter(self, scene: Any, data: mujoco.MjData, dt: float = 0.01) -> Any:
        """The drive for this model, bound to a scene's robots (control period ``dt``)."""
        from .drives import DRIVES

        return DRIVES[self.drive](self, scene, data, dt)


# --------------------------------------------------------------------------- finding


def available() -> list[str]:
    """Names of the built-in robot models (robot files in ``models/robots/``)."""
    return sorted(p.name.removesuffix(ROBOT_SUFFIX) for p in ROBOTS.glob(f"*{ROBOT_SUFFIX}"))


def resolve(name: str, where: str = "team.robot_model", base: Path | None = None) -> Path:
    """The file for a built-in name or a path (relative to the working directory, else to
    ``base``, the folder of the scenario that names it)."""
    path = Path(name).expanduser()
    is_path = path.suffix in (".xml", ".toml") or len(path.parts) > 1
    if not is_path:
        builtin = ROBOTS / f"{name}{ROBOT_SUFFIX}"
        if builtin.is_file():
            return builtin
        raise ScenarioError(
            f"{where}: unknown robot model {name!r} (available: {', '.join(available())}; "
            f"or give the path to a robot file NAME{ROBOT_SUFFIX} or an MJCF file)"
        )
    candidates = [path] if path.is_absolute() else [Path.cwd() / path]
    if base is not None and not path.is_absolute():
        candidates.append(base / path)
    for c in candidates:
        if c.is_file():
            if c.suffix not in (".xml", ".toml"):
                raise ScenarioError(
                    f"{where}: {name!r} is neither a robot file NAME{ROBOT_SUFFIX} nor an MJCF "
                    "file (.xml); write a robot file that names your MJCF (see the robots "
                    "guide of the documentation)"
                )
            return c.resolve()
    for c in candidates:
        if c.is_dir():
            raise ScenarioError(
                f"{where}: {name!r} is a folder ({c.resolve()}), expected a robot file"
                f" NAME{ROBOT_SUFFIX} or an MJCF file"
            )
        if c.is_symlink():
            resolved(c, where)  # a loop says so; a dangling link is "no such file" below
    looked = " and ".join(dict.fromkeys(str(c.parent) for c in candidates))
    raise ScenarioError(f"{where}: no such robot file {name!r} (looked in {looked})")


def get(name: str, where: str = "team.robot_model", base: Path | None = None) -> RobotModel:
    """The robot model called ``name``: a built-in name, a robot file or an MJCF path.

    ``where`` says where the name came from (for the error message); a relative path is
    looked up in the working directory, then in ``base``.
    """
    return load(resolve(name, where, base))


def load(path: Path) -> RobotModel:
    """Read and check one robot file (``*.robot.toml``) or MJCF of the older contract."""
    path = resolved(Path(path), str(path))
    if path.name.endswith(".toml"):
        robot = RobotModel(**read(path, CALIBRATION_KEYS))
        return _inspect(robot, keys={"base": "base", "keyframe": "keyframe", "role": robot.drive})
    return _load_legacy(path)


# --------------------------------------------------------------------------- older contract


def _load_legacy(path: Path) -> RobotModel:
    """An MJCF with a root body ``base``, a site ``center`` and ``<custom>`` declarations."""
    spec = _read_spec(path, path, None)
    texts = {t.name: t.data for t in spec.texts if t.name.startswith("dftc_")}
    nums = {
        n.name.removeprefix("dftc_"): float(np.atleast_1d(n.data)[0])
        for n in spec.numerics
        if n.name.startswith("dftc_")
    }
    if spec.body("base") is None:
        raise ScenarioError(
            f"{path}: no body named 'base'. A model of your own is used unchanged through a "
            f"robot file: write NAME{ROBOT_SUFFIX} beside it (mjcf, base, drive and the "
            "actuators; README 'Swap the robot')"
        )
    drive = texts.get("dftc_adapter", "holonomic")
    if drive not in LEGACY_ACTUATORS:
        raise ScenarioError(
            f"{path}: dftc_adapter: expected one of {', '.join(LEGACY_ACTUATORS)}, got {drive!r}"
        )
    site = spec.site("center")
    if site is None:
        raise ScenarioError(
            f"{path}: no site named 'center' (the point whose position the DFTC controls)"
        )
    if site.parent.name != "base":
        raise ScenarioError(f"{path}: site 'center' must be on body 'base'")
    params = {k: v for k, v in nums.items() if k not in ("xi_bar", "mismatch", "drift_bound")}
    for key in ("wheel_radius", "axle_width", "offset") if drive == "diffdrive" else ():
        if key not in params:
            raise ScenarioError(
                f'{path}: the diffdrive adapter needs <numeric name="dftc_{key}" data="..."/>'
            )
    calibration = {k: nums[k] for k in ("xi_bar", "mismatch", "drift_bound") if k in nums}
    from .plausible import calibration_problem

    for key, value in calibration.items():  # negative: as a robot file's (one line)
        why = calibration_problem(key, value) if value >= 0 else f"expected >= 0, got {value:g}"
        if why:
            raise ScenarioError(f'{path}: <numeric name="dftc_{key}">: {why}')
    robot = RobotModel(
        name=path.stem,
        path=path,
        mjcf=path,
        base="base",
        control_point=(float(site.pos[0]), float(site.pos[1])),
        drive=drive,
        actuators=dict(zip(DRIVE_ROLES[drive], LEGACY_ACTUATORS[drive], strict=True)),
        held={},
        xi_bar=nums.get("xi_bar", 0.005),
        mismatch=nums.get("mismatch", 0.0),
        params=params,
        calibration=calibration,
    )
    return _inspect(robot, keys=None)


# --------------------------------------------------------------------------- inspection


def _read_spec(mjcf: Path, owner: Path, key: str | None) -> mujoco.MjSpec:
    """MjSpec of ``mjcf`` with asset paths absolute (so that it can be attached anywhere)."""
    where = f"{owner}: {key}" if key else str(owner)
    if mjcf.suffix not in (".xml", ".urdf"):  # MuJoCo picks its reader by the suffix alone
        raise ScenarioError(
            f"{where}: MuJoCo reads a model from a .xml (MJCF) or .urdf file, got {mjcf.name!r}"
        )
    try:
        spec = mujoco.MjSpec.from_file(str(mjcf))
    except Exception as exc:
        raise ScenarioError(
            f"{where}: MuJoCo cannot read {mjcf.name}: {_first_line(exc)}"
        ) from None
    folder = mjcf.parent
    for attr, kinds in (("meshdir", ("meshes", "hfields")), ("texturedir", ("textures",))):
        sub = Path(getattr(spec, attr) or "")
        for kind in kinds:
            for asset in getattr(spec, kind):
                if asset.file and not Path(asset.file).is_absolute():
                    asset.file = str((folder / sub / asset.file).resolve())
        setattr(spec, attr, "")
    return spec


def _first_line(exc: BaseException) -> str:
    """MuJoCo's message on one line."""
    text = [ln.strip() for ln in str(exc).strip().splitlines() if ln.strip()]
    return "; ".join(text) if text else type(exc).__name__


def _robot_spec(robot: RobotModel, key: str | None = "mjcf") -> mujoco.MjSpec:
    """The robot's MJCF as an MjSpec (:func:`_read_spec`), with a planar base added to a
    fixed-base model that asks for one (``planar_base``)."""
    spec = _read_spec(robot.mjcf, robot.path, key)
    if robot.planar_base and spec.body(robot.base) is not None:
        from . import planar_base

        base = spec.body(robot.base)
        if base.joints:
            said = ", ".join(j.name or "unnamed" for j in base.joints) or "a free joint"
            raise ScenarioError(
                f"{robot.path}: planar_base: body {robot.base!r} already moves on {said}; "
                "planar_base gives a fixed-base model its x, y and yaw joints: remove the key"
            )
        planar_base.add(spec, robot.base)
    return spec


def _inspect(robot: RobotModel, keys: dict[str, str] | None) -> RobotModel:
    """Compile the robot alone and read what the simulator needs, checking as it goes.

    ``keys`` names the robot-file keys for messages (None: the older contract's terms).
    """
    path = robot.path

    def fail(key: str, message: str) -> NoReturn:
        raise ScenarioError(f"{path}: {key}: {message}" if keys else f"{path}: {message}")

    robot, model, data, options = _compiled(robot, keys, fail)
    body = model.body(robot.base).id
    root = _root(model, body, robot, fail)
    role_key = (lambda r: f"{keys['role']}.{r}") if keys else (lambda r: f"actuator {r!r}")
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    params = dict(robot.params)
    notes: list[str] = []
    if robot.drive == "diffdrive" and root == "free":
        from .transmission import diffdrive_wheels

        chosen, joints, sides, moment = diffdrive_wheels(model, data, body, robot, fail, role_key)
        names = [model.actuator(a).name for a in chosen]
        if moment is None:  # one actuator a wheel: the roles as the file names them
            roles = dict(zip(robot.actuators, names, strict=True))
        else:
            roles = {f"wheel{k}": n for k, n in enumerate(names)}
        first = int(model.body_jntadr[body])
        offsets = tuple(j - first for j in joints) if moment is not None else ()
        matrix = () if moment is None else tuple(tuple(float(c) for c in r) for r in moment)
        given = [role_key(r) for r in robot.actuators]  # the key that names each wheel
        keyed = given if moment is None else [given[0]] * len(joints)
        robot = replace(robot, actuators=roles, joint_offsets=offsets, moment=matrix)
        infos = _infos(model, full, robot, fail, role_key, keys)
        params.update(wheels.diffdrive(model, data, body, joints, sides, robot, fail, keyed, keys))
        driven_joints = set(joints)
    else:
        infos = _infos(model, full, robot, fail, role_key, keys)
        params.update(_drive_geometry(model, data, body, root, infos, robot, fail, role_key, keys))
        driven_joints = {j for i in infos.values() for j, _ in i.moment}
    if root == "free":
        from .transmission import idle_wheels

        note = idle_wheels(model, data, body, driven_joints, robot.name)
        notes += [note] if note else []
    driven = tuple(infos[r] for r in robot.actuators)
    held = tuple(infos[r] for r in robot.held)
    site = model.site(CONTROL_SITE).id
    inside = subtree(model, body)
    footprint = _footprint(model, data, site, inside)
    qpos = data.qpos[qpos_addresses(model, np.flatnonzero(inside[model.jnt_bodyid]))]
    return replace(
        robot,
        driven_infos=driven,
        held_infos=held,
        root=root,
        footprint_radius=footprint,
        params=params,
        options=options,
        init_qpos=tuple(float(v) for v in qpos),
        init_ctrl=tuple(float(v) for v in data.ctrl[attached_actuators(model, body)]),
        init_point=(float(data.site_xpos[site][0]), float(data.site_xpos[site][1])),
        floor_offset=_lowest(model, data, inside) if root == "free" else 0.0,
        notes=tuple(notes),
    )


def _compiled(
    robot: RobotModel, keys: dict[str, str] | None, fail: Fail
) -> tuple[RobotModel, mujoco.MjModel, mujoco.MjData, tuple[tuple[str, str], ...]]:
    """The robot's model compiled alone at its initial pose (keyframe, a free base at its
    MJCF pose as the scene puts it), after checking its base body and keyframe."""
    spec = _robot_spec(robot, "mjcf" if keys else None)
    base = spec.body(robot.base)
    if base is None:
        names = [b.name for b in spec.bodies if b.name and b.name != "world"]
        fail("base", f"no body {robot.base!r} in {robot.mjcf.name} (bodies: {_listing(names)})")
    if base.parent is None or base.parent.name != "world":
        fail("base", f"body {robot.base!r} must be a child of <worldbody> (it is attached as is)")
    if "mesh_density" in robot.params:
        mesh = _mesh_properties(spec, robot, robot.params["mesh_density"])
        robot = replace(
            robot,
            mass=mesh["mass"],
            inertia=mesh["inertia"],
            params={**robot.params, "mesh_com_z": mesh["com_z"]},
        )
    options = _option_settings(spec)
    base.add_site(name=CONTROL_SITE, pos=[*robot.control_point, 0.0])
    try:
        model = spec.compile()
    except Exception as exc:
        fail("mjcf", f"MuJoCo cannot compile {robot.mjcf.name}: {_first_line(exc)}")
    data = mujoco.MjData(model)
    if robot.keyframe is not None:
        k = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, robot.keyframe)
        if k < 0:
            keys_found = [model.key(i).name for i in range(model.nkey)]
            fail(
                "keyframe",
                f"no keyframe {robot.keyframe!r} in {robot.mjcf.name} "
                f"(keyframes: {_listing(keys_found)})",
            )
        mujoco.mj_resetDataKeyframe(model, data, k)
        body = model.body(robot.base).id
        free = [j for j in range(model.body_jntadr[body], model.body_jntadr[body] +
                model.body_jntnum[body]) if model.jnt_type[j] == _FREE]  # fmt: skip
        for j in free:  # the scene ignores a keyframe's root pose: so does the inspection
            adr = int(model.jnt_qposadr[j])
            data.qpos[adr : adr + 7] = model.qpos0[adr : adr + 7]
    mujoco.mj_forward(model, data)
    return robot, model, data, options


def _root(model: mujoco.MjModel, body: int, robot: RobotModel, fail: Fail) -> str:
    """How the base moves: "free" (a free joint) or "planar" (slide joints, a yaw hinge)."""
    joints = list(range(model.body_jntadr[body], model.body_jntadr[body] + model.body_jntnum[body]))
    types = [int(model.jnt_type[j]) for j in joints]
    if _FREE in types:
        return "free"
    if types and all(t in (_SLIDE, _HINGE) for t in types):
        return "planar"
    if not types:
        fail(
            "base",
            f"body {robot.base!r} has no joint: a fixed-base model; give it a planar base "
            "(planar_base = true in the robot file: x/y slide joints and a yaw hinge, driven "
            "as drive = 'holonomic'), or name a body on x/y slide joints or a free joint",
        )
    kinds = {_FREE: "free", _SLIDE: "slide", _HINGE: "hinge"}  # a ball joint
    said = ", ".join(
        f"{model.joint(j).name or f'joint {j}'} ({kinds.get(t, 'ball')})"
        for j, t in zip(joints, types, strict=True)
    )
    fail(
        "base",
        f"body {robot.base!r} moves on {said}: a ball joint lets the base tilt and roll, "
        "which no planar drive controls; expected x/y slide joints (and an optional yaw "
        "hinge) or a free joint",
    )


def _infos(
    model: mujoco.MjModel, full: np.ndarray, robot: RobotModel, fail: Fail, role_key: Any,
    keys: dict[str, str] | None,
) -> dict[str, ActuatorInfo]:  # fmt: skip
    """What each named actuator is (:func:`.actuators.classify`), with the inertia its
    length sees (a torque motor's loop gain)."""
    infos: dict[str, ActuatorInfo] = {}
    for role, name in {**robot.actuators, **robot.held}.items():
        a = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
        if a < 0:
            names = [model.actuator(i).name for i in range(model.nu)]
            if keys is None:
                fail(
                    "",
                    f"the {robot.drive} adapter drives actuators "
                    f"{', '.join(robot.actuators.values())}; missing: {name}",
                )
            fail(
                role_key(role),
                f"no actuator {name!r} in {robot.mjcf.name} (actuators: {_listing(names)})",
            )
        info = act.classify(model, a)
        if isinstance(info, str):
            fail(role_key(role), f"actuator {name!r} {info}")
        if info.tendon and not robot.moment:
            fail(
                role_key(role),
                f"actuator {name!r} pulls tendon {info.tendon!r}: only a diffdrive's wheels "
                "may be driven through tendons (name its wheels, or their actuators)",
            )
        dofs = [int(model.jnt_dofadr[j]) for j, _ in info.moment]
        inertia = act.seen_inertia(full, dofs, [c for _, c in info.moment])
        infos[role] = replace(info, inertia=inertia)
    return infos


def _drive_geometry(
    model: mujoco.MjModel, data: mujoco.MjData, body: int, root: str,
    infos: dict[str, ActuatorInfo], robot: RobotModel, fail: Fail, role_key: Any,
    keys: dict[str, str] | None,
) -> dict[str, float]:  # fmt: skip
    """What a holonomic, omni or swerve drive reads of the model, checked."""
    params: dict[str, float] = {}
    if robot.drive != "holonomic":
        if root != "free":
            fail(
                "drive",
                f"a {robot.drive} robot moves through its wheels: {robot.base!r} needs a "
                "free joint",
            )
        geometry = {"omni": wheels.omni}.get(robot.drive, wheels.swerve)
        return geometry(model, data, body, infos, robot, fail, role_key, keys)
    if root != "planar":
        fail(
            "drive",
            f"a holonomic drive needs x/y slide joints on {robot.base!r}; it has a "
            "free joint (a wheeled base on a free joint is drive = 'diffdrive')",
        )
    for role, axis in (("x", 0), ("y", 1)):
        info = infos[role]
        j = info.joint_id
        if info.joint_type != "slide" or model.jnt_bodyid[j] != body:
            fail(
                role_key(role),
                f"actuator {info.name!r} must drive a slide joint of "
                f"{robot.base!r} (it drives {info.joint!r})",
            )
        world_axis = data.xaxis[j]
        if abs(world_axis[axis]) < 0.999:
            fail(
                role_key(role),
                f"joint {info.joint!r} slides along "
                f"{np.round(world_axis, 3).tolist()}; expected the world {'xy'[axis]} axis",
            )
        params[f"sign_{'xy'[axis]}"] = float(np.sign(world_axis[axis]))
    if "yaw" in infos:
        info = infos["yaw"]
        j = info.joint_id
        if info.joint_type != "hinge" or abs(data.xaxis[j][2]) < 0.999:
            fail(
                role_key("yaw"),
                f"actuator {info.name!r} must drive a vertical hinge of {robot.base!r}",
            )
    return params


def _lowest(model: mujoco.MjModel, data: mujoco.MjData, inside: np.ndarray) -> float:
    """Height of the lowest point of the geoms that meet the floor (those that would touch a
    default geom in the robot's own model, as the scene filters them) [m]."""
    low = np.inf
    for g in range(model.ngeom):
        ground = (int(model.geom_contype[g]) | int(model.geom_conaffinity[g])) & 1
        if inside[model.geom_bodyid[g]] and ground:
            low = min(low, float(_surface_points(model, data, g)[:, 2].min()))
    return low if np.isfinite(low) else 0.0


def _listing(names: list[str], most: int = 12) -> str:
    names = [n for n in names if n]
    if not names:
        return "none named"
    more = f", ... ({len(names)} in all)" if len(names) > most else ""
    return ", ".join(names[:most]) + more


OPTION_NAMES = (
    "timestep",
    "integrator",
    "gravity",
    "cone",
    "impratio",
    "solver",
    "iterations",
    "noslip_iterations",
    "density",
    "viscosity",
    "wind",
    "magnetic",
    "jacobian",
    "disableflags",
    "enableflags",
)


_OPTION_ENUMS = {
    "integrator": mujoco.mjtIntegrator,
    "cone": mujoco.mjtCone,
    "solver": mujoco.mjtSolver,
    "jacobian": mujoco.mjtJacobian,
}


def option_value(option: Any, name: str) -> str:
    """An <option> attribute as text (``implicitfast``, ``0.002``), for comparing options."""
    v = getattr(option, name)
    if name in _OPTION_ENUMS:
        member = _OPTION_ENUMS[name](int(v)).name
        return member.split("_", 1)[1].lower()
    return " ".join(f"{x:g}" for x in np.atleast_1d(np.asarray(v, float)))


def _option_settings(spec: mujoco.MjSpec) -> tuple[tuple[str, str], ...]:
    """(name, value) of every <option> attribute the robot's MJCF sets to a non-default value."""
    default = mujoco.MjSpec().option
    return tuple(
        (name, option_value(spec.option, name))
        for name in OPTION_NAMES
        if option_value(spec.option, name) != option_value(default, name)
    )


def _mesh_properties(spec: mujoco.MjSpec, robot: RobotModel, density: float) -> dict[str, Any]:
    """Mass, inertia, centre of mass and horizontal radius of the robot's mesh, from trimesh."""
    import trimesh

    meshes = [m for m in spec.meshes if m.file]
    if not meshes:
        raise ScenarioError(f"{robot.path}: mesh_density is set but the robot has no mesh file")
    file = Path(meshes[0].file)
    try:
        mesh: Any = trimesh.load(file, force="mesh")  # a Trimesh (force="mesh")
    except Exception as exc:  # trimesh raises many kinds
        raise ScenarioError(f"{robot.path}: cannot load mesh {file}: {exc}") from None
    if not mesh.is_watertight:
        raise ScenarioError(
            f"{robot.path}: mesh {file} is not watertight: its volume and inertia are undefined"
        )
    mesh.density = density
    return {
        "mass": float(mesh.mass),
        "inertia": tuple(float(v) for v in np.diag(mesh.moment_inertia)),
        "com_z": float(mesh.center_mass[2]),
    }
