"""What a run leaves, and everything derived from its raw log after the run.

The loop records raw samples (positions, estimates, inputs, residuals,
thresholds, commands) and events; the summary's margins, obstacle
clearances, reactive spans, fault-estimate errors and task errors are
computed here from those records, so the hot loop does none of it. A saved
run (``summary.json``, ``log.npz``, ``scenario.toml``) is read back by
:func:`open_run`.
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit

from ..core.events import Kind, loaded, split_text
from ..core.mission import slot_spacing
from ..core.record import LOG_FIELDS, Events, matrix_rows, write_json, write_npz, write_text
from ..errors import ScenarioError, SimulationError
from . import outcomes

if TYPE_CHECKING:
    from ..scenario import Scenario

SETTLE = 5.0  # s after a bias fault before its compensation is judged settled


@dataclass
class RunResult:
    """What a run leaves: the log, the events, the summary, and the error if it failed.

    Events number robots from 1, like ``summary.json`` and the campaign tables.
    """

    scenario: Scenario
    log: dict[str, np.ndarray]
    events: Events
    summary: dict[str, Any]
    error: SimulationError | None = None
    extras: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """True when the physics ran to the end without trouble."""
        return self.error is None

    def save(
        self, out: str | Path, *, figures: bool = True, video: bool = False, overwrite: bool = False
    ) -> Path:
        """Write what ``python -m dftc_mujoco.run`` writes into the run folder ``out``.

        ``log.npz``, ``scenario.toml`` and ``summary.json``, the paper's figures in
        ``figures/`` unless ``figures`` is False, and ``video.mp4`` (640x480 at 30 fps,
        offscreen through the GL backend chosen when dftc_mujoco was imported) if ``video``,
        all written into a private folder that replaces ``out`` as a whole at the end: a
        folder that holds another run is replaced only with ``overwrite`` (never mixed
        with this one's files), a folder that holds no run is never replaced
        (OutputError). Returns ``out``.
        """
        from ..runtime.output import run_folder

        with run_folder(Path(out), overwrite) as work:
            self.write(work, figures=figures, video=video)
        return Path(out)

    def write(self, folder: Path, *, figures: bool = True, video: bool = False) -> None:
        """Write the run's files into ``folder`` as they are (``summary.json`` after the
        records it describes, each file atomically); :meth:`save` is the safe way."""
        write_npz(folder / "log.npz", self.log)
        write_text(folder / "scenario.toml", self.scenario.to_toml())
        write_json(folder / "summary.json", self.summary)
        if figures:
            from ..render import figures as figures_mod

            figures_mod.draw_all(self.log, self.summary, folder / "figures")
        if video:
            from ..render.video import write_video

            write_video(folder / "video.mp4", self.scenario, self.log, self.summary)

    def figures(self) -> dict[str, Any]:
        """The paper's figures of this run as matplotlib Figures, by name (nothing saved)."""
        from ..render import figures

        return figures.make_all(self.log, self.summary)


