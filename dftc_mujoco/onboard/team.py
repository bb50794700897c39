"""The N onboard DFTC stacks of Fig. 1, batched on a leading robot axis.

Row i of every array belongs to robot i and is computed from robot i's own
measurement and inputs, the messages ʲŷ of its in-neighbours j (delivered by
:class:`~dftc_mujoco.onboard.observer.Messages` along the graph's edges), its
own obstacle sensing and the mission that every robot is given.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..graph import Graph
from . import controller, observer
from .supervisor import Supervisor


@dataclass(frozen=True)
class TeamConfig:
    """Everything the onboard stacks are configured with (no simulator state)."""

    graph: Graph
    kc: float
    ko: float
    theta: float
    dt: float  # control period
    obstacle_position: np.ndarray  # (O, 2) what the robots' sensors report
    obstacle_safe: np.ndarray  # (O,) d of eq. 17
    obstacle_activation: np.ndarray  # (O,)


@dataclass
class TeamOutput:
    """What one control period of the whole team produces (leading robot axis)."""

    u: np.ndarray  # (N, 2) nominal input uᵢ of eq. 8
    u_bar: np.ndarray  # (N, 2) input sent to the actuators (eq. 28)
    x_hat: np.ndarray  # (N, N, 2) ⁱx̂ at this instant (before the update)
    residual: np.ndarray  # (N, N, 2) ⁱr (eq. 35)
    reactive: np.ndarray  # (N,) bool: robot on a reactive behaviour


class Team:
    """The team's onboard computers; :meth:`step` advances all of them by one period.

    The observer state is updated in place (preallocated arrays); the outputs
    of :meth:`step` are views into buffers that the next call overwrites.
    """

    def __init__(self, config: TeamConfig, x_m0: np.ndarray, prior: np.ndarray) -> None:
        n = config.graph.n
        self.config = config
        self.n = n
        self.messages = observer.Messages(config.graph.edges, n)
        self.state = observer.ObserverState.initial(x_m0, prior)
        self.supervisor = Supervisor(n, config.theta)
        self._x_hat = np.empty((n, n, 2))
        self._u_hat_g = np.empty((n, n, 2))

    def step(self, x_m: np.ndarray, x_d: np.ndarray, xd_dot: np.ndarray) -> TeamOutput:
        """One control period for every robot.

        ``x_m`` (N, 2): each robot's own noisy position; ``x_d``, ``xd_dot``
        (N, 2): the desired positions and velocities J⁻¹σ_d, J⁻¹σ̇_d.
        """
        c = self.config
        x_hat = self.state.estimate(out=self._x_hat)  # eq. 21
        u_hat_g = controller.collective_input(x_hat, x_d, xd_dot, c.kc, out=self._u_hat_g)
        u_g = controller.own_input(u_hat_g)  # eq. 16
        u, delta_u = self.supervisor.step(
            x_m, u_g, c.obstacle_position, c.obstacle_safe, c.obstacle_activation
        )  # eqs. 8, 18, 22
        r = observer.residual(self.state, self.messages, x_m)  # eq. 35
        observer.update(self.state, r, u_hat_g, delta_u, u, c.ko, c.dt)  # eqs. 19-21
        return TeamOutput(u=u, u_bar=u, x_hat=x_hat, residual=r, reactive=self.supervisor.reactive)
