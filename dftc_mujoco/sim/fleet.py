"""A team's robots: one model each (``team.robot_model`` a name, or one per robot).

A mixed team (a TidyBot beside a differential drive beside an omni base) is composed in
one scene, each robot with its own MJCF, drive and actuators (:mod:`.scene`,
:class:`MixedDrive`, :class:`MixedFaults`). The onboard blocks and the threshold rules are
configured for the whole team, so they take the team's **envelope** (:func:`envelope`):
the bounds every member satisfies — the largest ξ̄, measured mismatch, drift offset and
footprint, the largest calibrated compensation gain G, the smallest acceleration limit and
command range. A bound that holds for the worst robot holds for each (eq. 2's ξ̄, the
rules' ē), at the price of wider thresholds for the better ones. Each robot models its own
drive lag (``[calibration] lag``,
:func:`~dftc_mujoco.closed_loop.assembly.drive_lag`); the envelope's is the slowest robot's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from ..scenario import Scenario
from . import robots
from .faults import ActuatorFaults
from .robots import RobotModel


@dataclass(frozen=True)
class Fleet:
    """Each robot's model (N,), and the team's envelope."""

    models: tuple[RobotModel, ...]
    envelope: RobotModel

    @property
    def mixed(self) -> bool:
        """More than one model in the team."""
        return len({m.path for m in self.models}) > 1

    def groups(self) -> list[tuple[RobotModel, np.ndarray]]:
        """The team's models in order of first appearance, each with its robots (0-based)."""
        order: dict[Path, list[int]] = {}
        for i, m in enumerate(self.models):
            order.setdefault(m.path, []).append(i)
        first = {m.path: m for m in reversed(self.models)}
        return [(first[p], np.array(idx, dtype=int)) for p, idx in order.items()]


def load(names: tuple[str, ...], where: str, base: Path | None) -> Fleet:
    """The fleet for each robot's model name or file (``names``, one per robot)."""
    by_name: dict[str, RobotModel] = {}
    for name in dict.fromkeys(names):
        by_name[name] = robots.load(robots.resolve(name, where, base))
    models = tuple(by_name[n] for n in names)
    return Fleet(models, envelope(models, where))


def for_scenario(scenario: Scenario) -> tuple[Scenario, Fleet]:
    """The fleet of ``scenario``, and the scenario with each robot file named by its
    absolute path (built-in names kept)."""
    names = scenario.team.models
    team = load(names, f"{scenario.source}: team.robot_model", scenario.directory)
    built_in = robots.available()
    paths = tuple(
        n if n in built_in else str(m.path) for n, m in zip(names, team.models, strict=True)
    )
    if paths != names:
        scenario = scenario.with_overrides(robot_model=paths if team.mixed else paths[0])
    return with_step(scenario, min(m.timestep for m in team.models)), team


def with_step(scenario: Scenario, most: float) -> Scenario:
    """``scenario`` stepping at most ``most`` s (a robot whose drive runs away at a longer
    step: its calibrated ``timestep``), a whole number of steps per control period."""
    physics = scenario.physics
    if not most < physics.timestep:
        return scenario
    steps = math.ceil(physics.control_period / most - 1e-9)
    return replace(scenario, physics=replace(physics, timestep=physics.control_period / steps))


def actuation(
    team: Fleet, scene: Any, data: mujoco.MjData, dt: float, faults: tuple[Any, ...]
) -> tuple[Any, ActuatorFaults | MixedFaults]:
    """The team's drive and actuator faults: one model's, or each model's on its robots."""
    if team.mixed:
        drive = MixedDrive(team, scene, data, dt)
        return drive, MixedFaults(scene.model, faults, drive)
    drive = team.envelope.adapter(scene, data, dt)
    return drive, ActuatorFaults(scene.model, faults, drive)


def envelope(models: tuple[RobotModel, ...], where: str = "team.robot_model") -> RobotModel:
    """One model that stands for the team in every team-wide setting (module docstring):
    the first model with the team's bounds. A single model is itself."""
    unique = list({m.path: m for m in models}.values())
    if len(unique) == 1:
        return unique[0]
    cal: dict[str, float] = {}
    team_wide = ("xi_bar", "mismatch", "drift_bound", "drift_startup", "compensation_G")
    for key in (*team_wide, "response_time"):  # the largest: the slowest robot's
        found = [m.calibration[key] for m in unique if key in m.calibration]
        if found and (key != "xi_bar" or len(found) == len(unique)):  # calibrated: all are
            cal[key] = max(found)
    accel = min(m.accel for m in unique)
    if math.isfinite(accel):
        cal["accel"] = accel
    lags = [m.lag for m in unique]
    if max(lags) > 0:  # each robot models its own (assembly.drive_lag); this: the slowest
        cal["lag"] = max(lags)
    fast = [m.fast_lag for m in unique]
    if min(fast) > 0:  # the drive rule's model: the slowest robot's, when every robot has one
        cal["fast_lag"] = max(fast)
    speeds = [m.max_speed for m in unique if m.max_speed is not None]
    return replace(
        unique[0],
        name="/".join(m.name for m in unique),
        xi_bar=max(m.xi_bar for m in unique),
        mismatch=max(m.mismatch for m in unique),
        calibration=cal,
        max_speed=min(speeds) if speeds else None,
        footprint_radius=max(m.footprint_radius for m in unique),
    )


