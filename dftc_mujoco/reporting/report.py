"""What ``python -m dftc_mujoco.run`` prints about a finished run, for a person reading it.

One line says what ran and how fast; a table lists what happened, in time order; then one
line per question a reader has, each with its verdict: did the mission complete, what
became of each fault, were there false alarms, did the robots keep clear of the obstacles,
did the premises of the detection thresholds hold. ``verbose`` adds what a developer reads:
every premise span, the task errors of eqs. 9-12, the set-up and compile times, the
onboard path.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core.events import Kind, describe

if TYPE_CHECKING:
    from .results import RunResult

#: each premise in plain words (premises.PREMISES has the formal statement)
PLAIN = {
    "noise": "measurement noise within its bound η̄",
    "mismatch": "robots move as commanded, within ξ̄",
    "initial_error": "every robot starts within ε̄ of its slot",
    "saturation": "commands stay inside the drive's range",
    "contact": "no robot touches a teammate or a cylinder",
    "planar": "every robot stays flat on the floor",
    "connectivity": "the robots' graph stays strongly connected",
    "network": "every message arrives in time, intact",
    "slot": "a silent robot stays near its slot",
}
#: [s] premise spans that end by then belong to the start from rest
START = 1.0
#: events listed without ``verbose`` (summary.json keeps every one)
LISTED = 40


def _factor(x: float) -> str:
    """A real-time factor as 325x, 3.2x or 0.053x."""
    return f"{x:.0f}x" if x >= 10 else f"{x:.2g}x"


def _length(v: float) -> str:
    """A length for a reader: 14.8 cm, 1.9 mm, 2.35 m."""
    a = abs(v)
    if a >= 0.9995:
        return f"{v:.3g} m"
    if a >= 0.009995:
        return f"{v * 100:.3g} cm"
    return f"{v * 1000:.2g} mm"


def _robots(rs: list[int]) -> str:
    """1, 2 and 3."""
    names = [str(r) for r in rs]
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def headline(s: dict[str, Any]) -> str:
    """What ran, how much was simulated, how fast, and how it ended."""
    line = (
        f"{s['scenario']}: {s['simulated_time']:.2f} s simulated in {s['wall_time']:.2f} s "
        f"({_factor(s['real_time_factor'] or 0.0)} real time); status: {s['status']}"
    )
    compiled = s.get("compile_time") or 0.0
    if compiled >= 0.5:
        line += (
            f"\n(plus {compiled:.1f} s compiling the onboard code: once for this machine, "
            "later runs reuse it)"
        )
    return line


def event_table(result: RunResult, verbose: bool) -> list[str]:
    """The events in time order; without ``verbose`` no premise spans (the premises line
    sums them up) and at most :data:`LISTED` rows."""
    rows = [e for e in result.events.ordered() if verbose or e["kind"] != Kind.PREMISE_VIOLATED]
    lines = ["   t [s]  event"]
    shown = rows if verbose else rows[:LISTED]
    lines += [f"{e['t']:8.2f}  {describe(e)}" for e in shown]
    if len(rows) > len(shown):
        lines.append(
            f"          ... and {len(rows) - len(shown)} more (--verbose lists them all; "
            "summary.json keeps every one)"
        )
    return lines


def mission_line(s: dict[str, Any]) -> str:
    """Did the survivors end in formation on the path?"""
    m = s.get("mission")
    if not m or not m["survivors"]:
        return "mission:      not judged (no robot left in the team)"
    n = len(m["survivors"])
    who = "the team" if n == s["robots"] else f"the {n} robots left"
    where = (
        f"{who} ended {_length(m['final_slot_error'])} from their slots (tolerance "
        f"{_length(m['tolerance'])}), {_length(m['final_centroid_error'])} from the path"
    )
    if m["completed"]:
        return f"mission:      completed: {where}"
    if s["status"] != "ok":
        return f"mission:      not completed: the run ended early ({s['status']}); {where}"
    return f"mission:      NOT completed: {where}"


def _due(s: dict[str, Any], fault: dict[str, Any]) -> str:
    """Why a flagged fault was not excluded, when the reason is the run's end."""
    due = [
        e
        for e in s.get("events", [])
        if e.get("kind") == Kind.EXCLUSION_SCHEDULED
        and e.get("robot") == fault["robot"]
        and e["t"] >= fault["t"]
    ]
    end = s.get("duration")
    if not due or end is None or due[-1]["t_r"] <= end:
        return ""
    horizon = s.get("dt_d_max")
    horizon = horizon if isinstance(horizon, dict) else {}
    for later in horizon.get("after_exclusions", []):  # the one in force when it was due
        if later["t"] <= due[-1]["t"]:
            horizon = later
    if horizon.get("longer_than_the_run"):  # t_r is then only a lower bound
        return " before the run ended (Δt_d,max, eq. 46, is longer than the run)"
    return f" before the run ended (its exclusion was due at {due[-1]['t_r']:.2f} s)"


