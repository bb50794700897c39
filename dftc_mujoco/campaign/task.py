"""One campaign run as a task: simulate a drawn scenario and reduce it to a row of facts.

Every engine (this process, local worker processes in :mod:`.pool`, Ray in
:mod:`.cluster`) calls :func:`run_one`; the rows do not depend on the engine. The facts
come from the run's own summary: one entry per fault it actually had
(:func:`fault_facts`) and the run's counts (false flags, healthy exclusions, systemic
anomalies, premises).
"""

from __future__ import annotations

import contextlib
import json
import time
import traceback
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core.events import Kind
from .spec import Spec, scenario_for

if TYPE_CHECKING:
    from ..closed_loop.execution import Execution
    from ..runtime.interrupt import Signals


def run_one(
    spec: Spec,
    params: dict[str, Any],
    signals: Signals | None = None,
    execution: Execution | None = None,
) -> dict[str, Any]:
    """Simulate one run and reduce it to a row of facts; never raises (a signal caught by
    ``signals`` stops the simulation: the row then says "interrupted"). ``execution``: how
    its period runs (:class:`~..execution.Execution`; the default where None)."""
    from ..closed_loop.loop import Simulation

    t0 = time.perf_counter()
    row: dict[str, Any] = dict(params)
    try:
        s = scenario_for(spec, params)
        with Simulation(s, search=spec_folders(spec), execution=execution) as sim:
            with signals.stopping(sim) if signals is not None else contextlib.nullcontext():
                result = sim.run(progress=False)
        row.update(_facts(params, result.summary, s.fdir.dt_d_max))
        row["status"] = result.summary["status"]
        row["error"] = result.summary["error"]
    except Exception as exc:  # a run that raises is recorded, not fatal
        row["status"] = "failed"
        row["error"] = f"{type(exc).__name__}: {exc}"
        row["traceback"] = traceback.format_exc(limit=4)
    row["wall_time"] = time.perf_counter() - t0
    return row


def spec_folders(spec: Spec) -> list[Path]:
    """Where a campaign's user blocks are looked for: beside the spec and its base scenario."""
    folders = []
    for src in (spec.source, spec.base_source):
        p = Path(src)
        if p.is_file() and p.parent.resolve() not in folders:
            folders.append(p.parent.resolve())
    return folders


