"""The drift ē of the threshold rules: healthy robots' y_m offsets on fault-free runs of a
scenario, at the start, settled and after a re-plan."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..core.events import Kind
from ..errors import ScenarioError

REPLAN_WINDOW = 5.0  # s after an exclusion that count as the re-plan's transient


@dataclass(frozen=True)
class Drift:
    """A robot's drift y_k = x_k − ∫u_k in a mission, split as the threshold rules assume.

    ``drift_bound`` ē: the largest offset ‖D_k − S_k‖ left when the drift D_k(t) = y_k(t) −
    y_k(0) is followed by a slow part S_k that moves at most h ξ̄ per period (the greedy
    split: S_k steps towards D_k by at most h ξ̄). Compensation and actuator lag make the
    drift jitter and jump; those parts are bounded offsets, not drift (docs/thresholds.md).
    """

    scenario: str
    runs: int
    xi_bar: float
    startup: float  # ē over every robot, run and instant, the start-up included [m]
    drift_bound: float  # ē from ``settle`` s on [m]
    settle: float  # the start-up, the scenario's mission.transient [s]
    period_max: float  # largest per-period drift ‖w‖ / h [m/s], for comparison
    # ē of the robots that stayed healthy within REPLAN_WINDOW s after an exclusion (a run
    # with the scenario's stop faults, or a stop of robot 1): the re-plan's transient [m]
    replan: float | None = None
    replan_runs: int = 0
    excluded: int = 0  # exclusions seen in those runs


def split_drift(D: np.ndarray, step: float) -> np.ndarray:
    """‖D − S‖ (T,) for the greedy slow part S of drifts D (T, 2): S(0) = D(0) and S steps
    towards D by at most ``step`` per sample."""
    out = np.empty(len(D))
    s = D[0].copy()
    for t in range(len(D)):
        gap = D[t] - s
        norm = float(np.hypot(gap[0], gap[1]))
        if norm > step:
            s += gap * (step / norm)
        else:
            s[:] = D[t]
        out[t] = float(np.hypot(*(D[t] - s)))
    return out


def drift(
    name: str, scenario_name: str = "paper_case", overrides: dict | None = None, runs: int = 3
) -> Drift:
    """Run the scenario fault-free, noise at its bounds, with robot ``name`` (``runs`` seeds,
    every control period logged) and measure each robot's drift split (:class:`Drift`)."""
    from ..closed_loop.loop import simulate
    from ..scenario import apply_overrides, from_dict, load_scenario

    base = {
        **(overrides or {}),
        "team.robot_model": name,
        "faults": [],
        "noise.at_bound": True,
        "physics.matrix_log_rate": 0.1,
    }
    s0 = load_scenario(scenario_name, base)
    h = s0.physics.control_period
    # the runs below vary the scenario as read (a mission.scale applied once: the fault
    # times taken from it are already scaled)
    resolved = s0.to_dict()
    base = {"physics.log_rate": 1.0 / h}

    def load(extra: dict[str, Any]) -> Any:
        return from_dict(apply_overrides(resolved, {**base, **extra}, where=s0.source), s0.source)

    worst = after = per_period = 0.0
    xi_bar = 0.0
    for seed in range(1, runs + 1):
        s = load({"seed": seed})
        r = simulate(s)
        if not r.ok:
            raise ScenarioError(f"{s.source}: the run for the drift failed: {r.error}")
        xi_bar = float(r.summary["xi_bar"])
        off, d = _offsets(r.log, h, xi_bar)
        late = r.log["t"] >= s.mission.transient
        worst = max(worst, float(off.max()))
        after = max(after, float(off[late].max()) if late.any() else 0.0)
        per_period = max(per_period, float(np.linalg.norm(np.diff(d, axis=0), axis=2).max()) / h)
    # the re-plan: the scenario's stops (else robot 1 stopped at 60 % of the mission), the
    # drift of every robot that never had a fault, from each exclusion on
    stops: list[dict[str, Any]] = [
        {"robot": f.robot + 1, "kind": "stop", "t": f.t} for f in s0.faults if f.kind == "stop"
    ] or [{"robot": 1, "kind": "stop", "t": round(0.6 * s0.duration, 2)}]
    replan, excluded = 0.0, 0
    for seed in range(1, runs + 1):
        s = load({"faults": stops, "seed": seed})
        r = simulate(s)
        if not r.ok:
            raise ScenarioError(f"{s.source}: the run for the re-plan failed: {r.error}")
        t = r.log["t"]
        gone = r.events.of_kind(Kind.EXCLUSION)
        faulty = {int(f["robot"]) - 1 for f in stops}
        healthy = np.array(sorted(set(range(r.log["x"].shape[1])) - faulty), dtype=int)
        if not gone or not len(healthy):
            continue
        excluded += len(gone)
        off, _ = _offsets(r.log, h, xi_bar)
        window = np.zeros(len(t), bool)
        for e in gone:
            window |= (t >= e["t"]) & (t <= e["t"] + REPLAN_WINDOW)
        if window.any():
            replan = max(replan, float(off[np.ix_(window, healthy)].max()))
    return Drift(
        scenario_name,
        runs,
        xi_bar,
        worst,
        after,
        s0.mission.transient,
        per_period,
        replan=replan if excluded else None,
        replan_runs=runs,
        excluded=excluded,
    )


def _offsets(log: dict, h: float, xi_bar: float) -> tuple[np.ndarray, np.ndarray]:
    """Every robot's drift D_k(t) = y_k(t) − y_k(0), y_k = x_k − ∫u_k (eq. 20), (T, N, 2),
    and its offset ‖D_k − S_k‖ (T, N) after the greedy split at h ξ̄ per period."""
    x, u = log["x"], log["u"]
    integral = np.concatenate([np.zeros((1, *u.shape[1:])), np.cumsum(h * u[:-1], axis=0)])
    y = x - integral
    d = y - y[0]
    off = np.stack([split_drift(d[:, k], h * xi_bar) for k in range(d.shape[1])], axis=1)
    return off, d
