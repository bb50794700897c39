"""A Gymnasium environment: a policy drives one robot of the team (:mod:`.seat`)."""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from .seat import BIG, FIELDS, Seats


class DFTCEnv(gymnasium.Env):
    """One robot of a DFTC team, driven by the policy; the rest of the team runs the
    scenario's blocks. Observation: the robot's own view (:data:`.seat.FIELDS`, flattened,
    float32); action: its planar velocity command (m/s, within the drive's range); reward:
    minus its distance to its slot; the episode ends with the scenario's duration."""

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012 - gymnasium's own type

    def __init__(self, scenario: Any, robot: int = 1) -> None:
        self.seats = Seats(scenario, [int(robot) - 1])
        self.robot = int(robot) - 1
        size = sum(int(np.prod(s)) for s in self.seats.sizes(self.robot).values())
        self.observation_space = spaces.Box(-BIG, BIG, (size,), np.float32)
        lim = self.seats.limit
        self.action_space = spaces.Box(-lim, lim, (2,), np.float32)
        self.fields = FIELDS

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start the run again; ``seed`` replaces the scenario's seed."""
        super().reset(seed=seed)
        self.seats.reset(seed)
        return self.seats.flat(self.robot), self.seats.info(self.robot)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """One control period with the robot commanded ``action``."""
        self.seats.step({self.robot: action})
        s = self.seats
        return s.flat(self.robot), s.reward(self.robot), s.done, False, s.info(self.robot)

    def close(self) -> None:
        """Release the simulation."""
        self.seats.close()
