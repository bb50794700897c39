"""What the threshold rules assume, checked before a run and monitored during it.

Every rule of ``docs/thresholds.md`` is a bound *under premises*: measurement noise
within η̄, a drift of y_k within what ξ̄ and ē allow, a start within the initial-error
bound ε̄, a planar robot on a strongly connected graph, inputs that the robot really
applied. This module holds those premises in one place:

* before the run, :func:`initial_error_bound` derives ε̄ from the scenario itself (the
  start positions against the planned slots, in the rule's own meaning) and refuses a
  stated bound below it; :func:`rule_refusals` refuses configurations outside a rule's
  premises;
* during the run, :class:`Monitor` compares what the simulator knows (the true noise,
  the true positions and velocities, contacts, heights, the current graph) with those
  premises every control period, records each span of a violated premise as a
  ``premise_violated`` event and says, for any instant, which premises were violated
  then (so that every flag is labelled).

It never holds a control law and the onboard blocks never import it: the robots do not
know the truth, the simulator does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: the premises, in the order the tables print them, with a one-line meaning each
PREMISES: dict[str, str] = {
    "noise": "‖η_i‖ ≤ η̄ (eq. 4)",
    "mismatch": "‖ẋ_i − applied input‖ ≤ ξ̄ (eq. 2; the applied input after the drive's limits)",
    "initial_error": "every robot starts within ε̄ of its planned slot (initial_error_bound)",
    "saturation": "the nominal input is within the robot's command range (no saturation)",
    "contact": "no contact between a robot and a teammate or a cylinder",
    "planar": "the base stays on the floor, level, inside the arena",
    "connectivity": "the members' graph is strongly connected",
}


@dataclass(frozen=True)
class StartBound:
    """ε̄ of a run: the value the rule uses, the one the scenario implies and where from."""

    value: float  # ε̄ the rule uses [m]
    implied: float  # the least ε̄ the start positions allow [m]
    robot: int  # the robot (0-based) that sets ``implied``
    offset: float  # that robot's distance from its planned slot [m]
    meaning: str  # "robot" or "stacked"
    derived: bool  # True: "auto"


def implied_initial_error(
    x0: np.ndarray, slots: np.ndarray, eta_bar: float, meaning: str
) -> tuple[float, int, float]:
    """The least ε̄ valid for start positions ``x0`` and planned slots ``slots`` (N, 2).

    Every robot starts believing its teammates are at their slots and itself where it
    measures itself (the observer's reset), so with a_k = slot_k − x_k(0):
    "robot" (l1, drive) bounds each ‖a_k‖; "stacked" (eq. 40, block_row) bounds
    ‖ỹ*_k(0)‖ = √((N − 1)‖a_k‖² + ‖η_k(0)‖²) ≤ √((N − 1)‖a_k‖² + η̄²).
    Returns (ε̄, the robot that sets it, its offset ‖a_k‖); ε̄ carries a relative 1e-9
    (and 1 nm) on top of the rounding of the positions.
    """
    a = np.linalg.norm(np.asarray(slots, float) - np.asarray(x0, float), axis=1)
    n = len(a)
    if meaning == "robot":
        need = a
    else:
        need = np.sqrt(max(n - 1, 0) * a**2 + eta_bar**2)
    k = int(np.argmax(need))
    return float(need[k]) * (1 + 1e-9) + 1e-9, k, float(a[k])


def initial_error_bound(
    stated: float | str,
    x0: np.ndarray,
    slots: np.ndarray,
    eta_bar: float,
    meaning: str,
    where: str,
) -> tuple[StartBound, str | None]:
    """ε̄ for the run and, if the stated one is below what the start implies, a refusal."""
    implied, k, off = implied_initial_error(x0, slots, eta_bar, meaning)
    if stated == "auto":
        return StartBound(implied, implied, k, off, meaning, True), None
    value = float(stated)
    bound = StartBound(value, implied, k, off, meaning, False)
    if value >= implied:
        return bound, None
    what = (
        "each robot's start distance from its planned slot"
        if meaning == "robot"
        else "the stacked start error of every observer, √(N − 1) × a robot's offset"
    )
    return bound, (
        f"{where}: fdir.initial_error_bound = {value:g} m is smaller than the {implied:.4g} m "
        f"this scenario implies (robot {k + 1} starts {off:.4g} m from its planned slot; the "
        f"rule bounds {what}); set it to at least {math.ceil(implied * 1000) / 1000:g} or "
        '"auto"'
    )


def rule_refusals(rule: str, compensate: bool, low_pass: float, where: str) -> list[str]:
    """Configurations outside a built-in rule's premises, one line each."""
    out = []
    if rule == "drive" and not compensate:
        out.append(
            f'{where}: onboard.thresholds = "drive" needs fdir.compensate = true (it bounds '
            "y_m,k − y_m,k(0) = G φ̂_k, which holds only while φ̂ is applied; without it ∫e "
            'winds up and no Φ̄ exists); use "l1" or "block_row"'
        )
    if rule == "drive" and low_pass > 0:
        out.append(
            f'{where}: onboard.thresholds = "drive" needs fdir.phi_low_pass = 0 (a filtered '
            "compensation breaks the identity y_m,k − y_m,k(0) = G φ̂_k it rests on)"
        )
    return out
