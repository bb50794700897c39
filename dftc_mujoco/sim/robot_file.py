"""Reading a robot file (``NAME.robot.toml``): every key checked, every problem one line
naming the file and the key, before the MJCF it points at is compiled (:mod:`.robots`
inspects the model).

Besides the drive and its actuators, a robot file may say what its model needs of the
scene: ``integrator = "implicit"`` (the arena's is ``implicitfast``), and
``planar_base = true`` for a model published without a base joint (a fixed-base mobile
manipulator): its base body then moves on x / y slide joints and a yaw hinge of the
simulator's own, driven as a holonomic base (:mod:`.planar_base`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..errors import ScenarioError
from ..runtime.tomlcheck import Abort
from . import actuators as act
from .planar_base import PLANAR_ACTUATORS

ROBOT_SUFFIX = ".robot.toml"
#: the integrators a robot file may ask for (the arena's is the first)
INTEGRATORS = ("implicitfast", "implicit")
# the actuators each drive names (omni: a list ``wheels``, roles wheel0, wheel1, ...;
# diffdrive: ``left``/``right``, or ``left0``, ``left1``, ... for a skid steer)
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


def resolved(path: Path, where: str) -> Path:
    """``path`` with its links followed; a loop of symbolic links is one line of input."""
    try:
        return path.resolve(strict=False)
    except (RuntimeError, OSError) as exc:  # RuntimeError: Python < 3.13's "Symlink loop"
        raise ScenarioError(
            f"{where}: {path} is a symbolic link that loops back on itself ({exc}); expected "
            "a link to a file"
        ) from None


def _drive_table(
    sub: Any, kind: str, roles: dict[str, str], held: dict[str, str], params: dict[str, float]
) -> None:
    """Read the drive's table ``sub`` (``[diffdrive]``, ``[holonomic]``, ...) into the
    actuators it drives (``roles``), those it holds (``held``) and its geometry (``params``)."""
    if kind == "diffdrive":
        roles.update(_sides(sub))
    else:
        for role in DRIVE_ROLES[kind]:
            roles[role] = sub.string(role)
    if kind == "swerve":
        roles.update(_modules(sub))
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


def read(path: Path, calibration_keys: tuple[str, ...]) -> dict[str, Any]:
    """Read and check one robot file: the fields of its :class:`~.robots.RobotModel` before
    the model is inspected."""
    from ..runtime.tomlcheck import Doc, Table, read_toml
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
    planar = t.boolean("planar_base", False)
    integrator = t.string("integrator", INTEGRATORS[0], choices=INTEGRATORS)
    if planar and t.ok("drive") and drive != "holonomic":
        t.report(
            "planar_base",
            f"a planar base is driven as drive = 'holonomic' (its x, y and yaw joints), got "
            f"drive = {drive!r}",
        )
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
        _drive_table(sub, kind, roles, held, params)
    if t.ok("drive") and drive not in data:
        if planar and drive == "holonomic":  # its own joints' actuators
            roles.update({"x": PLANAR_ACTUATORS[0], "y": PLANAR_ACTUATORS[1]})
            held["yaw"] = PLANAR_ACTUATORS[2]
        else:
            t.report(drive, f"missing table [{drive}] naming the actuators to drive")
    motor_tau = act.MOTOR_TIME_CONSTANT
    if "motor" in data:
        m = t.table("motor")
        motor_tau = m.number("time_constant", act.MOTOR_TIME_CONSTANT, low=0.0)
        m.finish()
    calibration: dict[str, float] = {}
    if "calibration" in data:
        c = t.table("calibration")
        for key in calibration_keys:
            if key in c.data:  # a G of 0 is no gain (eq. 30): the calibration writes none then
                strict = key in ("compensation_G", "timestep")
                calibration[key] = c.number(key, low=0.0, strict_low=strict)
                if c.ok(key) and (why := calibration_problem(key, calibration[key])):
                    c.report(key, why)
        c.used.update(calibration_keys)
        c.finish()
    # the optional keys, so that a misspelt one is told what it could be
    t.used.update(
        ("keyframe", "max_speed", "mesh_density", "motor", "calibration", "planar_base",
         "integrator", *DRIVE_ROLES)
    )  # fmt: skip
    t.finish()
    doc.raise_problems()
    mjcf = resolved(path.parent / mjcf_name, f"{path}: mjcf")
    if mjcf.is_dir():
        raise ScenarioError(f"{path}: mjcf: {mjcf} is a folder, expected an MJCF file in it")
    if not mjcf.is_file():
        raise ScenarioError(f"{path}: mjcf: no such file {mjcf}")
    return dict(
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
        planar_base=planar,
        integrator=integrator,
    )


def _sides(sub: Any) -> dict[str, str]:
    """A differential drive's wheels, ``left`` and ``right``: each a name (an actuator, or a
    joint the model's actuators turn) or a list of them (a skid steer: several wheels a
    side), as roles ``left``/``right`` or ``left0``, ``left1``, ... ``right0``, ..."""
    out: dict[str, str] = {}
    for side in ("left", "right"):
        try:
            given = sub.raw(side)
        except Abort:  # missing: reported
            continue
        if isinstance(given, str):
            out[side] = given
        elif isinstance(given, list) and given and all(isinstance(w, str) for w in given):
            if len(given) == 1:
                out[side] = given[0]
            else:
                out.update({f"{side}{k}": w for k, w in enumerate(given)})
        elif given is not None:
            sub.report(
                side,
                f"expected the name of an actuator or wheel joint, or a list of them (a skid "
                f"steer), got {given!r}",
            )
    return out


def _modules(sub: Any) -> dict[str, str]:
    """A swerve drive's ``modules = [["steer0", "drive0"], ...]``: each module's pair."""
    try:
        listed = sub.raw("modules")
    except Abort:  # missing: reported
        return {}
    pairs = isinstance(listed, list) and all(
        isinstance(m, list) and len(m) == 2 and all(isinstance(a, str) for a in m) for m in listed
    )
    if not pairs:
        sub.report("modules", f"expected a list of [steer, drive] actuator names, got {listed!r}")
        return {}
    if len(listed) < 2:
        sub.report("modules", f"expected two or more modules, got {len(listed)}")
        return {}
    out: dict[str, str] = {}
    for k, (steer, drive_name) in enumerate(listed):
        out.update({f"steer{k}": steer, f"drive{k}": drive_name})
    return out
