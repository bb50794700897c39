"""Robot models and their adapters.

A robot model is an MJCF file under ``models/robots/`` with a root body named
``base``, a site named ``center`` (its planar position) and velocity
actuators. Its adapter turns the planar velocity each robot's DFTC stack asks
for into actuator commands, and a planar fault into actuator biases.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import mujoco
import numpy as np

from ..errors import ScenarioError
from ..paths import MODELS


class Adapter(Protocol):
    """Maps planar velocities to one robot model's actuators (leading robot axis)."""

    actuators: tuple[str, ...]

    def command(self, u_bar: np.ndarray) -> np.ndarray:
        """Actuator commands (N, A) for the desired planar velocities ``u_bar`` (N, 2)."""
        ...

    def bias(self, phi: np.ndarray) -> np.ndarray:
        """Actuator offsets (N, A), in command units, that shift the velocity by ``phi`` (N, 2)."""
        ...

    def planar(self, ctrl: np.ndarray) -> np.ndarray:
        """The planar velocity (N, 2) that actuator commands ``ctrl`` (N, A) ask for."""
        ...


class HolonomicAdapter:
    """Disk on slide joints: actuator ``vx`` and ``vy`` take the planar velocity as is."""

    actuators = ("vx", "vy")

    def command(self, u_bar: np.ndarray) -> np.ndarray:
        return u_bar

    def bias(self, phi: np.ndarray) -> np.ndarray:
        return phi

    def planar(self, ctrl: np.ndarray) -> np.ndarray:
        return ctrl


@dataclass(frozen=True)
class RobotModel:
    """A registered robot model: its MJCF file, adapter and footprint."""

    name: str
    path: Path
    adapter: type
    footprint_radius: float  # horizontal radius of the collision hull [m]

    def spec(self) -> mujoco.MjSpec:
        """A fresh MjSpec of the robot file."""
        return mujoco.MjSpec.from_file(str(self.path))


def _footprint(path: Path) -> float:
    """Largest horizontal extent of the robot's colliding geoms, from the compiled model."""
    m = mujoco.MjSpec.from_file(str(path)).compile()
    radius = 0.0
    for g in range(m.ngeom):
        if m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0:
            continue
        size = m.geom_size[g]
        t = int(m.geom_type[g])
        if t in (
            int(mujoco.mjtGeom.mjGEOM_CYLINDER),
            int(mujoco.mjtGeom.mjGEOM_SPHERE),
            int(mujoco.mjtGeom.mjGEOM_CAPSULE),
        ):
            r = size[0]
        elif t == int(mujoco.mjtGeom.mjGEOM_BOX):
            r = float(np.hypot(size[0], size[1]))
        else:
            r = m.geom_rbound[g]
        offset = float(np.hypot(*m.geom_pos[g][:2]))
        radius = max(radius, offset + r)
    return radius


_ADAPTERS = {"disk": HolonomicAdapter}


def available() -> list[str]:
    """Names of the robot models in ``models/robots/`` that have an adapter."""
    return sorted(p.stem for p in (MODELS / "robots").glob("*.xml") if p.stem in _ADAPTERS)


def get(name: str, where: str = "team.robot_model") -> RobotModel:
    """The robot model registered under ``name``; the error lists the available ones.

    ``where`` says where the name came from, for the error message.
    """
    path = MODELS / "robots" / f"{name}.xml"
    if name not in _ADAPTERS or not path.is_file():
        raise ScenarioError(
            f"{where}: unknown robot model {name!r} (available: {', '.join(available())})"
        )
    return RobotModel(name, path, _ADAPTERS[name], _footprint(path))
