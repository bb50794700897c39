"""A PettingZoo parallel environment: one agent per driven robot (:mod:`.seat`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from .seat import BIG, Seats, scenario_of


class DFTCParallelEnv(ParallelEnv):
    """Robots of a DFTC team as agents (``robot_1``, ...): each observes its own view
    (:data:`.seat.FIELDS`, float32) and commands its own planar velocity (or a correction of
    the team's command, ``action="correction"``); robots that are not agents run the
    scenario's blocks. Rewards: minus each robot's distance from its slot, in slots'
    spacings. An agent whose robot is excluded terminates and leaves ``agents``; every
    agent is truncated at the scenario's duration. ``vary`` and seeds as in
    :class:`~.gym.DFTCEnv`."""

    metadata: ClassVar[dict[str, Any]] = {"name": "dftc_parallel_v1", "render_modes": []}

    def __init__(
        self,
        scenario: Any = "paper_case",
        robots: list[int] | None = None,
        vary: Mapping[str, Any] | None = None,
        action: str = "velocity",
    ) -> None:
        s = scenario_of(scenario)
        chosen = [int(r) - 1 for r in (robots or range(1, s.team.robots + 1))]
        self.seats = Seats(s, chosen, vary, action)
        self.index = {f"robot_{i + 1}": i for i in chosen}
        self.possible_agents = list(self.index)
        self.agents: list[str] = []
        lim = self.seats.limit
        self._obs = {
            a: spaces.Box(-BIG, BIG, (self.seats.size(i),), np.float32)
            for a, i in self.index.items()
        }
        self._act = {a: spaces.Box(-lim, lim, (2,), np.float32) for a in self.index}
        self._rng = np.random.default_rng()

    def observation_space(self, agent: str) -> spaces.Box:
        """The agent's observation: its robot's own view."""
        return self._obs[agent]

    def action_space(self, agent: str) -> spaces.Box:
        """The agent's planar velocity command."""
        return self._act[agent]

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        """Start an episode: the one ``seed`` fixes, or without one the next of the stream."""
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.seats.reset(int(self._rng.integers(2**31 - 1)))
        self.agents = list(self.possible_agents)
        return (
            {a: self.seats.observe(self.index[a]).copy() for a in self.agents},
            {a: self.seats.info(self.index[a]) for a in self.agents},
        )

    def step(self, actions: dict[str, np.ndarray]) -> tuple[dict, dict, dict, dict, dict]:
        """One control period with each agent's robot commanded its action (every live
        agent must act: a missing or unknown agent is refused, as PettingZoo expects)."""
        if not isinstance(actions, dict):
            raise TypeError(f"step(actions): expected a dict of agent -> action, got {actions!r}")
        missing = [a for a in self.agents if a not in actions]
        unknown = [a for a in actions if a not in self.agents]
        if missing or unknown:
            raise KeyError(
                f"step(actions): the live agents are {self.agents}; "
                + (f"missing {missing}" if missing else f"not live {unknown}")
            )
        s = self.seats
        s.step({self.index[a]: actions[a] for a in self.agents})
        live = list(self.agents)
        obs = {a: s.observe(self.index[a]).copy() for a in live}
        rewards = {a: s.reward(self.index[a]) for a in live}
        terms = {a: s.terminated(self.index[a]) for a in live}
        truncs = {a: s.truncated and not terms[a] for a in live}
        infos = {a: s.info(self.index[a]) for a in live}
        self.agents = [a for a in live if not (terms[a] or truncs[a])]
        return obs, rewards, terms, truncs, infos

    def close(self) -> None:
        """Release the simulation."""
        self.seats.close()