def fault_facts(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """One entry per fault the run actually had (the base scenario's, the drawn ones, any
    number), from its own ``fault`` events: whether teammates flagged it, how many, the
    first and last flag's delay, whether and when that robot was excluded."""
    events = summary.get("events", [])
    found = summary.get("dt_d_max")
    horizon: dict[str, Any] = found if isinstance(found, dict) else {}
    settle = horizon.get("settle_time")  # T_s (None: not within the run)
    n = int(summary.get("robots") or 0)
    end = float(summary.get("simulated_time") or summary.get("duration") or 0.0)
    planned = float(summary.get("duration") or end)
    out = []
    for f in (e for e in events if e["kind"] == Kind.FAULT):
        robot, t_f = f["robot"], f["t"]
        gone_before = sum(1 for e in summary["exclusions"] if e["t"] < t_f)
        dt = horizon.get("value")
        # eq. 46 predicted a finite delay (not the 5 s fallback) on the graph of the moment
        promised = horizon.get("predicted_delays_max") is not None
        for later in horizon.get("after_exclusions", []):  # as recomputed at each exclusion
            if later["t"] < t_f:
                dt = later["value"]
                promised = later.get("predicted_delays_max") is not None
        since = settle  # T_s, or the restarted rule's after the last exclusion before t_f
        for later in horizon.get("settle_after_exclusions", []):
            if later["t"] <= t_f:
                since = later["settle_time"]
        settled = since is not None and t_f >= since
        told = f.get("command")  # the speed the robot was told at onset: a stop's size
        reference = horizon.get("reference_fault")
        on = [
            d
            for d in summary["detections"]
            if d["robot"] == robot and d["by"] != robot and d["t"] >= t_f
        ]
        gone = next(
            (e["t"] for e in summary["exclusions"] if e["robot"] == robot and e["t"] >= t_f), None
        )
        # another robot's exclusion restarted the thresholds within its window (detection_domain)
        cut = next(
            (
                e["t"]
                for e in events
                if e["kind"] == Kind.DETECTION_WINDOW_RESTARTED
                and e["robot"] == robot
                and e["onset"] == t_f
            ),
            None,
        )
        out.append(
            {
                "robot": robot,
                "kind": f.get("fault"),
                "t": t_f,
                "detected": bool(on),
                "detected_by": len({d["by"] for d in on}),
                "delay_first": min(d["t"] for d in on) - t_f if on else None,
                "delay_last": max(d["t"] for d in on) - t_f if on else None,
                "excluded": gone is not None,
                "exclusion_delay": None if gone is None else gone - t_f,
                "teammates": max(n - gone_before - 1, 0) if n else None,
                # why it was still in the team at the end (None: excluded)
                "kept_why": kept_why(events, robot, t_f, end, planned) if gone is None else None,
                "after_settle": settled,  # eq. 46's domain
                "restarted_in_window": cut,  # an exclusion's restart cut its window (or None)
                "dt_d_max": dt,
                "command": told,
                # eq. 46's promise applies: a finite prediction, a stop at least the reference
                # fault at onset, after T_s and no restart of the thresholds within its window,
                # and Δt_d,max ends within the run (observable)
                "in_domain": bool(
                    promised
                    and settled
                    and cut is None
                    and f.get("fault") == "stop"
                    and told is not None
                    and reference is not None
                    and told >= reference
                    and dt is not None
                    and t_f + dt <= end + 1e-9
                ),
            }
        )
    return out


#: the recovery's events about a flagged robot's exclusion (the last one says why it stayed)
RECOVERY_KINDS = (Kind.EXCLUSION_SCHEDULED, Kind.EXCLUSION_POSTPONED, Kind.EXCLUSION_CANCELLED)


def kept_why(
    events: list[dict[str, Any]], robot: int, t_f: float, end: float, planned: float
) -> str:
    """Why faulty ``robot`` (1-based; its fault began at ``t_f``) was still in the team when
    the run ended at ``end`` (``planned``: its duration), from the last word the recovery
    said of it that held at the onset or came after it: ``never_flagged`` (no teammate
    flagged it), ``cancelled_<reason>`` (at its t_r, e.g. ``cancelled_not_flagged``,
    ``cancelled_systemic_anomaly``), ``postponed_<reason>`` (``contact``, ``decaying``,
    ``estimate``), ``due_after_end`` (t_r = first flag + Δt_d,max after the run's
    duration) or ``run_stopped`` (the run stopped before a t_r within its duration).
    A robot flagged before its fault began keeps the t_r of that first flag: later flags
    schedule nothing new (before, such a robot, flagged after the onset too, read
    ``never_flagged``)."""
    last = None
    for e in events:
        if e["kind"] not in RECOVERY_KINDS or e.get("robot") != robot:
            continue
        if e["t"] >= t_f:
            last = e
        else:  # before the onset: in force at it while its t_r (None: never) is still to come
            t_r = e.get("t_r")
            pending = e["kind"] != Kind.EXCLUSION_CANCELLED and (t_r is None or t_r >= t_f)
            last = e if pending else None
    if last is None:
        return "never_flagged"
    if last["kind"] == Kind.EXCLUSION_CANCELLED:
        return "cancelled_" + str(last.get("reason")).replace(" ", "_")
    t_r = last.get("t_r")
    if t_r is not None and end + 1e-9 < t_r <= planned + 1e-9:
        return "run_stopped"
    if last["kind"] == Kind.EXCLUSION_POSTPONED:
        return "postponed_" + str(last.get("reason"))
    return "due_after_end" if t_r is not None and t_r > planned + 1e-9 else "run_stopped"


def _radio_facts(summary: dict[str, Any]) -> dict[str, Any]:
    """The network's side of a run: radio faults, how soon a silent robot was reported, how
    soon its stop was flagged by itself and seen by a listener, and the channel's measured
    loss rate and largest delay."""
    events = summary.get("events", [])
    silent = [e for e in events if e["kind"] == Kind.RADIO_FAULT and e.get("fault") == "silent"]
    reported = [e for e in events if e["kind"] == Kind.ROBOT_SILENT]
    delay = self_seen = sighted = None
    if silent:
        robot = silent[0]["robot"]
        later = [e["t"] for e in reported if e["robot"] == robot]
        delay = min(later) - silent[0]["t"] if later else None
        # its own later stop, flagged by itself (its teammates no longer hear it)
        stop = [e["t"] for e in events if e["kind"] == Kind.FAULT and e["robot"] == robot]
        own = [
            e["t"] - stop[0]
            for e in events
            if stop
            and e["kind"] == Kind.DETECTION
            and e["by"] == robot == e["robot"]
            and e["t"] >= stop[0]
        ]
        self_seen = min(own) if own else None
        # and seen by a listener off its slot (onboard/sighting.py)
        by_sight = [
            e["t"] - stop[0]
            for e in events
            if stop and e["kind"] == Kind.SIGHTING and e["robot"] == robot and e["t"] >= stop[0]
        ]
        sighted = min(by_sight) if by_sight else None
    net = summary.get("network") or {}
    links = net.get("links") or []
    sent = sum(x["sent"] for x in links)
    delays = [x["delay_max"] for x in links if x.get("delay_max") is not None]
    return {
        "radio_faults": sum(e["kind"] == Kind.RADIO_FAULT for e in events),
        "silent_reported": bool(silent) and delay is not None,
        "silent_report_delay": delay,
        "silent_stop_self_flag_delay": self_seen,
        "silent_stop_sighted_delay": sighted,
        "sightings": sum(e["kind"] == Kind.SIGHTING for e in events),
        "round_periods": net.get("round_periods", 1),
        "estimation_error_max": (summary.get("estimation_error") or {}).get("max"),
        "loss_measured": sum(x["lost"] for x in links) / sent if sent else None,
        "delay_max_measured": max(delays) if delays else None,
    }


def _facts(p: dict[str, Any], summary: dict[str, Any], dt_d_max: float | str) -> dict[str, Any]:
    """A run's row: per fault (``faults``, from the run's own fault events) and per run.

    The single-fault columns (``detected``, ``delay_first``, ...) describe the run's main
    fault: the drawn one (``faulty_robot``), else its first stop, else its first fault.
    ``false_flags`` counts flags on robots without an active fault (split by whether every
    premise held), ``healthy_exclusions`` exclusions of such robots."""
    faults = fault_facts(summary)
    horizon = summary.get("dt_d_max")  # the value the run used ("auto": from the analysis)
    if isinstance(horizon, dict) and horizon.get("value") is not None:
        dt_d_max = float(horizon["value"])
    drawn = p.get("faulty_robot")
    main = next((f for f in faults if f["robot"] == drawn), None) if drawn is not None else None
    main = main or next((f for f in faults if f["kind"] == "stop"), None)
    main = main or (faults[0] if faults else None)
    faulty = {f["robot"] for f in faults}
    excluded = [e["robot"] for e in summary["exclusions"]]
    err = summary["errors"]
    false_flags = summary.get("healthy_flags", 0)
    return {
        "faults": json.dumps(faults),
        "fault_count": len(faults),
        "main_fault_kind": main["kind"] if main else "none",
        "detected": bool(main and main["detected"]),
        "detected_by": main["detected_by"] if main else 0,
        "delay_first": main["delay_first"] if main else None,
        "delay_last": main["delay_last"] if main else None,
        "dt_d_max": dt_d_max,
        "false_flags": false_flags,
        "false_flags_premises_held": summary.get("healthy_flags_premises_held", 0),
        # per premise: the flags on healthy robots that came while it was violated
        "false_flags_by_premise": json.dumps(summary.get("healthy_flags_by_premise", {})),
        "false_alarms": false_flags,
        "false_alarm_robots": len(
            {d["robot"] for d in summary["detections"] if d["robot"] not in faulty}
        ),
        "excluded": json.dumps(excluded),
        "excluded_faulty": bool(main and main["excluded"]),
        "exclusion_delay": main["exclusion_delay"] if main else None,
        "healthy_exclusions": summary.get("healthy_exclusions", 0),
        "wrong_isolation": summary.get("healthy_exclusions", 0) > 0,
        "systemic_anomalies": summary.get("systemic_anomalies", 0),
        # every premise of the run's rule held for the whole run (premises.PREMISES)
        "premises_held": all(p.get("held", True) for p in summary.get("premises", {}).values()),
        **_radio_facts(summary),
        "premises_violated": json.dumps(
            [k for k, p in summary.get("premises", {}).items() if not p.get("held", True)]
        ),
        "settle_time": (horizon or {}).get("settle_time") if isinstance(horizon, dict) else None,
        "final_centroid": err["final_centroid"],
        "final_formation": err["final_formation"],
        "success": bool(
            summary["status"] == "ok"
            and err["final_centroid"] is not None
            and err["final_centroid"] < 0.05
            and err["final_formation"] < 0.05
        ),
        # what the mission achieved, apart from who is still counted (reporting/outcomes.py)
        **_mission_facts(summary),
        "margin": summary.get("margin"),
        "min_obstacle_clearance": summary["min_obstacle_clearance"],
        "warnings": len(summary["warnings"]),
        "onboard_path": summary.get("onboard", {}).get("path"),
        "thresholds": summary.get("onboard", {}).get("blocks", {}).get("thresholds"),
        "blocks": json.dumps(summary.get("onboard", {}).get("blocks", {}), sort_keys=True),
        "duration": summary["duration"],
    }


#: each fault's outcome (outcomes.fault_outcomes), counted per row
OUTCOMES = ("excluded", "detected", "compensated", "missed", "undecided")


def _mission_facts(summary: dict[str, Any]) -> dict[str, Any]:
    """The mission's outcome and each fault's, from the summary (None where it has none:
    the row of a run written before they existed)."""
    m = summary.get("mission") or {}
    found = summary.get("fault_outcomes") or []
    return {
        "mission_completed": m.get("completed"),
        "healthy_slot_rms": m.get("healthy_slot_rms"),
        "final_slot_error": m.get("final_slot_error"),
        "final_centroid_error": m.get("final_centroid_error"),
        "fault_outcomes": json.dumps(found),
        **{f"faults_{o}": sum(f["outcome"] == o for f in found) for o in OUTCOMES},
    }