def fault_lines(s: dict[str, Any]) -> list[str]:
    """One line per fault with its outcome."""
    out = []
    for f in s.get("fault_outcomes", []):
        what = f"{f['kind']} on robot {f['robot']} at {f['t']:.2f} s"
        kind = f["outcome"]
        if kind in ("excluded", "detected"):
            delay = f["first_flag"] - f["t"]
            by = ", ".join(str(b) for b in f["flagged_by"])
            said = f"flagged {delay:.2f} s later (by {by})"
            if kind == "excluded":
                said += f", excluded at {f['excluded_at']:.2f} s"
            else:
                said += ", NOT excluded" + _due(s, f)
        elif kind == "compensated":
            said = (
                f"compensated on board, flagged by nobody (off its slot by "
                f"{_length(f['max_slot_error'])} at most)"
            )
        elif kind == "missed":
            said = (
                f"MISSED: flagged by nobody while it drifted {_length(f['max_slot_error'])} "
                "from its slot"
            )
        else:
            said = "undecided: too close to the end of the run to tell"
        out.append(f"{what}: {said}")
    if not out:
        return ["faults:       none injected"]
    return ["faults:       " + out[0]] + ["              " + line for line in out[1:]]


def false_alarm_line(s: dict[str, Any]) -> str:
    """Were robots without a fault flagged or excluded?"""
    wrong = s.get("healthy_exclusions", 0)
    flags = s.get("healthy_flags", 0)
    if wrong:
        return (
            f"false alarms: {wrong} ROBOT(S) WITHOUT A FAULT EXCLUDED ({flags} flags on robots "
            "without a fault)"
        )
    if flags:
        held = s.get("healthy_flags_premises_held", 0)
        by = s.get("healthy_flags_by_premise", {})
        why = ", ".join(f"{p} {c}" for p, c in by.items())
        line = f"false alarms: {flags} flags on robots without a fault, none excluded"
        if held:
            return line + (
                f"; {held} while every premise held: A DEFECT OF THE THRESHOLD RULE "
                "(see the threshold rules in the documentation)"
            )
        return line + f"; each while a premise was violated ({why})"
    margin = s.get("margin")
    if margin is None:
        return "false alarms: none (detection is off)"
    return (
        f"false alarms: none (healthy robots' residuals peaked at {margin:.0%} of their thresholds)"
    )


def obstacle_line(s: dict[str, Any]) -> str | None:
    """How close did the robots come to the cylinders?"""
    gap = s.get("min_obstacle_clearance")
    if gap is None:
        return None
    margin = s["min_safe_distance_margin"]
    verdict = "no contact" if gap > 0 else f"CONTACT ({_length(-gap)} deep)"
    inside = (
        f"outside the safe distance d by {_length(margin)}"
        if margin >= 0
        else f"{_length(-margin)} inside the safe distance d at the closest"
    )
    return f"obstacles:    {verdict} (closest gap {_length(gap)}); {inside}"


