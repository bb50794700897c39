"""The run's events: every kind with the facts it carries, and the one line that says each.

An event is a plain dict (JSON in ``summary.json``) with ``t`` [s], ``kind`` and the fields
:data:`KINDS` lists for that kind; robots are numbered from 1. :func:`make` is the one
constructor (it refuses a kind or a field that :data:`KINDS` does not list), and
:func:`describe` the only place an event is put into words: the console's event table, the
warnings of a summary and the video's captions read it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

#: kind -> the fields an event of that kind carries besides ``t`` and ``kind``
KINDS: dict[str, tuple[str, ...]] = {
    "fault": ("robot", "fault", "command"),
    "fault_ended": ("robot", "fault"),
    "reactive_on": ("robot", "obstacle"),
    "reactive_off": ("robot",),
    "detection": ("by", "robot", "premises"),
    "premise_violated": ("premise", "robot", "value", "bound", "until"),
    "exclusion_scheduled": ("robot", "t_r"),
    "exclusion": ("robot", "flagged_by", "detected_by"),
    "exclusion_cancelled": ("robot", "detected_by", "reason"),
    "exclusion_postponed": ("robot", "reason", "last_contact", "t_r", "ratio", "was", "phi_bar"),
    "systemic_anomaly": ("robots", "excluded", "max_faults", "premises"),
    "systemic_anomaly_over": ("robots",),
    "detection_not_guaranteed": ("robot", "until", "restarted"),
    "detection_past_end": ("robot", "left", "dt_d_max"),
    "detection_window_restarted": ("robot", "onset", "until"),
    "detection_horizon": ("value", "before"),
    "graph_not_strongly_connected": ("robots", "components", "unheard", "pairs"),
    "graph_rewired": ("robot", "links", "how"),
    "warning": ("message",),
    "mission_ended": ("reason", "robots"),
    "simulation_error": ("message",),
    # the network (dftc_mujoco.network)
    "radio_fault": ("fault", "robot", "link", "value"),
    "link_silent": ("robot", "heard_by", "since"),
    "link_heard": ("robot", "heard_by"),
    "robot_silent": ("robot", "reported_by", "since"),
    "message_fault": ("robot", "reported_by"),
    "sighting": ("by", "robot", "distance", "tolerance"),
}


#: an event as it is stored: ``{"t": ..., "kind": ..., **fields}``
Event = dict[str, Any]


def make(t: float, kind: str, **fields: Any) -> Event:
    """The event ``kind`` at ``t`` with ``fields``, each of which :data:`KINDS` lists for it
    (ValueError otherwise: a new kind or field is declared there first, with its words in
    :func:`describe`)."""
    allowed = KINDS.get(kind)
    if allowed is None:
        raise ValueError(f"unknown event kind {kind!r}; known: {', '.join(KINDS)}")
    extra = set(fields) - set(allowed)
    if extra:
        raise ValueError(f"event {kind!r} has no field(s) {sorted(extra)}; it has {allowed}")
    return {"t": t, "kind": kind, **fields}


def _fault(e: Mapping[str, Any], r: int) -> str:
    return f"fault: {e['fault']} on robot {r}"


def _fault_ended(e: Mapping[str, Any], r: int) -> str:
    return f"fault over: {e['fault']} on robot {r}"


def _reactive_on(e: Mapping[str, Any], r: int) -> str:
    return f"robot {r} switches to obstacle avoidance ({e.get('obstacle', '?')})"


def _reactive_off(e: Mapping[str, Any], r: int) -> str:
    return f"robot {r} back to the global mission"


def _detection(e: Mapping[str, Any], r: int) -> str:
    held = e.get("premises")
    why = f" — while its premises were violated: {', '.join(held)}" if held else ""
    who = "itself" if e["by"] == r else f"robot {r}"
    return f"robot {e['by']} flags {who}{why}"


def _premise_violated(e: Mapping[str, Any], r: int) -> str:
    who = f"robot {r}" if r else "the team"
    return (
        f"premise '{e['premise']}' violated by {who} until {e['until']:.2f} s "
        f"(worst {e['value']:.4g} against {e['bound']:.4g})"
    )


def _exclusion_scheduled(e: Mapping[str, Any], r: int) -> str:
    return f"robot {r} will be excluded at {e['t_r']:.2f} s unless nobody flags it then"


def _exclusion(e: Mapping[str, Any], r: int) -> str:
    by = ", ".join(str(b) for b in e.get("flagged_by") or [])
    return f"robot {r} excluded from the team" + (f" (still flagged by {by})" if by else "")


def _exclusion_cancelled(e: Mapping[str, Any], r: int) -> str:
    why = {
        "systemic_anomaly": "a systemic anomaly holds (more robots flagged than faults)",
        "flagged_only_by_itself": "only its own flag is up (exclusion needs teammates)",
    }.get(e.get("reason", "").replace(" ", "_"), "nobody flags it any more")
    return f"robot {r} kept at t_r: {why}"


def _exclusion_postponed(e: Mapping[str, Any], r: int) -> str:
    when = f"t_r = {e['t_r']:.2f} s" if e["t_r"] is not None else "after this run"
    if e.get("reason") == "estimate":
        return (
            f"robot {r}'s exclusion postponed to {when}: since its first flag its own fault "
            f"estimate has not stayed beyond its healthy bound Φ̄ = {e['phi_bar']:.3g} m/s, "
            "nor its command beyond range, for a decision window, so its flags are the trace "
            "of a broken premise, not an actuator's fault (judged again each Δt_d,max while "
            "flagged)"
        )
    if e.get("reason") == "decaying":
        return (
            f"robot {r}'s exclusion postponed to {when}: its teammates' largest residual/"
            f"threshold fell from {e['was']:.3g} to {e['ratio']:.3g} since then, the trace "
            f"of its contact at {e['last_contact']:.2f} s decaying, not a fault's signature"
        )
    return (
        f"robot {r}'s exclusion postponed to {when}: its bumper touched something at "
        f"{e['last_contact']:.2f} s, and a contact, not a fault, may explain its flags"
    )


def _systemic_anomaly(e: Mapping[str, Any], r: int) -> str:
    who = ", ".join(str(b) for b in e["robots"])
    return (
        f"SYSTEMIC ANOMALY: robots {who} flagged at once, more than the "
        f"{e['max_faults']} faulty robot(s) at a time the fault hypothesis admits "
        "(fdir.max_faults); nobody is "
        "excluded until every flag is down"
        + (f" — premises violated: {', '.join(e['premises'])}" if e.get("premises") else "")
    )


def _detection_not_guaranteed(e: Mapping[str, Any], r: int) -> str:
    until = e["until"]
    when = f"{until:.2f} s" if until is not None else "after the end of the run"
    again = e.get("restarted")  # the exclusion whose restarted thresholds these are
    after = f" again after the exclusion at {again:.2f} s" if again is not None else ""
    return (
        f"robot {r}'s fault comes while the detection thresholds are still settling{after}: "
        f"its detection in time (within Δt_d,max, eq. 46) is guaranteed only for faults "
        f"from {when} on"
    )


def _detection_window_restarted(e: Mapping[str, Any], r: int) -> str:
    until = e["until"]
    when = f"at {until:.2f} s" if until is not None else "only after the end of the run"
    return (
        f"an exclusion restarted the detection thresholds while robot {r}'s fault (at "
        f"{e['onset']:.2f} s) waited to be detected: its detection in time (within "
        f"Δt_d,max, eq. 46) is no longer guaranteed (the thresholds settle again {when})"
    )


def _detection_past_end(e: Mapping[str, Any], r: int) -> str:
    return (
        f"robot {r}'s fault comes {e['left']:.2f} s before the end of the run, less than "
        f"the {e['dt_d_max']:.2f} s its detection may take (Δt_d,max): it may end undetected"
    )


def _systemic_anomaly_over(e: Mapping[str, Any], r: int) -> str:
    return "systemic anomaly over: no robot is flagged by a teammate any more"


def _detection_horizon(e: Mapping[str, Any], r: int) -> str:
    return (
        f"the time a fault may take to be detected (Δt_d,max, eq. 46) is now "
        f"{e['value']:.2f} s on the reduced team (was {e['before']:.2f} s)"
    )


def _graph_not_strongly_connected(e: Mapping[str, Any], r: int) -> str:
    return "WARNING: " + split_text(e)


def _graph_rewired(e: Mapping[str, Any], r: int) -> str:
    pairs = [f"{i} hears {j}" for j, i in e["links"]]
    shown = ", ".join(pairs[:6]) + (f" and {len(pairs) - 6} more" if len(pairs) > 6 else "")
    via = f" through robot {r}'s radio" if e.get("how") == "relay" else " directly"
    return f"the team re-wires around robot {r}: robot {shown}{via}"


def _warning(e: Mapping[str, Any], r: int) -> str:
    return f"WARNING: {e['message']}"


def _mission_ended(e: Mapping[str, Any], r: int) -> str:
    return f"MISSION ENDED: {e['reason']}"


def _simulation_error(e: Mapping[str, Any], r: int) -> str:
    return f"SIMULATION ERROR: {e['message']}"


def _radio_fault(e: Mapping[str, Any], r: int) -> str:
    if e["fault"] == "link_down":
        return f"radio fault: link {e['link'][0]} -> {e['link'][1]} down"
    if e["fault"] == "corrupt":
        return f"radio fault: robot {r} sends corrupted estimates (+{e['value']:g} m)"
    return f"radio fault: robot {r} falls silent"


def _link_silent(e: Mapping[str, Any], r: int) -> str:
    return (
        f"robot {e['heard_by']} hears nothing from robot {r} (it keeps its last message, "
        f"of round {e['since']})"
    )


def _link_heard(e: Mapping[str, Any], r: int) -> str:
    return f"robot {e['heard_by']} hears robot {r} again"


def _message_fault(e: Mapping[str, Any], r: int) -> str:
    by = ", ".join(str(b) for b in e["reported_by"])
    who = f"robot {r}'s messages" if r else "a message they receive"
    return (
        f"MESSAGE FAULT: robots {by} flag more robots at once than the fault hypothesis "
        f"admits: {who} (not an actuator fault)"
    )


def _sighting(e: Mapping[str, Any], r: int) -> str:
    return (
        f"robot {e['by']} sees silent robot {r} {e['distance']:.2f} m from its slot "
        f"(tolerance {e['tolerance']:.2f} m)"
    )


def _robot_silent(e: Mapping[str, Any], r: int) -> str:
    by = ", ".join(str(b) for b in e["reported_by"])
    return (
        f"robot {r} is SILENT (a communication fault, not an actuator fault): reported by "
        f"robots {by}, who keep its last messages"
    )


#: each kind's line (robot ``r`` the event's robot, 0 for none)
_LINES: dict[str, Callable[[Mapping[str, Any], int], str]] = {
    "fault": _fault,
    "fault_ended": _fault_ended,
    "reactive_on": _reactive_on,
    "reactive_off": _reactive_off,
    "detection": _detection,
    "premise_violated": _premise_violated,
    "exclusion_scheduled": _exclusion_scheduled,
    "exclusion": _exclusion,
    "exclusion_cancelled": _exclusion_cancelled,
    "exclusion_postponed": _exclusion_postponed,
    "systemic_anomaly": _systemic_anomaly,
    "detection_not_guaranteed": _detection_not_guaranteed,
    "detection_window_restarted": _detection_window_restarted,
    "detection_past_end": _detection_past_end,
    "systemic_anomaly_over": _systemic_anomaly_over,
    "detection_horizon": _detection_horizon,
    "graph_not_strongly_connected": _graph_not_strongly_connected,
    "graph_rewired": _graph_rewired,
    "warning": _warning,
    "mission_ended": _mission_ended,
    "simulation_error": _simulation_error,
    "radio_fault": _radio_fault,
    "link_silent": _link_silent,
    "link_heard": _link_heard,
    "message_fault": _message_fault,
    "sighting": _sighting,
    "robot_silent": _robot_silent,
}


def describe(e: Mapping[str, Any]) -> str:
    """The one line that says what event ``e`` means (the console table, summaries and the
    video captions all use it): its kind's line of :data:`_LINES`."""
    line = _LINES.get(e["kind"])
    return f"{e['kind']} {dict(e)}" if line is None else line(e, e.get("robot", 0))


def split_text(e: Mapping[str, Any]) -> str:
    """One line for a ``graph_not_strongly_connected`` event: who is left, in which groups,
    and which estimates lost their bound."""
    groups = e.get("components") or [e["robots"]]
    text = (
        f"after an exclusion the graph of robots {', '.join(str(r) for r in e['robots'])} "
        "is not strongly connected"
    )
    if len(groups) > 1:
        parts = []
        for g, lost in zip(groups, e.get("unheard", []), strict=False):
            if lost:
                parts.append(f"robots {_span(g)} hear nothing from robots {_span(lost)}")
        text += f" ({len(groups)} groups; " + "; ".join(parts) + ")"
    return text + (
        ": those estimates, and the residuals and thresholds built on them, have no bound "
        '(fdir.rewire = "adopt", the default on the ideal network, re-wires the survivors)'
    )


def _span(robots: list[int]) -> str:
    """Robots as a short list (at most 8 named)."""
    head = ", ".join(str(r) for r in robots[:8])
    return head + (f" and {len(robots) - 8} more" if len(robots) > 8 else "")
