"""The input a robot applies: its nominal input after its own drive's limits (Remark 4.1).

Eq. 21 builds y_m,i = x_m,i − ∫uᵢ from "the real input" of robot i, eq. 22 builds Δuᵢ
from it and the local observer of eq. 29 is driven by it. A drive delivers at most its
command range, so a nominal input of eq. 8 beyond that range is not what the robot
applies: integrated as if it were, the difference reads as a fault (a 100-robot team
started metres from its slots asks for 55 m/s at t = 0 from a 1 m/s drive, and every
robot flags every other one). Here each robot saturates its own nominal input, per axis,
at the part of its range that the compensation of eq. 28 leaves free
(``TeamConfig.input_limit``), and that saturated input is uᵢ everywhere after the
supervisor: in y_m, in Δuᵢ = uᵢ − u_g,i and in the fault estimator. ``fdir.input =
"nominal"`` keeps the unsaturated input (``input_limit`` = inf): the paper's equations
read literally, valid only while no command leaves the range.
"""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def limit_input(u, u_g, delta_u, limit):  # pragma: no cover - compiled
    """Saturate the nominal inputs ``u`` (M, n) per axis at ±``limit`` in place and set
    Δuᵢ = uᵢ − u_g,i (eq. 22) for the saturated input; returns the number of robots whose
    input was saturated."""
    hit = 0
    for i in range(u.shape[0]):
        if max(abs(u[i, 0]), abs(u[i, 1])) <= limit:
            continue  # within range: u and Δu as the supervisor made them
        hit += 1
        for d in range(u.shape[1]):
            u[i, d] = min(max(u[i, d], -limit), limit)
            delta_u[i, d] = u[i, d] - u_g[i, d]
    return hit
