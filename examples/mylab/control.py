"""A saturated Lyapunov-gradient controller, in place of the paper's eq. 15."""

import numpy as np

from dftc_mujoco.blocks import paper


class Lyapunov(paper.Controller):
    """ⁱû_g,k = ẋ_d,k + gain · e_k / √(1 + (gain ‖e_k‖ / v_max)²), e_k = x_d,k − ⁱx̂_k.

    The gradient of a Lyapunov function V = Σ (v_max²/gain) (√(1 + (gain‖e‖/v_max)²) − 1):
    linear (gain) for small errors like eq. 15, but never asking more than
    ``v_max`` m/s on top of the mission's own velocity. Robot i uses only its own
    estimate ⁱx̂ and the mission.
    """

    def __init__(self, gain: float = 2.0, v_max: float = 0.25) -> None:
        self.gain = float(gain)
        self.v_max = float(v_max)

    def collective_input(self, x_hat, x_d, xd_dot):
        e = x_d[None] - x_hat  # (M, M, 2): robot i's error on every robot k
        scale = np.sqrt(
            1.0 + (self.gain * np.linalg.norm(e, axis=2, keepdims=True) / self.v_max) ** 2
        )
        return xd_dot[None] + self.gain * e / scale
