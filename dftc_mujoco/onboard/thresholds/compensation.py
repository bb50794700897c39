"""The compensation's bounds (eqs. 28-31): Φ̄ and the offset it leaves in the drift.

:func:`estimator_gain` bounds ‖φ̂‖ on a healthy robot (the ℓ1 norm of the estimator's
closed loop, with the drive's lag when the robot models one); :func:`compensation_offset`
is the drift offset ‖G‖Φ̄ + 2η̄ the compensation makes (y_m,k − y_m,k(0) = G φ̂_k), which ē
must cover for l1 and block_row."""

from __future__ import annotations

import numpy as np

from ...errors import ScenarioError
from ..applied import distinct_lags, lag_coefficients


def compensation_offset(G: np.ndarray, phi_bar: float, eta_bar: float) -> float:
    """The drift offset the compensation makes on a healthy robot: ‖G‖₂ Φ̄ + 2η̄.

    With the fault estimator (eqs. 29-31) and the observer fed the same input,
    y_m,k(t) − y_m,k(0) = G φ̂_k(t) exactly, so D_k = G φ̂_k − η_k(t) + η_k(0)
    (``docs/thresholds.md``): l1 and block_row take ē at least this large.
    """
    return float(np.linalg.norm(np.asarray(G, float), 2)) * phi_bar + 2.0 * eta_bar


def estimator_gain(
    K: np.ndarray,
    G: np.ndarray,
    h: float,
    eta_bar: float,
    xi_bar: float,
    steps: int = 100000,
    lag: float | np.ndarray = 0.0,
) -> float:
    """Bound of ‖φ̂‖ on a healthy robot (x_m = x + η, mismatch ‖ξ‖ ≤ ξ̄ from its drive model).

    A team whose robots model different lags (``lag`` (N,)) gets the largest of its robots'
    bounds, which holds for each.

    The fault estimator's closed loop (eqs. 28-31 with compensation) is linear in
    the deviation d = x − z and the integral I = ∫e: φ̂ = G⁻¹(d + η + K I),
    d⁺ = d + h(ξ − φ̂ − K(d + η)), I⁺ = I + h(d + η) on an ideal plant (ẋ = ū + ξ). A drive
    with a first-order lag ``lag`` that the robot models (``onboard/applied.py``) delivers
    its command's lagged response: the model cancels the lag of u, but φ̂ reaches the
    plant through the lag too, d⁺ = d + h(ξ − (1 − b)φ̂ − b w − K(d + η)), w⁺ = aφ̂ + (1 − a)w
    (a, b of :func:`~.applied.lag_coefficients`). Returns Σ_t ‖H_η(t)‖₂ η̄ + Σ_t ‖H_ξ(t)‖₂ ξ̄
    (ℓ1 norms of its impulse responses).
    """
    if np.ndim(lag) > 0:
        lags = distinct_lags(lag)
        return max(estimator_gain(K, G, h, eta_bar, xi_bar, steps, tau) for tau in lags)
    lag = float(lag)
    K, G = np.asarray(K, float), np.asarray(G, float)
    gi = np.linalg.inv(G)
    n = len(K)
    eye, zero = np.eye(n), np.zeros((n, n))
    a, b = lag_coefficients(lag, h)
    # state s = [d, I] (and w with a lag); φ̂ = C s + D η
    C = np.hstack([gi, gi @ K])
    D = gi
    Ad = np.block([[eye - h * (1 - b) * gi - h * K, -h * (1 - b) * gi @ K], [h * eye, eye]])
    B_eta = np.vstack([-h * (1 - b) * gi - h * K, h * eye])
    B_xi = np.vstack([h * eye, zero])
    if a > 0.0:
        Ad = np.block(
            [
                [Ad, np.vstack([-h * b * eye, zero])],
                [a * gi, a * gi @ K, (1 - a) * eye],
            ]
        )
        C = np.hstack([C, zero])
        B_eta = np.vstack([B_eta, a * gi])
        B_xi = np.vstack([B_xi, zero])
    if np.abs(np.linalg.eigvals(Ad)).max() >= 1.0:
        raise ScenarioError(
            "gains.G, gains.K: the fault estimator's loop is unstable at this control period"
            + (f" with the drive lag of {lag:g} s" if a > 0 else "")
            + "; its compensation has no bound Φ̄ (raise gains.G)"
        )
    # the states Ad^t B up to the first below 1e-14 (in blocks: the products past it are
    # dropped), then the impulse responses C Ad^t B and their 2-norms in batched calls
    # (numpy's products and SVDs matrix by matrix, as one call a step took: 30x the time)
    se: list[np.ndarray] = []
    sx: list[np.ndarray] = []
    xe, xx = B_eta.copy(), B_xi.copy()
    while len(se) < steps:
        for _ in range(min(64, steps - len(se))):
            se.append(xe)
            sx.append(xx)
            xe, xx = Ad @ xe, Ad @ xx
        size = np.maximum(np.abs(se[-64:]).max(axis=(1, 2)), np.abs(sx[-64:]).max(axis=(1, 2)))
        below = np.flatnonzero(size < 1e-14)  # size[j] is of state len(se) - len(size) + j
        if len(below):
            end = len(se) - len(size) + int(below[0]) + 1
            del se[end:], sx[end:]
            break
    total_eta = float(np.linalg.norm(D, 2))
    for v in np.linalg.norm(C @ np.stack(se), 2, axis=(1, 2)).tolist():  # in time order
        total_eta += v
    total_xi = 0.0
    for v in np.linalg.norm(C @ np.stack(sx), 2, axis=(1, 2)).tolist():
        total_xi += v
    return float(total_eta * eta_bar + total_xi * xi_bar)
