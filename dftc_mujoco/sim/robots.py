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
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, NoReturn

import mujoco
import numpy as np

from ..errors import ScenarioError
from ..paths import MODELS
from . import actuators as act
from . import wheels
from .actuators import ActuatorInfo
from .tree import (
    _footprint,
    attached_actuators,
    qpos_addresses,
    subtree,
)

ROBOTS = MODELS / "robots"
ROBOT_SUFFIX = ".robot.toml"
CONTROL_SITE = "dftc_control_point"  # the site added (in memory) at the control point
# the actuators each drive names (omni: a list ``wheels``, roles wheel0, wheel1, ...)
DRIVE_ROLES: dict[str, tuple[str, ...]] = {
    "holonomic": ("x", "y"),
    "diffdrive": ("left", "right"),
    "omni": (),
    "swerve": (),
}
HELD_ROLES: dict[str, tuple[str, ...]] = {
    "holonomic": ("yaw",),
    "diffdrive": (),
    "omni": (),
    "swerve": (),
}
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
)
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
    def accel(self) -> float:
        """a_max from calibration: the fastest change of its nominal input the robot's drive
        follows without running its compensation loop away (inf: not limited)."""
        return float(self.calibration.get("accel", 0.0)) or math.inf

    def spec(self) -> mujoco.MjSpec:
        """A fresh MjSpec of the robot's MJCF with, in memory only: file paths made absolute,
        a site at the control point, no keyframes (the initial pose is applied by the
        scene), and the mesh inertia for mesh robots."""
        spec = _read_spec(self.mjcf, self.path, "mjcf")
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
            _resolved(c, where)  # a loop says so; a dangling link is "no such file" below
    looked = " and ".join(dict.fromkeys(str(c.parent) for c in candidates))
    raise ScenarioError(f"{where}: no such robot file {name!r} (looked in {looked})")


def _resolved(path: Path, where: str) -> Path:
    """``path`` with its links followed; a loop of symbolic links is one line of input."""
    try:
        return path.resolve(strict=False)
    except (RuntimeError, OSError) as exc:  # RuntimeError: Python < 3.13's "Symlink loop"
        raise ScenarioError(
            f"{where}: {path} is a symbolic link that loops back on itself ({exc}); expected "
            "a link to a file"
        ) from None


def get(name: str, where: str = "team.robot_model", base: Path | None = None) -> RobotModel:
    """The robot model called ``name``: a built-in name, a robot file or an MJCF path.

    ``where`` says where the name came from (for the error message); a relative path is
    looked up in the working directory, then in ``base``.
    """
    return load(resolve(name, where, base))


def load(path: Path) -> RobotModel:
    """Read and check one robot file (``*.robot.toml``) or MJCF of the older contract."""
    path = _resolved(Path(path), str(path))
    if path.name.endswith(".toml"):
        return _load_robot_file(path)
    return _load_legacy(path)


# --------------------------------------------------------------------------- robot files


def _load_robot_file(path: Path) -> RobotModel:
    from ..tomlcheck import Doc, Table, read_toml
    from .plausible import calibration_problem

    data = read_toml(path)
    doc = Doc(str(path), data)
    t = Table(str(path), data, "", doc)
    mjcf_name = t.string("mjcf")
    base = t.string("base")
    cp = t.array("control_point", (2,), default=[0.0, 0.0])
    drive = t.string("drive", choices=tuple(DRIVE_ROLES))
    keyframe = t.string("keyframe", default=None) if "keyframe" in data else None
    max_speed = t.number("max_speed", low=0.0) if "max_speed" in data else None
    name = t.string("name", path.name.removesuffix(ROBOT_SUFFIX).removesuffix(".toml"))
    if "name" in data and isinstance(data["name"], str) and not name.strip():
        t.report("name", "expected a name to show in events and captions, got an empty one")
    params: dict[str, float] = {}
    if "mesh_density" in data:
        params["mesh_density"] = t.number("mesh_density", low=0.0)
    roles: dict[str, str] = {}
    held: dict[str, str] = {}
    if not t.ok("drive"):
        t.used.update(DRIVE_ROLES)  # which table belongs here depends on the drive
    for kind in DRIVE_ROLES if t.ok("drive") else ():
        if kind not in data:
            continue
        sub = t.table(kind)
        if kind != drive:
            t.report(kind, f"this table goes with drive = {kind!r}, but drive = {drive!r}")
            continue
        for role in DRIVE_ROLES[kind]:
            roles[role] = sub.string(role)
        if kind == "swerve":  # modules = [["steer0", "drive0"], ...]: each module's pair
            listed = sub.raw("modules")
            pairs = isinstance(listed, list) and all(
                isinstance(m, list) and len(m) == 2 and all(isinstance(a, str) for a in m)
                for m in listed
            )
            if not pairs:
                sub.report(
                    "modules", f"expected a list of [steer, drive] actuator names, got {listed!r}"
                )
            elif len(listed) < 2:
                sub.report("modules", f"expected two or more modules, got {len(listed)}")
            else:
                for k, (steer, drive_name) in enumerate(listed):
                    roles.update({f"steer{k}": steer, f"drive{k}": drive_name})
        if kind == "omni":  # wheels = ["w0", "w1", "w2", ...]: the wheels' actuators
            listed = sub.raw("wheels")
            if not isinstance(listed, list) or not all(isinstance(w, str) for w in listed):
                sub.report("wheels", f"expected a list of actuator names, got {listed!r}")
            elif len(listed) < 3:
                sub.report("wheels", f"expected three or more wheels, got {len(listed)}")
            else:
                roles.update({f"wheel{k}": w for k, w in enumerate(listed)})
        for role in HELD_ROLES[kind]:
            if role in sub.data:
                held[role] = sub.string(role)
        geometry = ("wheel_radius", "axle_width") if kind == "diffdrive" else ()
        for key in geometry:
            if key in sub.data:
                params[key] = sub.number(key, low=0.0)
        sub.used.update((*HELD_ROLES[kind], *geometry))  # optional: known when misspelt
        sub.finish()
    if t.ok("drive") and drive not in data:
        t.report(drive, f"missing table [{drive}] naming the actuators to drive")
    motor_tau = act.MOTOR_TIME_CONSTANT
    if "motor" in data:
        m = t.table("motor")
        motor_tau = m.number("time_constant", act.MOTOR_TIME_CONSTANT, low=0.0)
        m.finish()
    calibration: dict[str, float] = {}
    if "calibration" in data:
        c = t.table("calibration")
        for key in CALIBRATION_KEYS:
            if key in c.data:  # a G of 0 is no gain (eq. 30): the calibration writes none then
                strict = key == "compensation_G"
                calibration[key] = c.number(key, low=0.0, strict_low=strict)
                if c.ok(key) and (why := calibration_problem(key, calibration[key])):
                    c.report(key, why)
        c.used.update(CALIBRATION_KEYS)
        c.finish()
    # the optional keys, so that a misspelt one is told what it could be
    t.used.update(("keyframe", "max_speed", "mesh_density", "motor", "calibration", *DRIVE_ROLES))
    t.finish()
    doc.raise_problems()
    mjcf = _resolved(path.parent / mjcf_name, f"{path}: mjcf")
    if mjcf.is_dir():
        raise ScenarioError(f"{path}: mjcf: {mjcf} is a folder, expected an MJCF file in it")
    if not mjcf.is_file():
        raise ScenarioError(f"{path}: mjcf: no such file {mjcf}")
    robot = RobotModel(
        name=name,
        path=path,
        mjcf=mjcf,
        base=base,
        control_point=(float(cp[0]), float(cp[1])),
        drive=drive,
        actuators=roles,
        held=held,
        xi_bar=calibration.get("xi_bar", 0.005),
        mismatch=calibration.get("mismatch", 0.0),
        params=params,
        calibration=calibration,
        keyframe=keyframe,
        max_speed=max_speed,
        motor_time_constant=motor_tau,
    )
    return _inspect(robot, keys={"base": "base", "keyframe": "keyframe", "role": drive})


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


