"""A ``dm_env`` environment: a policy drives one robot of the team (:mod:`.seat`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import dm_env
import numpy as np
from dm_env import specs

from .seat import BIG, Seats


class DFTCDmEnv(dm_env.Environment):
    """One robot of a DFTC team, driven by the policy (dm_env's interface): the observation is the
    robot's own view (``dftc_mujoco.envs.seat.FIELDS``, float32), the action its planar velocity
    command (or a correction, ``action="correction"``), the reward minus its distance from its slot
    in slots' spacings. An exclusion ends the episode with discount 0; the scenario's duration
    truncates it (discount 1: the value goes on). ``seed`` starts the stream of episodes each reset
    draws the next of; ``vary`` as in ``dftc_mujoco.envs.gym.DFTCEnv``."""

    def __init__(
        self,
        scenario: Any = "paper_case",
        robot: int = 1,
        seed: int | None = None,
        vary: Mapping[str, Any] | None = None,
        action: str = "velocity",
    ) -> None:
        self.seats = Seats(scenario, [int(robot) - 1], vary, action)
        self.robot = int(robot) - 1
        self._rng = np.random.default_rng(seed)
        self._started = False

    def reset(self) -> dm_env.TimeStep:
        """Start the next episode of the stream."""
        self.seats.reset(int(self._rng.integers(2**31 - 1)))
        self._started = True
        return dm_env.restart(self.seats.observe(self.robot).copy())

    def step(self, action: np.ndarray) -> dm_env.TimeStep:
        """One control period with the robot commanded ``action`` (a new episode after the
        last one ended)."""
        s, i = self.seats, self.robot
        if not self._started or s.terminated(i) or s.truncated:
            return self.reset()
        s.step({i: action})
        obs, r = s.observe(i).copy(), s.reward(i)
        if s.terminated(i):
            return dm_env.termination(r, obs)
        if s.truncated:
            return dm_env.truncation(r, obs)
        return dm_env.transition(r, obs)

    def observation_spec(self) -> specs.BoundedArray:
        """The robot's view, one float32 vector (``dftc_mujoco.envs.seat.FIELDS``)."""
        size = (self.seats.size(self.robot),)
        return specs.BoundedArray(size, np.float32, -BIG, BIG, name="observation")

    def action_spec(self) -> specs.BoundedArray:
        """The planar velocity command, within the drive's range."""
        lim = self.seats.limit
        return specs.BoundedArray((2,), np.float64, -lim, lim, name="velocity")

    def close(self) -> None:
        """Release the simulation."""
        self.seats.close()