def open_run(folder: str | Path) -> RunResult:
    """Read a saved run folder (``summary.json``, ``log.npz``, ``scenario.toml``).

    Raises ScenarioError naming the file when something is missing or unreadable.
    """
    from ..scenario import from_dict

    folder = Path(folder)
    files = {name: folder / name for name in ("summary.json", "log.npz", "scenario.toml")}
    for path in files.values():
        if not path.is_file():
            raise ScenarioError(f"{path}: missing: {folder} is not a complete run folder")
    try:
        summary = json.loads(files["summary.json"].read_text())
    except (OSError, ValueError) as exc:
        raise ScenarioError(f"{files['summary.json']}: unreadable: {_one_line(exc)}") from None
    if not isinstance(summary, dict) or not isinstance(summary.get("events", []), list):
        raise ScenarioError(f"{files['summary.json']}: not a run summary (a JSON object)")
    for k, e in enumerate(summary.get("events", [])):  # an integer was a TypeError
        if not (
            isinstance(e, dict)
            and isinstance(e.get("kind"), str)
            and isinstance(e.get("t"), int | float)
            and not isinstance(e.get("t"), bool)
        ):
            raise ScenarioError(
                f"{files['summary.json']}: events[{k + 1}]: expected an event (an object with "
                f'a number "t" and a string "kind"), got {str(json.dumps(e))[:60]}'
            )
    log = _read_log(files["log.npz"])
    try:
        data = tomllib.loads(files["scenario.toml"].read_text())
    except (OSError, ValueError, RecursionError) as exc:
        raise ScenarioError(f"{files['scenario.toml']}: unreadable: {_one_line(exc)}") from None
    scenario = from_dict(data, source=str(files["scenario.toml"]))
    events = Events([loaded(e) for e in summary.get("events", [])])
    failed = summary.get("status") == "failed"
    error = SimulationError(str(summary.get("error") or "failed")) if failed else None
    return RunResult(scenario, log, events, summary, error)


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def _read_log(path: Path) -> dict[str, np.ndarray]:
    """Every array of a saved ``log.npz``; a ScenarioError (one line) when the file is
    truncated, corrupt or lacks a field the figures need."""
    try:
        with np.load(path, allow_pickle=False) as npz:
            log = {k: npz[k] for k in npz.files}
    except Exception as exc:  # zipfile, zlib and numpy each raise their own kind
        raise ScenarioError(
            f"{path}: unreadable ({type(exc).__name__}: {_one_line(exc)}); the file is "
            "truncated or corrupt: run the scenario again"
        ) from None
    missing = [k for k in LOG_FIELDS if k not in log]
    if missing:
        raise ScenarioError(f"{path}: not a run log: missing {', '.join(missing)}")
    odd = [k for k, a in log.items() if a.dtype.kind not in "biuf"]
    if odd:
        k = odd[0]
        raise ScenarioError(
            f"{path}: not a run log: field {k!r} holds {log[k].dtype.name} values, expected numbers"
        )
    t = log["t"]
    if t.ndim != 1 or any(len(log[k]) != len(t) for k in ("x", "u", "pose")):
        raise ScenarioError(f"{path}: not a run log: its arrays do not have one row per time")
    return log


# --------------------------------------------------------------------------- derived values


def _rms(a: np.ndarray) -> float | None:
    a = a[np.isfinite(a)]
    return float(np.sqrt(np.mean(a**2))) if len(a) else None


