"""dm_control's environment: a policy drives one robot of the team (``dftc_mujoco.envs.seat``).

:func:`environment` is a ``dm_control.rl.control.Environment`` of two parts, as dm_control's
own domains are:

* :class:`TeamPhysics`, a ``dm_control.mujoco.Physics`` over the simulation's own
  ``MjData`` (no copy): one of its steps is one control period of the team, the onboard
  blocks and the physics substeps included, so ``physics.timestep()`` is the control
  period; ``physics.render()``, ``physics.named`` and dm_control's viewer read the team's
  state as it is.
* :class:`HoldSlotTask`, a ``dm_control.suite.base.Task``: it starts each episode from its
  own random state (``random``, dm_control's convention), commands the driven robot before
  each step, observes it (``seat.FIELDS``, one named entry each), rewards minus its
  distance from its slot in slots' spacings, and ends the episode with discount 0 when the
  robot is excluded. The scenario's duration is the environment's time limit: the last
  step of a full episode has discount 1 (truncation).
"""

from __future__ import annotations

import collections
from collections.abc import Mapping
from typing import Any

import numpy as np
from dm_control import mujoco
from dm_control.mujoco.wrapper import core
from dm_control.rl import control
from dm_control.suite import base
from dm_env import specs

from .seat import BIG, FIELDS, Seats


class TeamPhysics(mujoco.Physics):
    """dm_control's Physics of a team's simulation (``seats.sim``): its data is the
    simulation's own, and a step is one control period of the whole team."""

    seats: Seats
    _commands: dict[int, np.ndarray]

    @classmethod
    def of(cls, seats: Seats) -> TeamPhysics:
        """The Physics of the simulation ``seats`` runs."""
        physics = cls(core.MjData(seats.sim.data))
        physics.seats = seats
        physics._commands = {}
        return physics

    def rebind(self) -> None:
        """Follow the simulation after an episode began (it may be a new one)."""
        if self.data.ptr is not self.seats.sim.data:
            self._reload_from_data(core.MjData(self.seats.sim.data))

    def command(self, robot: int, action: np.ndarray) -> None:
        """Command ``robot`` (0-based) with ``action`` in the next step."""
        self._commands[robot] = action

    def step(self, nstep: int = 1) -> None:
        """``nstep`` control periods of the team, the driven robots commanded as told."""
        for _ in range(nstep):
            self.seats.step(self._commands)

    def timestep(self) -> float:
        """The control period [s]: one step of this Physics."""
        return float(self.seats.scenario.physics.control_period)

    def reset(self, keyframe_id: int | None = None) -> None:
        """Nothing: an episode begins in :meth:`HoldSlotTask.initialize_episode`, where the
        simulation sets its own start."""

    def after_reset(self) -> None:
        """Nothing: the simulation's start is already consistent."""


class HoldSlotTask(base.Task):
    """Robot ``robot`` (0-based) of the team, driven by the policy: its planar velocity
    command (or a correction of the team's, with ``action="correction"`` in the seats)."""

    def __init__(self, robot: int, random: Any = None) -> None:
        super().__init__(random=random)
        self.robot = robot

    def initialize_episode(self, physics: TeamPhysics) -> None:
        """The next episode of this task's random stream."""
        physics.seats.reset(int(self.random.randint(2**31 - 1)))
        physics.rebind()

    def before_step(self, action: np.ndarray, physics: TeamPhysics) -> None:
        physics.command(self.robot, action)

    def get_observation(self, physics: TeamPhysics) -> collections.OrderedDict:
        """The robot's view, one entry per field of ``seat.FIELDS`` (float32)."""
        view = physics.seats.observe(self.robot)
        out = collections.OrderedDict()
        at = 0
        for (name, *_), size in zip(FIELDS, self._sizes(physics), strict=True):
            out[name] = view[at : at + size].copy()
            at += size
        return out

    def get_reward(self, physics: TeamPhysics) -> float:
        return physics.seats.reward(self.robot)

    def get_termination(self, physics: TeamPhysics) -> float | None:
        """Discount 0 once the robot is excluded (or the team or the physics ends it), 1 at
        the scenario's duration (the environment's time limit says the same)."""
        seats = physics.seats
        if seats.terminated(self.robot):
            return 0.0
        return 1.0 if seats.truncated else None

    def action_spec(self, physics: TeamPhysics) -> specs.BoundedArray:
        """The planar velocity command, within the drive's range."""
        lim = physics.seats.limit
        return specs.BoundedArray((2,), np.float64, -lim, lim, name="velocity")

    def observation_spec(self, physics: TeamPhysics) -> collections.OrderedDict:
        return collections.OrderedDict(
            (name, specs.BoundedArray((size,), np.float32, -BIG, BIG, name=name))
            for (name, *_), size in zip(FIELDS, self._sizes(physics), strict=True)
        )

    def _sizes(self, physics: TeamPhysics) -> list[int]:
        """Each field's length for this robot (``d``: its in-neighbours, ``N``: the team)."""
        seats = physics.seats
        d, n = len(seats.heard[self.robot]), seats.n
        return [{"1": 1, "2": 2, "2d": 2 * d, "N": n}[size] for _, size, *_ in FIELDS]


def environment(
    scenario: Any,
    robot: int = 1,
    seed: int | None = None,
    vary: Mapping[str, Any] | None = None,
    action: str = "velocity",
) -> control.Environment:
    """dm_control's Environment in which a policy drives ``robot`` (numbered from 1) of the
    team of ``scenario``; ``seed`` starts the task's random stream of episodes, ``vary`` draws
    each episode's faults, starts or keys (a campaign's ``[vary]`` table)."""
    seats = Seats(scenario, [int(robot) - 1], vary, action)
    physics = TeamPhysics.of(seats)
    task = HoldSlotTask(int(robot) - 1, random=seed)
    return control.Environment(
        physics,
        task,
        time_limit=float(seats.scenario.duration),
        n_sub_steps=1,
    )
