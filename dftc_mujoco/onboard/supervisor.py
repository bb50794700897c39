"""Local supervisor: reactive obstacle avoidance in the null space (eqs. 8, 17-18, 22).

Each robot decides alone, from its own measured position and the obstacles
its sensors report, whether to switch from the global input u_g,i to the
avoidance input of eq. 18. Only one behaviour is active at a time (eq. 8).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Supervisor:
    """Switching state of every robot's supervisor (leading robot axis).

    ``active[i]`` is the obstacle robot i is avoiding, or -1 when it follows
    the global mission (α of eq. 8). Within an obstacle's activation distance
    (its sensing range) avoidance switches on when the global input would
    approach the obstacle faster than eq. 17's primary task allows, i.e. when
    r̂ᵀu_g,i < θ(d − ‖xᵢ − x_o‖), and off when r̂ᵀu_g,i exceeds that by
    ``release`` m/s. At the switching condition eq. 18 and u_g,i coincide, so
    the command does not jump (NOTES 12); ``release`` only keeps measurement
    noise from toggling the behaviour.
    """

    n_robots: int
    theta: float
    release: float = 0.01
    active: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.active = np.full(self.n_robots, -1, dtype=np.intp)

    def step(
        self,
        x: np.ndarray,
        u_g: np.ndarray,
        obstacles: np.ndarray,
        safe: np.ndarray,
        activation: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Nominal inputs uᵢ (eq. 8) and Δuᵢ (eq. 22), each (N, n).

        ``x`` (N, n) are the robots' own measured positions, ``u_g`` (N, n)
        their global inputs u_g,i, ``obstacles`` (O, n) the sensed obstacle
        centres with safe distances d (O,) and activation distances (O,).
        """
        n = len(x)
        if len(obstacles) == 0:
            self.active[:] = -1
            return u_g.copy(), np.zeros_like(u_g)
        rel = x[:, None, :] - obstacles[None, :, :]
        dist = np.sqrt(np.einsum("nok,nok->no", rel, rel))
        if not (dist < activation[None, :]).any():  # nobody near anything: the global input
            self.active[:] = -1
            return u_g.copy(), np.zeros_like(u_g)
        r_hat = rel / np.maximum(dist, 1e-9)[..., None]  # obstacle-to-robot unit vector
        radial = np.einsum("nok,nk->no", r_hat, u_g)  # r̂ᵀ u_g,i
        barrier = self.theta * (safe[None, :] - dist)  # θ (d − ‖xᵢ − x_o‖), eq. 17
        current = self.active[:, None] == np.arange(len(obstacles))[None, :]
        needed = radial < barrier + self.release * current
        margin = np.where(needed & (dist < activation[None, :]), dist - safe[None, :], np.inf)
        best = np.argmin(margin, axis=1)
        rows = np.arange(n)
        on = np.isfinite(margin[rows, best])
        self.active = np.where(on, best, -1)

        r = r_hat[rows, best]  # Jₗ = r̂ᵀ, Jₗ† = r̂
        # eq. 18: Jₗ† θ (d − ‖xᵢ − x_o‖) + (I − r̂ r̂ᵀ) u_g,i
        u_l = (barrier[rows, best] - radial[rows, best])[:, None] * r + u_g
        u = np.where(on[:, None], u_l, u_g)
        return u, u - u_g  # Δuᵢ = uᵢ − u_g,i (eq. 22 with one active behaviour)

    @property
    def reactive(self) -> np.ndarray:
        """Which robots are currently on a reactive behaviour, (N,) bool."""
        return self.active >= 0