def _inspect(robot: RobotModel, keys: dict[str, str] | None) -> RobotModel:
    """Compile the robot alone and read what the simulator needs, checking as it goes.

    ``keys`` names the robot-file keys for messages (None: the older contract's terms).
    """
    path = robot.path

    def fail(key: str, message: str) -> NoReturn:
        raise ScenarioError(f"{path}: {key}: {message}" if keys else f"{path}: {message}")

    spec = _read_spec(robot.mjcf, path, "mjcf" if keys else None)
    base = spec.body(robot.base)
    if base is None:
        names = [b.name for b in spec.bodies if b.name and b.name != "world"]
        fail("base", f"no body {robot.base!r} in {robot.mjcf.name} (bodies: {_listing(names)})")
    if base.parent is None or base.parent.name != "world":
        fail("base", f"body {robot.base!r} must be a child of <worldbody> (it is attached as is)")
    mesh: dict[str, Any] = {}
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
    mujoco.mj_forward(model, data)
    body = model.body(robot.base).id
    joints = list(range(model.body_jntadr[body], model.body_jntadr[body] + model.body_jntnum[body]))
    types = [int(model.jnt_type[j]) for j in joints]
    if _FREE in types:
        root = "free"
    elif types and all(t in (_SLIDE, _HINGE) for t in types):
        root = "planar"
    elif not types:
        fail("base", f"body {robot.base!r} has no joint: expected x/y slide joints or a free joint")
    else:  # a ball joint (it was told it "has no joint")
        kinds = {_FREE: "free", _SLIDE: "slide", _HINGE: "hinge"}
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

    role_key = (lambda r: f"{keys['role']}.{r}") if keys else (lambda r: f"actuator {r!r}")
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
        j = int(model.actuator_trnid[a, 0])
        dof = int(model.jnt_dofadr[j])
        infos[role] = replace(info, inertia=_joint_inertia(model, data, dof))
    params = dict(robot.params)
    if robot.drive == "holonomic":
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
    else:
        if root != "free":
            fail(
                "drive",
                f"a {robot.drive} robot moves through its wheels: {robot.base!r} needs a "
                "free joint",
            )
        geometry = {"diffdrive": wheels.diffdrive, "omni": wheels.omni}.get(
            robot.drive, wheels.swerve
        )
        params.update(geometry(model, data, body, infos, robot, fail, role_key, keys))
    driven = tuple(infos[r] for r in robot.actuators)
    held = tuple(infos[r] for r in robot.held)
    site = model.site(CONTROL_SITE).id
    footprint = _footprint(model, data, site, subtree(model, body))
    qpos = data.qpos[qpos_addresses(model, np.flatnonzero(subtree(model, body)[model.jnt_bodyid]))]
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
    )


def _joint_inertia(model: mujoco.MjModel, data: mujoco.MjData, dof: int) -> float:
    """Diagonal of the joint-space inertia at the current pose (armature included)."""
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    return float(full[dof, dof])


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
