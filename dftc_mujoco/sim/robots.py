"""Robot models and their adapters (the contract is in ``models/robots/README.md``).

A robot model is an MJCF file: a root body ``base``, a site ``center`` (the
point whose planar position the DFTC controls), velocity actuators, and a
``<custom>`` block that names its adapter and its measured model mismatch
(``dftc_xi_bar``). The adapter turns the planar velocity each robot's DFTC
stack asks for into actuator commands, and a planar fault into actuator
offsets. Models are found by name in ``models/robots/`` or by path.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import mujoco
import numpy as np

from ..errors import ScenarioError
from ..paths import MODELS

ROBOTS = MODELS / "robots"
FORBIDDEN = ("option", "compiler", "size", "visual", "statistic", "default", "keyframe")
GROUND_GROUP = 3  # geoms in this group touch the floor (wheels, casters); others are hull


class Adapter(Protocol):
    """Maps planar velocities to one robot model's actuators (leading robot axis)."""

    actuators: tuple[str, ...]
    command_limit: float

    def command(self, u_bar: np.ndarray) -> np.ndarray:
        """Actuator commands (N, A) for desired planar velocities ``u_bar`` (N, 2)."""
        ...

    def bias(self, phi: np.ndarray) -> np.ndarray:
        """Actuator offsets (N, A), in command units, that shift the velocity by ``phi`` (N, 2)."""
        ...

    def planar(self, ctrl: np.ndarray, heading: np.ndarray | None = None) -> np.ndarray:
        """The planar velocity (N, 2) that actuator commands ``ctrl`` (N, A) ask for, with
        the robots' headings (N,) [rad] if given, else their current ones."""
        ...


@dataclass(frozen=True)
class RobotModel:
    """A robot model: its MJCF file and what the simulator needs to know about it."""

    name: str
    path: Path
    adapter_kind: str
    footprint_radius: float  # horizontal reach of the colliding geoms from the site [m]
    xi_bar: float  # recommended ξ̄ [m/s], from calibrate
    params: dict[str, float] = field(default_factory=dict)
    mass: float = 0.0  # from the mesh, for mesh robots (0: MJCF's own)
    inertia: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mismatch: float = 0.0  # measured ‖ẋ − u‖ on smooth commands [m/s], from calibrate

    def spec(self) -> mujoco.MjSpec:
        """A fresh MjSpec of the robot, mesh paths absolute, mesh inertia applied."""
        spec = mujoco.MjSpec.from_file(str(self.path))
        for mesh in spec.meshes:
            if mesh.file and not Path(mesh.file).is_absolute():
                mesh.file = str((self.path.parent / spec.meshdir / mesh.file).resolve())
        spec.meshdir = ""
        if self.adapter_kind == "holonomic" and "mesh_density" in self.params:
            base = spec.body("base")
            base.explicitinertial = True
            base.mass = self.mass
            base.inertia = list(self.inertia)
            base.ipos = [0.0, 0.0, self.params.get("mesh_com_z", 0.0)]
        return spec

    def adapter(self, scene: Any, data: mujoco.MjData) -> Adapter:
        """The adapter for this model, bound to a scene's robots."""
        cls = ADAPTERS[self.adapter_kind]
        return cls(self, scene, data)


class HolonomicAdapter:
    """Robots on x/y slide joints: actuators ``vx`` and ``vy`` take the planar velocity as is."""

    actuators = ("vx", "vy")
    pose_dependent = False  # commands do not depend on the robot's heading

    def __init__(self, robot: RobotModel, scene: Any, data: mujoco.MjData) -> None:
        rng = scene.model.actuator_ctrlrange[scene.actuator]
        self.command_limit = float(np.abs(rng).min())

    def command(self, u_bar: np.ndarray) -> np.ndarray:
        return u_bar

    def bias(self, phi: np.ndarray) -> np.ndarray:
        return phi

    def planar(self, ctrl: np.ndarray, heading: np.ndarray | None = None) -> np.ndarray:
        return ctrl


