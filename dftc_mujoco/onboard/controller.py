"""Global mission controller on each robot's estimate (eqs. 14-16)."""

from __future__ import annotations

import numpy as np


def collective_input(
    x_hat: np.ndarray, x_d: np.ndarray, xd_dot: np.ndarray, kc: float, out: np.ndarray | None = None
) -> np.ndarray:
    """ⁱû_g = J⁻¹[σ̇_d + k_c(σ_d − J ⁱx̂)] for every robot i (eq. 15), shape (N, N, n).

    With J square and invertible (NOTES 11) this equals ẋ_d + k_c(x_d − ⁱx̂),
    where x_d = J⁻¹σ_d are the desired positions (computed once per step by
    the mission, which every robot knows).
    """
    out = np.subtract(x_d[None], x_hat, out=out)
    out *= kc
    out += xd_dot[None]
    return out


def own_input(u_hat_g: np.ndarray) -> np.ndarray:
    """u_g,i = Γᵢ ⁱû_g: robot i takes its own block of its estimate (eq. 16), shape (N, n)."""
    idx = np.arange(u_hat_g.shape[0])
    return u_hat_g[idx, idx]
