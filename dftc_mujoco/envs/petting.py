"""A PettingZoo parallel environment: one agent per driven robot (:mod:`.seat`)."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from .seat import BIG, Seats


class DFTCParallelEnv(ParallelEnv):
    """Robots of a DFTC team as agents (``robot_1``, ...): each observes its own view
    (flattened, float32) and commands its own planar velocity; robots that are not agents
    run the scenario's blocks. Rewards: minus each robot's distance to its slot."""

    metadata: ClassVar[dict[str, Any]] = {"name": "dftc_parallel_v0", "render_modes": []}

    def __init__(self, scenario: Any, robots: list[int] | None = None) -> None:
        from .seat import scenario_of

        s = scenario_of(scenario)
        chosen = [int(r) - 1 for r in (robots or range(1, s.team.robots + 1))]
        self.seats = Seats(s, chosen)
        self.index = {f"robot_{i + 1}": i for i in chosen}
        self.possible_agents = list(self.index)
        self.agents: list[str] = []
        lim = self.seats.limit
        self._obs = {
            a: spaces.Box(
                -BIG,
                BIG,
                (sum(int(np.prod(v)) for v in self.seats.sizes(i).values()),),
                np.float32,
            )
            for a, i in self.index.items()
        }
        self._act = {a: spaces.Box(-lim, lim, (2,), np.float32) for a in self.index}

    def observation_space(self, agent: str) -> spaces.Box:
        """The agent's observation: its robot's own view, flattened."""
        return self._obs[agent]

    def action_space(self, agent: str) -> spaces.Box:
        """The agent's planar velocity command."""
        return self._act[agent]

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        """Start the run again; ``seed`` replaces the scenario's seed."""
        self.seats.reset(seed)
        self.agents = list(self.possible_agents)
        return (
            {a: self.seats.flat(self.index[a]) for a in self.agents},
            {a: self.seats.info(self.index[a]) for a in self.agents},
        )

    def step(self, actions: dict[str, np.ndarray]) -> tuple[dict, dict, dict, dict, dict]:
        """One control period with each agent's robot commanded its action."""
        self.seats.step({self.index[a]: v for a, v in actions.items() if a in self.index})
        done = self.seats.done
        live = list(self.agents)
        obs = {a: self.seats.flat(self.index[a]) for a in live}
        rewards = {a: self.seats.reward(self.index[a]) for a in live}
        terms = dict.fromkeys(live, done)
        truncs = dict.fromkeys(live, False)
        infos = {a: self.seats.info(self.index[a]) for a in live}
        if done:
            self.agents = []
        return obs, rewards, terms, truncs, infos

    def close(self) -> None:
        """Release the simulation."""
        self.seats.close()