class DiffDriveAdapter:
    """Differential drive: offset-point feedback linearisation (wheel speeds from ū).

    The controlled point p lies ``offset`` = b ahead of the axle on the robot's
    heading θ. With forward speed v and turn rate ω,
    ṗ = [cos θ, −b sin θ; sin θ, b cos θ] [v; ω], which is inverted exactly, so
    the DFTC sees the integrator ṗ = ū at p. Wheel speeds (rad/s):
    ω_{l,r} = (v ∓ ω L/2) / r. The heading is the robot's own (its compass or
    odometry), read from its body orientation.
    """

    actuators = ("wheel_l", "wheel_r")
    pose_dependent = True  # wheel commands depend on the robot's heading

    def __init__(self, robot: RobotModel, scene: Any, data: mujoco.MjData) -> None:
        self.r = robot.params["wheel_radius"]
        self.half = robot.params["axle_width"] / 2
        self.b = robot.params["offset"]
        self.data = data
        self.body = scene.body
        w_max = float(np.abs(scene.model.actuator_ctrlrange[scene.actuator]).min())
        # the per-axis planar speed reachable in every heading
        self.command_limit = w_max * self.r * min(1.0, self.b / self.half) / np.sqrt(2)

    def _heading(self) -> tuple[np.ndarray, np.ndarray]:
        mat = self.data.xmat[self.body]  # (N, 9), row-major
        c, s = mat[:, 0], mat[:, 3]
        norm = np.hypot(c, s)
        unset = norm == 0.0  # kinematics not computed yet: heading 0
        norm[unset] = 1.0
        return np.where(unset, 1.0, c / norm), s / norm

    def _wheels(self, u: np.ndarray) -> np.ndarray:
        c, s = self._heading()
        v = c * u[:, 0] + s * u[:, 1]
        w = (-s * u[:, 0] + c * u[:, 1]) / self.b
        return np.stack([(v - w * self.half) / self.r, (v + w * self.half) / self.r], axis=1)

    def command(self, u_bar: np.ndarray) -> np.ndarray:
        return self._wheels(u_bar)

    def bias(self, phi: np.ndarray) -> np.ndarray:
        return self._wheels(phi)

    def planar(self, ctrl: np.ndarray, heading: np.ndarray | None = None) -> np.ndarray:
        c, s = self._heading() if heading is None else (np.cos(heading), np.sin(heading))
        v = self.r * (ctrl[:, 0] + ctrl[:, 1]) / 2
        w = self.r * (ctrl[:, 1] - ctrl[:, 0]) / (2 * self.half)
        return np.stack([c * v - self.b * s * w, s * v + self.b * c * w], axis=1)


ADAPTERS: dict[str, type] = {"holonomic": HolonomicAdapter, "diffdrive": DiffDriveAdapter}
_REQUIRED = {"diffdrive": ("wheel_radius", "axle_width", "offset")}


def _fail(path: Path, message: str) -> None:
    raise ScenarioError(f"{path}: {message}")


def _check_xml(path: Path) -> None:
    """Forbidden top-level elements (they would clash with the arena)."""
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        _fail(path, f"not valid XML: {exc}")
    for child in root:
        if child.tag in FORBIDDEN:
            _fail(
                path,
                f"<{child.tag}> is not allowed in a robot file (the arena sets "
                f"{', '.join('<' + t + '>' for t in FORBIDDEN)}); remove it",
            )


def _declarations(spec: mujoco.MjSpec) -> tuple[dict[str, str], dict[str, float]]:
    texts = {t.name: t.data for t in spec.texts if t.name.startswith("dftc_")}
    nums = {
        n.name: float(np.atleast_1d(n.data)[0]) for n in spec.numerics if n.name.startswith("dftc_")
    }
    return texts, nums


def _mesh_properties(spec: mujoco.MjSpec, path: Path, density: float) -> dict[str, Any]:
    """Mass, inertia, centre of mass and horizontal radius of the robot's mesh, from trimesh."""
    import trimesh

    meshes = [m for m in spec.meshes if m.file]
    if not meshes:
        _fail(path, "dftc_mesh_density is set but the robot has no <mesh file=...>")
    file = (path.parent / spec.meshdir / meshes[0].file).resolve()
    try:
        mesh = trimesh.load(file, force="mesh")
    except Exception as exc:  # trimesh raises many kinds
        _fail(path, f"cannot load mesh {file}: {exc}")
    if not mesh.is_watertight:
        _fail(path, f"mesh {file} is not watertight: its volume and inertia are undefined")
    mesh.density = density
    inertia = np.diag(mesh.moment_inertia)
    radius = float(np.hypot(mesh.vertices[:, 0], mesh.vertices[:, 1]).max())
    return {
        "mass": float(mesh.mass),
        "inertia": tuple(float(v) for v in inertia),
        "com_z": float(mesh.center_mass[2]),
        "radius": radius,
    }


