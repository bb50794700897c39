"""T_s: the instant from which every threshold ⁱμ_k(t) stays within a tolerance of its
steady value, the domain of eq. 46's guarantee (a fault before it may be flagged later
than Δt_d,max, or never)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numba import njit


@njit(cache=True)
def _within(mu, limit, finite):  # pragma: no cover - compiled
    """Whether mu ≤ limit wherever ``finite`` (a NaN is not), entry by entry, stopping at
    the first that is not (no temporaries: numpy's masks cost 3 ms per instant at N = 1000)."""
    for i in range(mu.shape[0]):
        for k in range(mu.shape[1]):
            if finite[i, k] and not mu[i, k] <= limit[i, k]:
                return False
    return True


def settle_time(
    mu: Callable[[float], np.ndarray], dt: float, horizon: float, tolerance: float = 0.1
) -> float:
    """T_s of the rule whose thresholds at t are ``mu(t)``, sampled on a geometric grid of
    at most 96 instants (multiples of the control period ``dt``) up to ``horizon`` [s]: the first
    instant from which every later one has every finite threshold within ``tolerance`` of
    its value at t = 1e9 s; inf if the last one has not."""
    steady = np.asarray(mu(1e9), dtype=float)
    finite = np.isfinite(steady)
    if not finite.any():
        return float("inf")
    limit = steady * (1 + tolerance) + 1e-12  # now: mu's array is valid until its next call
    grid = np.unique(np.round(np.geomspace(dt, max(horizon, dt), 96) / dt) * dt)
    settled = float("inf")
    for t in grid[::-1]:  # the last instant that is still outside, from the end
        if _within(np.asarray(mu(float(t)), dtype=float), limit, finite):
            settled = float(t)
        else:
            break
    return settled
