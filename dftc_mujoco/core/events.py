"""The run's events: every kind with the facts it carries, and the one line that says each.

An event is an :class:`Event` record (a dict, JSON in ``summary.json``) with ``t`` [s], its
:class:`Kind` and the fields :data:`KINDS` lists for that kind; robots are numbered from 1.
:func:`make` is the one constructor (it refuses a kind or a field that :data:`KINDS` does not
list), and :func:`describe` the only place an event is put into words: the console's event
table, the warnings of a summary and the video's captions read it. Code outside this module
names a kind as ``Kind.EXCLUSION``, never as a string, so a misspelt kind fails where it is
written.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from enum import StrEnum
from typing import Any, Required, TypedDict, cast


class Kind(StrEnum):
    """Every kind of event; a member equals its name as a string (``Kind.EXCLUSION ==
    "exclusion"``), which is how ``summary.json`` stores it, and shows as that string."""

    def __repr__(self) -> str:
        return repr(self.value)

    FAULT = "fault"
    FAULT_ENDED = "fault_ended"
    REACTIVE_ON = "reactive_on"
    REACTIVE_OFF = "reactive_off"
    DETECTION = "detection"
    PREMISE_VIOLATED = "premise_violated"
    EXCLUSION_SCHEDULED = "exclusion_scheduled"
    EXCLUSION = "exclusion"
    EXCLUSION_CANCELLED = "exclusion_cancelled"
    EXCLUSION_POSTPONED = "exclusion_postponed"
    SYSTEMIC_ANOMALY = "systemic_anomaly"
    SYSTEMIC_ANOMALY_OVER = "systemic_anomaly_over"
    DETECTION_NOT_GUARANTEED = "detection_not_guaranteed"
    DETECTION_PAST_END = "detection_past_end"
    DETECTION_WINDOW_RESTARTED = "detection_window_restarted"
    DETECTION_HORIZON = "detection_horizon"
    GRAPH_NOT_STRONGLY_CONNECTED = "graph_not_strongly_connected"
    GRAPH_REWIRED = "graph_rewired"
    WARNING = "warning"
    MISSION_ENDED = "mission_ended"
    SIMULATION_ERROR = "simulation_error"
    RADIO_FAULT = "radio_fault"
    LINK_SILENT = "link_silent"
    LINK_HEARD = "link_heard"
    ROBOT_SILENT = "robot_silent"
    MESSAGE_FAULT = "message_fault"
    SIGHTING = "sighting"


#: kind -> the fields an event of that kind carries besides ``t`` and ``kind``
KINDS: dict[Kind, tuple[str, ...]] = {
    Kind.FAULT: ("robot", "fault", "command"),
    Kind.FAULT_ENDED: ("robot", "fault"),
    Kind.REACTIVE_ON: ("robot", "obstacle"),
    Kind.REACTIVE_OFF: ("robot",),
    Kind.DETECTION: ("by", "robot", "premises"),
    Kind.PREMISE_VIOLATED: ("premise", "robot", "value", "bound", "until"),
    Kind.EXCLUSION_SCHEDULED: ("robot", "t_r", "after_run"),
    Kind.EXCLUSION: ("robot", "flagged_by", "detected_by"),
    Kind.EXCLUSION_CANCELLED: ("robot", "detected_by", "reason"),
    Kind.EXCLUSION_POSTPONED: ("robot", "reason", "last_contact", "t_r", "ratio", "was", "phi_bar"),
    Kind.SYSTEMIC_ANOMALY: ("robots", "excluded", "max_faults", "premises"),
    Kind.SYSTEMIC_ANOMALY_OVER: ("robots",),
    Kind.DETECTION_NOT_GUARANTEED: ("robot", "until", "restarted"),
    Kind.DETECTION_PAST_END: ("robot", "left", "dt_d_max"),
    Kind.DETECTION_WINDOW_RESTARTED: ("robot", "onset", "until"),
    Kind.DETECTION_HORIZON: ("value", "before"),
    Kind.GRAPH_NOT_STRONGLY_CONNECTED: ("robots", "components", "unheard", "pairs"),
    Kind.GRAPH_REWIRED: ("robot", "links", "how"),
    Kind.WARNING: ("message",),
    Kind.MISSION_ENDED: ("reason", "robots"),
    Kind.SIMULATION_ERROR: ("message",),
    # the network (dftc_mujoco.closed_loop.network)
    Kind.RADIO_FAULT: ("fault", "robot", "link", "value"),
    Kind.LINK_SILENT: ("robot", "heard_by", "since"),
    Kind.LINK_HEARD: ("robot", "heard_by"),
    Kind.ROBOT_SILENT: ("robot", "reported_by", "since"),
    Kind.MESSAGE_FAULT: ("robot", "reported_by"),
    Kind.SIGHTING: ("by", "robot", "distance", "tolerance"),
}


class Event(TypedDict, total=False):
    """An event as it is stored: ``t`` [s], its :class:`Kind` and the fields :data:`KINDS`
    lists for that kind (the others absent)."""

    t: Required[float]
    kind: Required[Kind]
    after_run: Any
    before: Any
    bound: Any
    by: Any
    command: Any
    components: Any
    detected_by: Any
    distance: Any
    dt_d_max: Any
    excluded: Any
    fault: Any
    flagged_by: Any
    heard_by: Any
    how: Any
    last_contact: Any
    left: Any
    link: Any
    links: Any
    max_faults: Any
    message: Any
    obstacle: Any
    onset: Any
    pairs: Any
    phi_bar: Any
    premise: Any
    premises: Any
    ratio: Any
    reason: Any
    reported_by: Any
    restarted: Any
    robot: Any
    robots: Any
    since: Any
    t_r: Any
    tolerance: Any
    unheard: Any
    until: Any
    value: Any
    was: Any


def make(t: float, kind: Kind, **fields: Any) -> Event:
    """The event ``kind`` at ``t`` with ``fields``, each of which :data:`KINDS` lists for it
    (ValueError otherwise: a new kind or field is declared there first, with its words in
    :func:`describe`)."""
    try:
        kind = Kind(kind)
    except ValueError:
        raise ValueError(f"unknown event kind {kind!r}; known: {', '.join(KINDS)}") from None
    allowed = KINDS[kind]
    extra = set(fields) - set(allowed)
    if extra:
        raise ValueError(f"event {kind!r} has no field(s) {sorted(extra)}; it has {allowed}")
    return cast(Event, {"t": t, "kind": kind, **fields})


def loaded(d: Mapping[str, Any]) -> Event:
    """An event read back from ``summary.json``: its kind a :class:`Kind` again (a kind this
    version does not know stays a string, which :func:`describe` still says)."""
    e = dict(d)
    try:
        e["kind"] = Kind(e["kind"])
    except (KeyError, ValueError):
        pass
    return cast(Event, e)


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
    if e.get("after_run"):  # t_r past the run's end (a lower bound where eq. 46's sweep stopped)
        return f"robot {r} will not be excluded before the run ends: Δt_d,max reaches past it"
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
_LINES: dict[Kind, Callable[[Mapping[str, Any], int], str]] = {
    Kind.FAULT: _fault,
    Kind.FAULT_ENDED: _fault_ended,
    Kind.REACTIVE_ON: _reactive_on,
    Kind.REACTIVE_OFF: _reactive_off,
    Kind.DETECTION: _detection,
    Kind.PREMISE_VIOLATED: _premise_violated,
    Kind.EXCLUSION_SCHEDULED: _exclusion_scheduled,
    Kind.EXCLUSION: _exclusion,
    Kind.EXCLUSION_CANCELLED: _exclusion_cancelled,
    Kind.EXCLUSION_POSTPONED: _exclusion_postponed,
    Kind.SYSTEMIC_ANOMALY: _systemic_anomaly,
    Kind.DETECTION_NOT_GUARANTEED: _detection_not_guaranteed,
    Kind.DETECTION_WINDOW_RESTARTED: _detection_window_restarted,
    Kind.DETECTION_PAST_END: _detection_past_end,
    Kind.SYSTEMIC_ANOMALY_OVER: _systemic_anomaly_over,
    Kind.DETECTION_HORIZON: _detection_horizon,
    Kind.GRAPH_NOT_STRONGLY_CONNECTED: _graph_not_strongly_connected,
    Kind.GRAPH_REWIRED: _graph_rewired,
    Kind.WARNING: _warning,
    Kind.MISSION_ENDED: _mission_ended,
    Kind.SIMULATION_ERROR: _simulation_error,
    Kind.RADIO_FAULT: _radio_fault,
    Kind.LINK_SILENT: _link_silent,
    Kind.LINK_HEARD: _link_heard,
    Kind.MESSAGE_FAULT: _message_fault,
    Kind.SIGHTING: _sighting,
    Kind.ROBOT_SILENT: _robot_silent,
}


def describe(e: Mapping[str, Any]) -> str:
    """The one line that says what event ``e`` means (the console table, summaries and the
    video captions all use it)."""
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