def _footprint(spec_model: mujoco.MjModel) -> float:
    """Largest horizontal reach of the hull (non-ground colliding geoms) from site 'center'."""
    m = spec_model
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    centre = d.site_xpos[m.site("center").id][:2]
    reach = 0.0
    for g in range(m.ngeom):
        if (m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0) or m.geom_group[
            g
        ] == GROUND_GROUP:
            continue
        t = int(m.geom_type[g])
        size = m.geom_size[g]
        if t in (
            int(mujoco.mjtGeom.mjGEOM_CYLINDER),
            int(mujoco.mjtGeom.mjGEOM_SPHERE),
            int(mujoco.mjtGeom.mjGEOM_CAPSULE),
        ):
            r = size[0]
        elif t == int(mujoco.mjtGeom.mjGEOM_BOX):
            r = float(np.hypot(size[0], size[1]))
        elif t == int(mujoco.mjtGeom.mjGEOM_MESH):
            mid = m.geom_dataid[g]
            start, count = m.mesh_vertadr[mid], m.mesh_vertnum[mid]
            verts = m.mesh_vert[start : start + count]
            rot = d.geom_xmat[g].reshape(3, 3)
            world = verts @ rot.T + d.geom_xpos[g]
            reach = max(reach, float(np.linalg.norm(world[:, :2] - centre, axis=1).max()))
            continue
        else:
            r = m.geom_rbound[g]
        reach = max(reach, float(np.linalg.norm(d.geom_xpos[g][:2] - centre)) + r)
    return reach


def available() -> list[str]:
    """Names of the robot models in ``models/robots/``."""
    return sorted(p.stem for p in ROBOTS.glob("*.xml"))


def get(name: str, where: str = "team.robot_model") -> RobotModel:
    """The robot model called ``name`` (in ``models/robots/``) or stored at path ``name``.

    ``where`` says where the name came from, for the error message.
    """
    path = Path(name)
    if path.suffix != ".xml":
        path = ROBOTS / f"{name}.xml"
    if not path.is_file():
        raise ScenarioError(
            f"{where}: unknown robot model {name!r} (available: {', '.join(available())}; "
            "or give the path to an MJCF file)"
        )
    return load(path)


def load(path: Path) -> RobotModel:
    """Read and check one robot file against the contract."""
    path = path.resolve()
    _check_xml(path)
    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except Exception as exc:
        _fail(path, f"MuJoCo cannot read it: {exc}")
    texts, nums = _declarations(spec)
    kind = texts.get("dftc_adapter", "holonomic")
    if kind not in ADAPTERS:
        _fail(path, f"dftc_adapter: expected one of {', '.join(ADAPTERS)}, got {kind!r}")
    if spec.body("base") is None:
        _fail(path, "no root body named 'base'")
    if spec.site("center") is None:
        _fail(path, "no site named 'center' (the point whose position the DFTC controls)")
    params = {k.removeprefix("dftc_"): v for k, v in nums.items()}
    for key in _REQUIRED.get(kind, ()):
        if key not in params:
            _fail(path, f'the {kind} adapter needs <numeric name="dftc_{key}" data="..."/>')
    mesh: dict[str, Any] = {}
    if "mesh_density" in params:
        mesh = _mesh_properties(spec, path, params["mesh_density"])
        params["mesh_com_z"] = mesh["com_z"]
    provisional = RobotModel(
        path.stem,
        path,
        kind,
        0.0,
        0.0,
        params,
        mass=mesh.get("mass", 0.0),
        inertia=mesh.get("inertia", (0.0, 0.0, 0.0)),
    )
    try:
        compiled = provisional.spec().compile()
    except Exception as exc:
        _fail(path, f"MuJoCo cannot compile it: {exc}")
    names = {compiled.actuator(a).name for a in range(compiled.nu)}
    missing = [a for a in ADAPTERS[kind].actuators if a not in names]
    if missing:
        _fail(
            path,
            f"the {kind} adapter drives actuators {', '.join(ADAPTERS[kind].actuators)}; "
            f"missing: {', '.join(missing)}",
        )
    xi_bar = params.pop("xi_bar", 0.005)
    mismatch = params.pop("mismatch", 0.0)
    return RobotModel(
        path.stem,
        path,
        kind,
        _footprint(compiled),
        xi_bar,
        params,
        mass=mesh.get("mass", 0.0),
        inertia=mesh.get("inertia", (0.0, 0.0, 0.0)),
        mismatch=mismatch,
    )