@dataclass(frozen=True)
class Group:
    """The robots of one model in a scene: what a drive needs of them (a scene's view)."""

    model: mujoco.MjModel
    robots: np.ndarray  # (n,) 0-based robots of the team
    body: np.ndarray  # (n,) their base bodies
    actuator: np.ndarray  # (n, A) their driven actuators
    held: np.ndarray  # (n, H) their held actuators


class MixedDrive:
    """The drives of a mixed team, one per model, behind one drive's interface: the
    commands of every robot in one flat vector, in the scene's ``ctrl_index`` order."""

    def __init__(self, fleet: Fleet, scene: Any, data: mujoco.MjData, dt: float) -> None:
        self.parts = []  # (robots, drive, slice of the flat command)
        start = 0
        for (robot, _), group in zip(fleet.groups(), scene.groups, strict=True):
            drive = robot.adapter(group, data, dt)
            width = group.actuator.shape[1] + group.held.shape[1]
            self.parts.append(
                (group.robots, drive, slice(start, start + width * len(group.robots)))
            )
            start += width * len(group.robots)
        self._flat = np.zeros(start)
        self.command_limit = min(d.command_limit for _, d, _ in self.parts)
        self.pose_dependent = any(d.pose_dependent for _, d, _ in self.parts)

    def reset(self) -> None:
        """Every model's drive at the start of a run."""
        for _, drive, _ in self.parts:
            drive.reset()

    def command(self, u: np.ndarray) -> np.ndarray:
        """Every robot's actuator commands for ``u`` (N, 2), flat."""
        for robots_, drive, cut in self.parts:
            self._flat[cut] = np.asarray(drive.command(u[robots_])).ravel()
        return self._flat


class MixedFaults:
    """The actuator faults of a mixed team: one :class:`~.faults.ActuatorFaults` per model
    on its own robots, the faults and the commands on the team's axis."""

    def __init__(self, model: mujoco.MjModel, faults: tuple[Any, ...], drive: MixedDrive) -> None:
        self.parts = []
        n = sum(len(r) for r, _, _ in drive.parts)
        self.stuck = np.zeros(n, bool)
        self.any_stuck = False  # stuck.any(), read every period
        self._global: dict[int, Any] = {}  # id of a group's fault -> the scenario's
        for robots_, d, cut in drive.parts:
            local = np.full(n, -1)
            local[robots_] = np.arange(len(robots_))
            mine = []
            for f in faults:
                if getattr(f, "robot", -1) >= 0 and local[f.robot] >= 0:
                    g = replace(f, robot=int(local[f.robot]))
                    self._global[id(g)] = f
                    mine.append(g)
            self.parts.append((robots_, ActuatorFaults(model, tuple(mine), d), cut))
        self.just_ended: list[Any] = []
        self.due = min(p.due for _, p, _ in self.parts)

    def apply(self, t: float) -> list[Any]:
        """Each model's faults at ``t``; returns the scenario's faults that start now."""
        new, self.just_ended = [], []
        for robots_, part, _ in self.parts:
            if t >= part.due:
                new += [self._global[id(f)] for f in part.apply(t)]
                self.just_ended += [self._global[id(f)] for f in part.just_ended]
            self.stuck[robots_] = part.stuck
        self.any_stuck = bool(self.stuck.any())
        self.due = min(p.due for _, p, _ in self.parts)
        return new

    def hold(self, ctrl: np.ndarray) -> np.ndarray:
        """The flat commands with each stuck robot's kept at those of its onset (a copy)."""
        out = np.array(ctrl, copy=True)
        for robots_, part, cut in self.parts:
            if part.stuck.any():
                rows = out[cut].reshape(len(robots_), -1)
                out[cut] = part.hold(rows).ravel()
        return out

    def phi_series(self, t: np.ndarray, v_cmd: np.ndarray) -> np.ndarray:
        """The additive fault φ of eq. 1 (T, N, 2) each robot suffered, from the log."""
        phi = np.zeros((len(t), v_cmd.shape[1], 2))
        for robots_, part, _ in self.parts:
            phi[:, robots_] = part.phi_series(t, v_cmd[:, robots_])
        return phi

    def clear(self) -> None:
        """Every actuator back to its healthy parameters."""
        for _, part, _ in self.parts:
            part.clear()
        self.stuck[:] = False
        self.any_stuck = False