def _finite_or_none(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def fault_masks(s: Scenario, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per logged instant (T, N): robots still healthy, and biased robots whose
    compensation has settled; plus which robots have only bias faults (N,)."""
    n = s.team.robots
    start = np.full(n, np.inf)
    bias_only = np.ones(n, bool)
    for f in s.faults:
        start[f.robot] = min(start[f.robot], f.t)
        bias_only[f.robot] &= f.kind == "bias"
    healthy = start[None, :] > t[:, None]
    settled = bias_only[None, :] & (start[None, :] + SETTLE <= t[:, None])
    return healthy, settled, bias_only & np.isfinite(start)


def estimation_errors(log: dict[str, np.ndarray], transient: float) -> dict[str, Any]:
    """How far the team's estimates are from the world: for every robot k, the RMS over the
    logged samples after ``transient`` and over its teammates i of ‖ⁱx̂_k − x_k‖ (its true
    position), and the largest. A controller whose estimates agree with each other but not
    with the robots shows here, not in the residuals."""
    rows = matrix_rows(log)
    x_hat, x, t = log["x_hat"], log["x"], log["t"]
    n = x.shape[1] if x.ndim == 3 else 0
    keep = [j for j, r in enumerate(rows) if r < len(t) and t[r] >= transient]
    if not keep or n == 0:
        return {"per_robot_rms": [None] * n, "max": None}
    total, count = np.zeros(n), np.zeros(n)
    worst = _estimate_sums(x_hat, x, rows, np.array(keep, dtype=np.int64), total, count)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt(total / count)
    return {
        "per_robot_rms": [_finite_or_none(v) for v in rms],
        "max": _finite_or_none(worst),
    }


@njit(cache=True)
def _estimate_sums(x_hat, x, rows, keep, total, count):  # pragma: no cover - compiled
    """For the samples ``keep`` of the N × N log, add Σ_i ‖ⁱx̂_k − x_k‖² over the teammates i
    whose error is finite into ``total[k]`` and their number into ``count[k]``, sample by
    sample (a sample's sum first, then into the total); returns the largest error (NaN
    aside) of the samples with a finite one, 0 if none. The numbers of the N × N arrays
    numpy made before, one sample at a time, without them."""
    n = total.shape[0]
    part = np.empty(n)
    worst = 0.0
    for j in keep:
        xr = x[rows[j]]
        part[:] = 0.0
        top, finite = -np.inf, False
        for i in range(n):
            for k in range(n):
                if i == k:
                    continue  # a robot's estimate of itself is its own measurement
                d0 = np.float64(x_hat[j, i, k, 0]) - xr[k, 0]
                d1 = np.float64(x_hat[j, i, k, 1]) - xr[k, 1]
                e = np.sqrt(d0 * d0 + d1 * d1)
                if not np.isnan(e):
                    top = max(top, e)
                if np.isfinite(e):
                    part[k] += e * e
                    count[k] += 1.0
                    finite = True
        for k in range(n):
            total[k] += part[k]
        if finite:
            worst = max(worst, top)
    return worst


def peak_ratio(residual: np.ndarray, threshold: np.ndarray, columns: np.ndarray) -> float:
    """max ‖ⁱr_k‖ / ⁱμ_k over samples and observers i, for the robots k selected per sample
    by ``columns`` (T, N); 0 when none is selected. Excluded robots (NaN) are skipped."""
    return _peak_ratio(residual, threshold, np.ascontiguousarray(columns, dtype=bool))


@njit(cache=True)
def _peak_ratio(residual, threshold, columns):  # pragma: no cover - compiled
    """:func:`peak_ratio`, entry by entry (the ratios in float64, finite ones only)."""
    best = 0.0
    for a in range(min(residual.shape[0], columns.shape[0])):
        for i in range(residual.shape[1]):
            for k in range(residual.shape[2]):
                if columns[a, k]:
                    r = np.float64(residual[a, i, k]) / np.float64(threshold[a, i, k])
                    if np.isfinite(r) and r > best:
                        best = r
    return best


def reactive_spans(events: Events) -> list[dict[str, Any]]:
    """Obstacle-avoidance spans per robot (1-based), from the reactive events."""
    on: dict[int, float] = {}
    spans = []
    for e in events.items:
        if e["kind"] == Kind.REACTIVE_ON:
            on[e["robot"]] = e["t"]
        elif e["kind"] == Kind.REACTIVE_OFF and e["robot"] in on:
            spans.append({"robot": e["robot"], "t_on": on.pop(e["robot"]), "t_off": e["t"]})
    spans += [{"robot": r, "t_on": t, "t_off": None} for r, t in on.items()]
    return sorted(spans, key=lambda r: (r["t_on"], r["robot"]))


def fault_estimates(s: Scenario, log: dict[str, np.ndarray], events: Events) -> list[dict]:
    """Error of φ̂ against the injected φ per robot with bias faults, once settled.

    A bias is judged from its start + :data:`SETTLE` to the next fault, exclusion or
    physics error (of any robot); a robot with several biases gets one entry over the
    union of their windows (its φ is their sum), with every bias's start in
    ``faults`` and each window in ``windows``.
    """
    t = log["t"]
    marks = sorted(
        {
            e["t"]
            for e in events.items
            if e["kind"] in (Kind.FAULT, Kind.EXCLUSION, Kind.SIMULATION_ERROR)
        }
    )
    end_of_log = t[-1] + 1e-9 if len(t) else 0.0
    by_robot: dict[int, list[float]] = {}
    for f in s.faults:
        if f.kind == "bias":
            by_robot.setdefault(f.robot, []).append(float(f.t))
    rows = []
    for robot, starts in sorted(by_robot.items()):
        win = np.zeros(len(t), bool)
        windows = []
        for t_f in sorted(set(starts)):
            end = min([m for m in marks if m > t_f] + [end_of_log])
            this = (t >= t_f + SETTLE) & (t < end)
            if this.sum() >= 2:
                win |= this
                windows.append([t_f + SETTLE, float(t[this][-1])])
        if win.sum() < 2:
            continue
        err = log["phi_hat"][win, robot] - log["phi"][win, robot]
        rows.append(
            {
                "robot": robot + 1,
                "t": min(starts),
                "faults": sorted(starts),
                "window": [windows[0][0], windows[-1][1]],
                "windows": windows,
                "mean_error": np.abs(err.mean(axis=0)).tolist(),
                "rms_error": np.sqrt((err**2).mean(axis=0)).tolist(),
            }
        )
    return rows


def obstacle_clearance(
    log: dict[str, np.ndarray], footprint: float, safe: np.ndarray
) -> tuple[float, float]:
    """Smallest hull-to-cylinder gap and smallest distance beyond d over the logged samples."""
    obs = log["obstacles"]
    x = log["x"]
    if not len(obs) or not len(x):
        return math.inf, math.inf
    rel = x[:, :, None, :] - obs[None, None, :, :2]
    dist = np.sqrt(np.einsum("tnok,tnok->tno", rel, rel))
    gap = float(np.nanmin(dist - (obs[:, 2] + footprint)))
    margin = float(np.nanmin(dist - safe))
    return gap, margin


def summarize(
    s: Scenario,
    log: dict[str, np.ndarray],
    events: Events,
    *,
    xi_bar: float,
    footprint: float,
    obstacle_safe: np.ndarray,
    wall: float,
    error: SimulationError | None,
    sim_time: float,
    finished: bool = True,
    ended: str | None = None,
    stopped: str | None = None,
) -> dict[str, Any]:
    """The ``summary.json`` contract (robots numbered from 1), from the raw records."""
    t = log["t"]
    window = t >= s.mission.transient
    err = log["sigma_err"]
    last = err[-1] if len(err) else (math.nan, math.nan)
    # the time the physics reached, not the last logged row: with a slow log rate
    # (physics.log_rate = 0.001) the last row can be t = 0
    simulated = round(float(sim_time), 9)
    gap, margin_d = obstacle_clearance(log, footprint, obstacle_safe)
    status = "ok" if error is None else "failed"
    if error is None and stopped and not finished:
        status = "interrupted"  # stopped on request (a signal): the records so far
        ended = stopped
    elif error is None and ended:
        status = "ended"  # the mission ended early: the team fell apart
    elif error is None and not finished:
        status = "incomplete"
    summary: dict[str, Any] = {
        "scenario": s.name,
        "seed": s.seed,
        "duration": s.duration,
        "robots": s.team.robots,
        "robot_model": s.team.robot_model,
        "status": status,
        "error": None if error is None else str(error),
        "end_reason": ended,
        "simulated_time": simulated,
        "wall_time": wall,
        "real_time_factor": (simulated / wall) if wall > 0 else None,
        "faults": [
            {"robot": e["robot"], "kind": e["fault"], "t": e["t"]}
            for e in events.of_kind(Kind.FAULT)
        ],
        "reactive": reactive_spans(events),
        "detections": [
            {"by": e["by"], "robot": e["robot"], "t": e["t"], "premises": e.get("premises", [])}
            for e in events.of_kind(Kind.DETECTION)
        ],
        "exclusions": [{"robot": e["robot"], "t": e["t"]} for e in events.of_kind(Kind.EXCLUSION)],
        "errors": {
            "window": [s.mission.transient, simulated],
            "centroid_rms": _rms(err[window, 0]),
            "formation_rms": _rms(err[window, 1]),
            "final_centroid": _finite_or_none(last[0]),
            "final_formation": _finite_or_none(last[1]),
        },
        "xi_bar": xi_bar,
        "xi_bar_source": "scenario" if s.noise.xi_bar is not None else "robot model",
        "warnings": _warnings(events),
        "min_obstacle_clearance": _finite_or_none(gap),
        "min_safe_distance_margin": _finite_or_none(margin_d),
    }
    summary["estimation_error"] = estimation_errors(log, s.mission.transient)
    summary["warnings"] += _estimates_off(s, summary["estimation_error"], events, simulated)
    if s.fdir.enabled:
        healthy, settled, biased = fault_masks(s, t[matrix_rows(log)])
        summary["margin"] = peak_ratio(log["residual"], log["threshold"], healthy)
        summary["margin_compensated"] = (
            peak_ratio(log["residual"], log["threshold"], settled) if biased.any() else None
        )
        summary["fault_estimates"] = fault_estimates(s, log, events)
    onset = fault_onsets(events)
    healthy_flags = [d for d in summary["detections"] if _healthy_at(onset, d["robot"], d["t"])]
    summary["healthy_flags"] = len(healthy_flags)
    summary["healthy_flags_premises_held"] = sum(1 for d in healthy_flags if not d["premises"])
    by_premise: dict[str, int] = {}  # each flag counted once under every premise it violated
    for d in healthy_flags:
        for p in d["premises"]:
            by_premise[p] = by_premise.get(p, 0) + 1
    summary["healthy_flags_by_premise"] = dict(sorted(by_premise.items()))
    summary["healthy_exclusions"] = sum(
        1 for e in events.of_kind(Kind.EXCLUSION) if _healthy_at(onset, e["robot"], e["t"])
    )
    summary["systemic_anomalies"] = len(events.of_kind(Kind.SYSTEMIC_ANOMALY))
    tol = outcomes.tolerance(s.mission.formation, s.team.robots)
    faulty = {r - 1 for r in onset}
    summary["mission"] = outcomes.mission_outcome(
        log, faulty, tol, s.mission.transient, status == "ok" and finished
    )
    summary["fault_outcomes"] = outcomes.fault_outcomes(log, events, tol, simulated)
    summary["events"] = events.ordered()
    return summary


def _estimates_off(s: Scenario, found: dict[str, Any], events: Events, end: float) -> list[str]:
    """A warning for each robot without a fault whose teammates' estimates were, after the
    transient, farther from it (RMS) than half the slots' spacing: estimates that agree with
    each other but not with the world (the residuals cannot show it)."""
    tol = slot_spacing(s.mission.formation, s.team.robots) / 2
    onset = fault_onsets(events)
    out = []
    for k, rms in enumerate(found["per_robot_rms"]):
        if rms is not None and rms > tol and _healthy_at(onset, k + 1, end):
            out.append(
                f"the team's estimates of robot {k + 1} were {rms:.3g} m (RMS after the "
                f"transient) from where it was, more than half the slots' spacing "
                f"({tol:.3g} m): they agree with each other, not with the world "
                "(summary estimation_error; an observer or controller block that drifts?)"
            )
    return out


def _warnings(events: Events) -> list[str]:
    """The run's warnings, and each split of the graph an exclusion left, as lines."""
    return [e["message"] for e in events.of_kind(Kind.WARNING)] + [
        f"t = {e['t']:g} s: " + split_text(e)
        for e in events.of_kind(Kind.GRAPH_NOT_STRONGLY_CONNECTED)
    ]


def fault_onsets(events: Events) -> dict[int, float]:
    """Each faulty robot's (1-based) first fault onset, from the ``fault`` events."""
    onset: dict[int, float] = {}
    for e in events.of_kind(Kind.FAULT):
        onset[e["robot"]] = min(e["t"], onset.get(e["robot"], np.inf))
    return onset


def _healthy_at(onset: dict[int, float], robot: int, t: float) -> bool:
    """Robot ``robot`` (1-based) had no fault at or before ``t`` (``onset``:
    :func:`fault_onsets`; looked up, not searched: a run of 400 robots can hold 10⁵
    detections and as many events, and searching the events per detection took hours)."""
    return t < onset.get(robot, np.inf)
