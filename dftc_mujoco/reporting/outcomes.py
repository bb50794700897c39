"""What a run achieved, as a user judges it: the mission's outcome and each fault's.

Both are read from the raw log and the events after the run (:func:`~.results.summarize`
puts them in ``summary.json``; campaigns copy them into their rows):

* :func:`mission_outcome`: the robots without a fault, how far they were from their slots;
  the survivors (the robots still in the team at the end), how far their centroid was from
  the path and whether they ended in formation within :func:`tolerance`. Unlike the task
  errors of eqs. 9-12, these do not change when a robot leaves the count: a team that
  excludes its stopped robot and re-forms completes its mission; one that keeps dragging
  it along does not.
* :func:`fault_outcomes`: one outcome per fault: ``excluded`` (flagged by a teammate and
  excluded), ``detected`` (flagged by a teammate, still in the team at the end),
  ``compensated`` (flagged by no teammate while the robot stayed within the tolerance of its
  slot), ``missed`` (flagged by no teammate while the robot left its slot by more than the
  tolerance) or ``undecided`` (neither flagged nor off its slot, with less than
  :data:`JUDGED_AFTER` s of the run left to tell).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..core.events import Event, Kind
from ..core.mission import Formation, slot_spacing
from ..core.record import Events

#: the survivors are in formation when every one is within this share of the slots' spacing
TOLERANCE_SHARE = 0.1
#: [m] the tolerance is at least this (a formation of very close slots)
TOLERANCE_FLOOR = 0.02
#: [s] a fault is judged from this long after its onset: a compensated bias settles first
#: (results.SETTLE), a stop is flagged within a few seconds (Δt_d,max is 5 s on paper_case)
JUDGED_AFTER = 5.0


def tolerance(formation: Formation, robots: int) -> float:
    """[m] how far from its slot a robot may end and the mission still count as completed:
    :data:`TOLERANCE_SHARE` of the slots' spacing, at least :data:`TOLERANCE_FLOOR`."""
    spacing = slot_spacing(formation, robots)
    return max(TOLERANCE_SHARE * spacing, TOLERANCE_FLOOR) if np.isfinite(spacing) else 0.05


def _slot_error(log: dict[str, np.ndarray]) -> np.ndarray:
    """(T, N) each robot's distance from its desired slot (NaN where not logged)."""
    d = log["x"] - log["x_d"]
    return np.sqrt(np.einsum("tnk,tnk->tn", d, d))


def mission_outcome(
    log: dict[str, np.ndarray], faulty: set[int], tol: float, transient: float, finished: bool
) -> dict[str, Any]:
    """The mission's outcome: ``faulty`` are the 0-based robots that had a fault; ``tol`` the
    formation tolerance [m]; ``finished``: the run reached its duration."""
    t = log["t"]
    out: dict[str, Any] = {
        "completed": False,
        "tolerance": tol,
        "survivors": [],
        "healthy_slot_rms": None,
        "final_slot_error": None,
        "final_centroid_error": None,
    }
    if not len(t):
        return out
    err = _slot_error(log)
    active = log["active"].astype(bool)
    healthy = np.array([k not in faulty for k in range(err.shape[1])])
    after = (t >= transient)[:, None] & active & healthy[None, :]
    samples = err[after]
    samples = samples[np.isfinite(samples)]
    if len(samples):
        out["healthy_slot_rms"] = float(np.sqrt(np.mean(samples**2)))
    last = active[-1]
    out["survivors"] = [int(k) + 1 for k in np.flatnonzero(last)]
    if last.any():
        out["final_slot_error"] = float(np.nanmax(err[-1, last]))
        centroid = log["x"][-1, last].mean(axis=0) - log["x_d"][-1, last].mean(axis=0)
        out["final_centroid_error"] = float(np.hypot(*centroid))
        out["completed"] = bool(
            finished
            and last.sum() > 1
            and out["final_slot_error"] <= tol
            and out["final_centroid_error"] <= tol
        )
    return out


def fault_outcomes(
    log: dict[str, np.ndarray], events: Events, tol: float, end: float
) -> list[dict[str, Any]]:
    """One entry per fault (the ``fault`` events, robots from 1): its outcome (module
    docstring), the first teammate's flag and who flagged it, its exclusion, and the largest
    slot error of its robot from :data:`JUDGED_AFTER` s after the onset on (not while it
    avoids an obstacle, nor in the :data:`JUDGED_AFTER` s after an exclusion re-forms the
    team)."""
    faults = events.of_kind(Kind.FAULT)
    exclusions = events.of_kind(Kind.EXCLUSION)
    flagged: dict[int, list[Event]] = {}  # a large run holds 10⁵ detections
    for d in events.of_kind(Kind.DETECTION):
        flagged.setdefault(d["robot"], []).append(d)
    t = log["t"]
    err = _slot_error(log) if len(t) else np.zeros((0, 0))
    out = []
    for j, f in enumerate(faults):
        r, onset = f["robot"], f["t"]
        later = [g["t"] for g in faults[j + 1 :] if g["robot"] == r]
        until = min(later) if later else np.inf
        flags = [d for d in flagged.get(r, []) if d["by"] != r and onset <= d["t"] < until]
        gone = [e["t"] for e in exclusions if e["robot"] == r and e["t"] >= onset]
        # judged on its own: not while it avoids an obstacle, nor while the team re-forms
        window = (t >= onset + JUDGED_AFTER) & (t < until) & ~log["reactive"][:, r - 1]
        for e in exclusions:
            window &= (t < e["t"]) | (t >= e["t"] + JUDGED_AFTER)
        if gone:
            window &= t <= gone[0]
        worst = err[window, r - 1] if len(t) else np.zeros(0)
        worst = worst[np.isfinite(worst)]
        off = float(worst.max()) if len(worst) else None
        if gone and flags:
            outcome = "excluded"
        elif flags:
            outcome = "detected"
        elif off is not None and off > tol:
            outcome = "missed"
        elif end - onset >= JUDGED_AFTER and off is not None:
            outcome = "compensated"
        else:
            outcome = "undecided"
        out.append(
            {
                "robot": r,
                "kind": f["fault"],
                "t": onset,
                "outcome": outcome,
                "first_flag": min(d["t"] for d in flags) if flags else None,
                "flagged_by": sorted({d["by"] for d in flags}),
                "excluded_at": gone[0] if gone else None,
                "max_slot_error": off,
            }
        )
    return out