def premises_line(result: RunResult) -> str | None:
    """Did the premises of the threshold rule hold? Spans that end within :data:`START`
    seconds are the start from rest, said apart from the others."""
    table = result.summary.get("premises")
    if not table:
        return None
    spans = result.events.of_kind(Kind.PREMISE_VIOLATED)
    start = {e["premise"] for e in spans if e["until"] <= START}
    later = {e["premise"] for e in spans if e["until"] > START}
    broken = [p for p, v in table.items() if not v["held"]]
    if not broken:
        return "premises:     all held (what the detection thresholds assume)"
    if set(broken) <= start and not later:
        end = max(e["until"] for e in spans)
        return (
            f"premises:     all held after the start from rest ({', '.join(sorted(start))} "
            f"for its first {end:.2f} s: the drives lag their first commands)"
        )
    parts = []
    for p in broken:
        v = table[p]
        who = f", worst robot {v['robot']}" if v.get("robot") else ""
        parts.append(f"{p} ({PLAIN.get(p, p)}: {v['spans']} spans{who})")
    return (
        "premises:     VIOLATED: " + "; ".join(parts) + ". Flags raised meanwhile carry no "
        "guarantee (each is labelled in the event table)"
    )


def blocks_line(s: dict[str, Any]) -> str | None:
    """Which onboard blocks are not the paper's (None when every block is)."""
    custom = {k: v for k, v in s.get("onboard", {}).get("blocks", {}).items() if v != "paper"}
    if not custom:
        return None
    mine = ", ".join(f"{k} = {v}" for k, v in custom.items())
    return f"blocks:       {mine} (the paper's for the others)"


def developer_lines(result: RunResult) -> list[str]:
    """``--verbose``: what a developer of the onboard code reads."""
    s = result.summary
    err = s["errors"]

    def m(v: float | None) -> str:
        return "n/a" if v is None else f"{v:.4f} m"

    lines = [
        f"task errors (eqs. 9-12) from t = {err['window'][0]:g} s: centroid rms "
        f"{m(err['centroid_rms'])}, formation rms {m(err['formation_rms'])}; final: centroid "
        f"{m(err['final_centroid'])}, formation {m(err['final_formation'])} (robots still "
        "counted)"
    ]
    for f in s.get("fault_estimates", []):  # one entry per robot, however many biases
        mean = ", ".join(f"{v:.4f}" for v in f["mean_error"])
        windows = f.get("windows", [f["window"]])
        when = (
            f"from {windows[0][0]:g} s"
            if len(windows) == 1
            else f"{len(f['faults'])} biases, " + ", ".join(f"{a:g}-{b:g} s" for a, b in windows)
        )
        lines.append(f"fault estimate on robot {f['robot']} ({when}): mean error [{mean}] m/s")
    for p, v in (s.get("premises") or {}).items():
        if not v["held"]:
            lines.append(
                f"premise {p}: {v['spans']} spans, worst {v['worst']:.4g} against {v['bound']:.4g}"
            )
    o = s.get("onboard", {})
    path = f"onboard: {o.get('path', '?')} path"
    if o.get("compiling_in_background"):
        path += " (the compiled period was being compiled in the background)"
    lines.append(path)
    lines.append(
        f"set-up {s.get('build_time', 0.0):.2f} s, compiling {s.get('compile_time', 0.0):.2f} s"
    )
    return lines


def report(result: RunResult, out: Path, verbose: bool = False) -> str:
    """The text printed at the end of a run whose records are in ``out``."""
    s = result.summary
    lines = [headline(s), "", *event_table(result, verbose), ""]
    lines.append(mission_line(s))
    lines += fault_lines(s)
    if s.get("margin") is not None or s.get("healthy_flags"):
        lines.append(false_alarm_line(s))
    for line in (obstacle_line(s), premises_line(result), blocks_line(s)):
        if line is not None:
            lines.append(line)
    if verbose:
        lines += developer_lines(result)
    lines.append(f"records:      {out} (summary.json, log.npz, scenario.toml)")
    return "\n".join(lines)
