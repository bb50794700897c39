"""Global mission controller on each robot's estimate (eqs. 14-16).

The equations are the compiled :func:`collective_input` and :func:`own_input`;
:class:`Controller` is the block that calls them.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .block import Block, TeamConfig


@njit(inline="always")
def collective_one(vd, kc, xd, xh):  # pragma: no cover - compiled
    """One entry of ⁱû_g = ẋ_d + k_c(x_d − ⁱx̂) (eq. 15 with J square, docs/notes.md, 11)."""
    return vd + kc * (xd - xh)


@njit(cache=True)
def collective_input(x_hat, x_d, xd_dot, kc, out):  # pragma: no cover - compiled
    """ⁱû_g = J⁻¹[σ̇_d + k_c(σ_d − J ⁱx̂)] for every robot i (eq. 15), into ``out`` (M, M, n).

    With J square and invertible (docs/notes.md, 11) this is ẋ_d + k_c(x_d − ⁱx̂), where
    x_d = J⁻¹σ_d are the desired positions (the mission, which every robot knows).
    """
    m, _, n = x_hat.shape
    xd, vd = x_d.reshape(-1), xd_dot.reshape(-1)
    xh, o = x_hat.reshape(m, m * n), out.reshape(m, m * n)
    for i in range(m):
        for a in range(m * n):
            o[i, a] = collective_one(vd[a], kc, xd[a], xh[i, a])


@njit(cache=True)
def own_input(u_hat_g, out):  # pragma: no cover - compiled
    """u_g,i = Γᵢ ⁱû_g: robot i takes its own block of its estimate (eq. 16), into ``out``."""
    for i in range(u_hat_g.shape[0]):
        for d in range(u_hat_g.shape[2]):
            out[i, d] = u_hat_g[i, i, d]


class ControllerRecord(NamedTuple):
    """What the compiled period (:mod:`.period`) reads of the controller."""

    kc: float


class Controller(Block):
    """The paper's centroid + formation controller (eqs. 15-16) on every robot.

    Override :meth:`collective_input` (and, rarely, :meth:`own_input`) to try
    another control law. Robot i's row may use only its own estimate ⁱx̂ and
    the mission (x_d, ẋ_d), which every robot knows.
    """

    kind = "controller"

    def reset(self, config: TeamConfig, x_m0: np.ndarray, prior: np.ndarray) -> None:
        """Read the gain k_c."""
        self.kc = config.kc

    def record(self) -> ControllerRecord:
        """The gain the compiled period uses."""
        return ControllerRecord(self.kc)

    def collective_input(
        self, x_hat: np.ndarray, x_d: np.ndarray, xd_dot: np.ndarray
    ) -> np.ndarray:
        """ⁱû_g (M, M, n) of eq. 15 from the estimates ⁱx̂ (M, M, n), x_d (M, n) and ẋ_d (M, n)."""
        out = np.empty(x_hat.shape)
        collective_input(
            np.ascontiguousarray(x_hat, float),
            np.ascontiguousarray(x_d, float),
            np.ascontiguousarray(xd_dot, float),
            self.kc,
            out,
        )
        return out

    def own_input(self, u_hat_g: np.ndarray) -> np.ndarray:
        """u_g,i (M, n): robot i's own block of ⁱû_g (eq. 16)."""
        out = np.empty((u_hat_g.shape[0], u_hat_g.shape[2]))
        own_input(np.ascontiguousarray(u_hat_g, float), out)
        return out
