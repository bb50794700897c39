"""A ``dm_env`` environment: a policy drives one robot of the team (:mod:`.seat`)."""

from __future__ import annotations

from typing import Any

import dm_env
import numpy as np
from dm_env import specs

from .seat import BIG, FIELDS, Seats


class DFTCDmEnv(dm_env.Environment):
    """One robot of a DFTC team, driven by the policy (dm_env's interface): observations are
    a dict of the robot's own view (:data:`.seat.FIELDS`), the action its planar velocity
    command, the reward minus its distance to its slot."""

    def __init__(self, scenario: Any, robot: int = 1, seed: int | None = None) -> None:
        self.seats = Seats(scenario, [int(robot) - 1])
        self.robot, self.seed = int(robot) - 1, seed
        self._started = False

    def reset(self) -> dm_env.TimeStep:
        """Start the run again."""
        self.seats.reset(self.seed)
        self._started = True
        return dm_env.restart(self.seats.observe(self.robot))

    def step(self, action: np.ndarray) -> dm_env.TimeStep:
        """One control period with the robot commanded ``action`` (a new episode after the
        last one ended)."""
        if not self._started or self.seats.done:
            return self.reset()
        self.seats.step({self.robot: action})
        obs, r = self.seats.observe(self.robot), self.seats.reward(self.robot)
        if self.seats.done:
            return dm_env.termination(r, obs)
        return dm_env.transition(r, obs)

    def observation_spec(self) -> dict[str, specs.BoundedArray]:
        """One float32 array per entry of the robot's view."""
        return {
            k: specs.BoundedArray(shape, np.float32, -BIG, BIG, name=k)
            for k, shape in self.seats.sizes(self.robot).items()
            if k in FIELDS
        }

    def action_spec(self) -> specs.BoundedArray:
        """The planar velocity command, within the drive's range."""
        lim = self.seats.limit
        return specs.BoundedArray((2,), np.float64, -lim, lim, name="velocity")

    def close(self) -> None:
        """Release the simulation."""
        self.seats.close()
