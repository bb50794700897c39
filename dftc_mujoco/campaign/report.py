"""Campaign report: ``report.md`` and figures, computed from the result rows alone."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from ..render.figures import new_figure
from ..runtime.atomic import atomic_write, write_text
from .task import OUTCOMES


def _pct(a: float | None) -> str:
    return "n/a" if a is None else f"{100 * a:.1f} %"


def _num(a: float | None, digits: int) -> str:
    return "n/a" if a is None else f"{a:.{digits}f}"


def _rate(xs: list[bool]) -> float | None:
    return float(np.mean(xs)) if xs else None


def _by_premise(rows: list[dict[str, Any]]) -> dict[str, int]:
    """Flags on healthy robots per violated premise, summed over ``rows``."""
    total: dict[str, int] = {}
    for r in rows:
        for p, n in json.loads(r.get("false_flags_by_premise") or "{}").items():
            total[p] = total.get(p, 0) + n
    return dict(sorted(total.items()))


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The campaign's figures of merit (all rates are fractions)."""
    ok = [r for r in rows if r.get("status") == "ok"]
    stops = [r for r in ok if _kind(r) == "stop"]
    biases = [r for r in ok if _kind(r) == "bias"]
    clean = [r for r in ok if _kind(r) == "none"]
    faults = [f for r in ok for f in json.loads(r.get("faults") or "[]")]
    stop_faults = [f for f in faults if f["kind"] == "stop"]
    # eq. 46's promise: a stop in its domain (task.fault_facts: after T_s, a finite
    # prediction, at least the reference fault at onset, observable within the run), on a
    # run whose premises held, is flagged by every teammate within Δt_d,max
    domain = [
        f
        for r in ok
        if r.get("premises_held")
        for f in json.loads(r.get("faults") or "[]")
        if f.get("in_domain")
    ]
    kept = [
        f["detected_by"] >= (f.get("teammates") or 0)
        and f["delay_last"] is not None
        and f.get("dt_d_max") is not None
        and f["delay_last"] <= f["dt_d_max"] + 1e-9
        for f in domain
    ]
    delays = [r["delay_first"] for r in ok if r.get("delay_first") is not None]
    delays_last = [r["delay_last"] for r in ok if r.get("delay_last") is not None]
    robot_hours = sum(r["robots"] * r["duration"] for r in ok) / 3600.0
    false_robots = sum(r["false_alarm_robots"] for r in ok)
    dt_max = max(
        (r["dt_d_max"] for r in ok if isinstance(r.get("dt_d_max"), int | float)), default=None
    )
    excluded_stop = [r for r in stops if r["excluded_faulty"]]
    return {
        "runs": len(rows),
        "ok": len(ok),
        "failed": len(rows) - len(ok),
        "stop_runs": len(stops),
        "detection_rate": _rate([r["detected"] for r in stops]),
        # by every teammate (``detected_by`` counts teammates, the robot itself never)
        "detected_by_all_rate": _rate([r["detected_by"] >= r["robots"] - 1 for r in stops]),
        "missed": sum(not r["detected"] for r in stops),
        "bias_runs": len(biases),
        "bias_detection_rate": _rate([r["detected"] for r in biases]),
        "fault_free_runs": len(clean),
        "false_alarm_rate_per_run": _rate([r["false_alarms"] > 0 for r in ok]),
        "false_alarm_rate_fault_free": _rate([r["false_alarms"] > 0 for r in clean]),
        "false_alarms_per_robot_hour": false_robots / robot_hours if robot_hours else None,
        "wrong_isolations": sum(r["wrong_isolation"] for r in ok),
        "healthy_exclusions": sum(r.get("healthy_exclusions", 0) for r in ok),
        "false_flags": sum(r.get("false_flags", 0) for r in ok),
        "false_flags_premises_held": sum(r.get("false_flags_premises_held", 0) for r in ok),
        "false_flags_by_premise": _by_premise(ok),
        "systemic_anomalies": sum(r.get("systemic_anomalies", 0) for r in ok),
        "faults": len(faults),
        "stop_faults": len(stop_faults),
        "stop_faults_detected_rate": _rate([f["detected"] for f in stop_faults]),
        "stop_faults_excluded_rate": _rate([f["excluded"] for f in stop_faults]),
        "eq46_stops": len(domain),
        "eq46_kept": int(sum(kept)),
        "runs_premises_held": sum(bool(r.get("premises_held")) for r in ok),
        "delay_median": float(np.median(delays)) if delays else None,
        "delay_p95": float(np.percentile(delays, 95)) if delays else None,
        "delay_max": float(np.max(delays)) if delays else None,
        "delay_last_max": float(np.max(delays_last)) if delays_last else None,
        "exclusion_delay_max": max(
            (r["exclusion_delay"] for r in ok if r.get("exclusion_delay") is not None),
            default=None,
        ),
        "dt_d_max": dt_max,
        "success_after_recovery": _rate([r["success"] for r in excluded_stop]),
        "success_all": _rate([r["success"] for r in ok]),
        "margin_max": max((r["margin"] for r in ok if r.get("margin") is not None), default=None),
        **_outcomes(ok),
    }


def _outcomes(ok: list[dict[str, Any]]) -> dict[str, Any]:
    """What the missions and the faults came to (reporting/outcomes.py): the share of missions
    completed, each fault's outcome counted, and the stops that came after an earlier
    exclusion in their run (a later fault, judged by the team that was left)."""
    found = [(r, f) for r in ok for f in json.loads(r.get("fault_outcomes") or "[]")]
    counts = {o: sum(f["outcome"] == o for _, f in found) for o in OUTCOMES}
    later = []
    for r, f in found:
        gone = json.loads(r.get("fault_outcomes") or "[]")
        before = [g["excluded_at"] for g in gone if g["excluded_at"] is not None]
        if f["kind"] == "stop" and before and min(before) < f["t"]:
            later.append(f["outcome"] == "excluded")
    done = [r["mission_completed"] for r in ok if r.get("mission_completed") is not None]
    slot = [r["healthy_slot_rms"] for r in ok if r.get("healthy_slot_rms") is not None]
    return {
        "fault_outcomes": counts,
        "later_stops": len(later),
        "later_stops_excluded": int(sum(later)),
        "mission_completed_rate": _rate(done),
        "healthy_slot_rms_median": float(np.median(slot)) if slot else None,
    }


def _delays(m: dict[str, Any]) -> str:
    """A summary's first-flag delays as "median / p95 / max" (n/a without a detection)."""
    if m["delay_median"] is None:
        return "n/a"
    return f"{m['delay_median']:.2f} / {m['delay_p95']:.2f} / {m['delay_max']:.2f}"


def _kind(row: dict[str, Any]) -> str:
    """The kind of a run's main fault: from its own faults, else from what was drawn."""
    return str(row.get("main_fault_kind") or row["fault_kind"])


def _by(rows: list[dict[str, Any]], *keys: str) -> dict[tuple, list[dict[str, Any]]]:
    groups: dict[tuple, list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        groups[tuple(r[k] for k in keys)].append(r)
    return dict(sorted(groups.items()))


def write(rows: list[dict[str, Any]], out: Path, title: str, description: str = "") -> Path:
    """Write ``out/report.md`` and ``out/figures/*.png``; returns the report's path."""
    s = summarise(rows)
    figs = out / "figures"
    figs.mkdir(parents=True, exist_ok=True)
    ok = [r for r in rows if r.get("status") == "ok"]
    lines = [*_measures(s, title, description), ""]
    lines += _delay_figure(ok, s, figs)
    lines += _bias_figure(ok, figs)
    lines += _rule_table(ok)
    lines += _kind_table(ok)
    lines += _kept_table(ok)
    lines += _scale_table(ok, figs)
    lines += _network_table(ok, figs)
    lines += _method_table(ok, figs)
    path = out / "report.md"
    write_text(path, "\n".join(lines) + "\n")
    return path


def _measures(s: dict[str, Any], title: str, description: str) -> list[str]:
    """The report's title and its table of measures over every run (:func:`summarise`)."""
    rph = s["false_alarms_per_robot_hour"]
    per_hour = "n/a" if rph is None else f"{rph:.3f}"
    lines = [
        f"# Campaign {title}",
        "",
        description,
        "",
        f"{s['runs']} runs: {s['ok']} finished, {s['failed']} failed "
        "(failed runs keep their error in results.jsonl).",
        "",
        "| measure | value |",
        "|---|---|",
        f"| stop faults: detection rate (faulty robot flagged by someone) | "
        f"{_pct(s['detection_rate'])} of {s['stop_runs']} |",
        f"| stop faults: flagged by every teammate | {_pct(s['detected_by_all_rate'])} |",
        f"| missed detections (stop faults never flagged) | {s['missed']} |",
        f"| bias faults: detection rate | {_pct(s['bias_detection_rate'])} of {s['bias_runs']} |",
        f"| false alarms: runs with any healthy robot flagged | "
        f"{_pct(s['false_alarm_rate_per_run'])} |",
        f"| false alarms in fault-free runs | {_pct(s['false_alarm_rate_fault_free'])} of "
        f"{s['fault_free_runs']} |",
        f"| false alarms per robot-hour | {per_hour} |",
        f"| wrong isolations (runs where a healthy robot was excluded) | {s['wrong_isolations']} |",
        f"| healthy robots excluded (all runs) | {s['healthy_exclusions']} |",
        f"| flags on healthy robots: all / while every premise held | {s['false_flags']} / "
        f"{s['false_flags_premises_held']} |",
        "| flags on healthy robots by the premise violated then | "
        + (", ".join(f"{p} {n}" for p, n in s["false_flags_by_premise"].items()) or "none")
        + " |",
        f"| systemic anomalies (more robots flagged than fdir.max_faults) | "
        f"{s['systemic_anomalies']} |",
        f"| faults in all runs: stops flagged by a teammate / excluded | "
        f"{_pct(s['stop_faults_detected_rate'])} / {_pct(s['stop_faults_excluded_rate'])} "
        f"of {s['stop_faults']} |",
        f"| runs in which every premise held | {s['runs_premises_held']} of {s['ok']} |",
        "| stops in eq. 46's domain on those runs (after T_s, a finite prediction, at least "
        "the reference fault at onset, Δt_d,max within the run) flagged by every teammate "
        f"within Δt_d,max | "
        f"{s['eq46_kept']} of {s['eq46_stops']} |",
        f"| largest healthy residual / threshold (margin) | {_num(s['margin_max'], 3)} |",
    ]
    if s["delay_median"] is not None:
        lines.append(
            f"| detection delay, first flag: median / 95th pct / max | "
            f"{s['delay_median']:.2f} / {s['delay_p95']:.2f} / {s['delay_max']:.2f} s "
            f"(Δt_d,max up to {_num(s['dt_d_max'], 2)} s) |"
        )
        lines.append(f"| detection delay, last flag: max | {s['delay_last_max']:.2f} s |")
    lines.append(
        f"| mission success after recovery (final errors < 5 cm) | "
        f"{_pct(s['success_after_recovery'])} |"
    )
    counts = s["fault_outcomes"]
    lines += [
        "| faults: excluded / detected, not excluded / compensated / missed / undecided | "
        + " / ".join(str(counts[o]) for o in OUTCOMES)
        + " |",
        f"| stops after an earlier exclusion in their run: excluded | "
        f"{s['later_stops_excluded']} of {s['later_stops']} |",
        f"| missions completed (the survivors in formation, within tolerance, at the end) | "
        f"{_pct(s['mission_completed_rate'])} |",
        f"| healthy robots' distance from their slots after the transient: median of runs' "
        f"rms | {_num(s['healthy_slot_rms_median'], 4)} m |",
    ]
    return lines


def _delay_figure(ok: list[dict[str, Any]], s: dict[str, Any], figs: Path) -> list[str]:
    """The histogram of first-detection delays (``figs/delays.png``) and its line."""
    lines: list[str] = []
    if ok and any(r["delay_first"] is not None for r in ok):
        d = [r["delay_first"] for r in ok if r["delay_first"] is not None]
        fig, ax = new_figure(figsize=(6, 3.5))
        ax.hist(d, bins=min(30, max(5, len(d) // 2)), color="tab:blue")
        if s["dt_d_max"]:
            ax.axvline(s["dt_d_max"], color="k", ls="--", label="Δt_d,max")
            ax.legend()
        ax.set_xlabel("first detection − fault [s]")
        ax.set_ylabel("runs")
        ax.set_title("Detection delay")
        _save(fig, figs / "delays.png")
        lines += ["![detection delays](figures/delays.png)", ""]
    return lines


def _bias_figure(ok: list[dict[str, Any]], figs: Path) -> list[str]:
    """Detection against bias magnitude (``figs/bias_detection.png``) and its lines."""
    lines: list[str] = []
    biases = [r for r in ok if r["fault_kind"] == "bias"]
    if biases:
        mags = np.array([r["bias_magnitude"] for r in biases])
        hit = np.array([r["detected"] for r in biases], float)
        edges = np.linspace(mags.min(), mags.max() + 1e-9, min(10, len(biases)) + 1)
        idx = np.clip(np.digitize(mags, edges) - 1, 0, len(edges) - 2)
        centre = (edges[:-1] + edges[1:]) / 2
        rate = [hit[idx == b].mean() if (idx == b).any() else np.nan for b in range(len(centre))]
        fig, ax = new_figure(figsize=(6, 3.5))
        ax.plot(centre, rate, "o-")
        ax.set_xlabel("bias magnitude [m/s]")
        ax.set_ylabel("detection rate")
        ax.set_ylim(-0.05, 1.05)
        ax.set_title("Detection against bias magnitude")
        _save(fig, figs / "bias_detection.png")
        smallest = mags[hit > 0].min() if hit.any() else None
        largest_missed = mags[hit == 0].max() if (hit == 0).any() else None
        lines += [
            f"Smallest bias detected: {'none' if smallest is None else f'{smallest:.3f} m/s'}; "
            f"largest bias missed: "
            f"{'none' if largest_missed is None else f'{largest_missed:.3f} m/s'}.",
            "",
            "![bias detection](figures/bias_detection.png)",
            "",
        ]
    return lines


def _bias_limits(rows: list[dict[str, Any]]) -> tuple[float | None, float | None]:
    """Smallest bias detected and largest bias missed among bias runs."""
    hit = [r["bias_magnitude"] for r in rows if r["fault_kind"] == "bias" and r["detected"]]
    miss = [r["bias_magnitude"] for r in rows if r["fault_kind"] == "bias" and not r["detected"]]
    return (min(hit) if hit else None), (max(miss) if miss else None)


def _rule(r: dict[str, Any]) -> str:
    """A row's threshold rule, named with its method where the campaign compares methods:
    two methods that share a rule (with and without detection, say) stay apart."""
    rule = r.get("thresholds") or "paper"
    return f"{r['method']}: {rule}" if "method" in r else rule


def _rule_table(ok: list[dict[str, Any]]) -> list[str]:
    """The campaign's measures per threshold rule, when its runs used several."""
    groups = _by([{**r, "thresholds": _rule(r)} for r in ok], "thresholds")
    if len(groups) <= 1:
        return []
    lines = [
        "| rule | runs | stops detected | by all | first flag: median / p95 / max [s] | "
        "biases detected | smallest detected / largest missed bias [m/s] | runs with a "
        "false alarm | false alarms per robot-hour | margin |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (rule,), rs in groups.items():
        m = summarise(rs)
        d = _delays(m)
        hit, miss = _bias_limits(rs)
        lines.append(
            f"| {rule} | {len(rs)} | {_pct(m['detection_rate'])} | "
            f"{_pct(m['detected_by_all_rate'])} | {d} | {_pct(m['bias_detection_rate'])} | "
            f"{_num(hit, 3)} / {_num(miss, 3)} | {_pct(m['false_alarm_rate_per_run'])} | "
            f"{_num(m['false_alarms_per_robot_hour'], 3)} | {_num(m['margin_max'], 3)} |"
        )
    return [*lines, ""]


def _kind_table(ok: list[dict[str, Any]]) -> list[str]:
    """Detection and isolation per fault kind drawn (per rule), when a campaign drew several:
    what the FDI does with each kind of the fault zoo."""
    rows = [{**r, "thresholds": _rule(r)} for r in ok]
    groups = _by(rows, "fault_kind", "thresholds")
    if len({k[0] for k in groups}) <= 1:
        return []
    lines = [
        "| fault kind | rule | runs | faulty robot flagged by a teammate | by all | first "
        "flag: median / max [s] | excluded | healthy flags: all / premises held | healthy "
        "excluded |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for (kind, rule), rs in groups.items():
        faulty = [r for r in rs if r.get("main_fault_kind") not in (None, "none")]
        delays = [r["delay_first"] for r in faulty if r.get("delay_first") is not None]
        m = summarise(rs)
        d = f"{np.median(delays):.2f} / {max(delays):.2f}" if delays else "n/a"
        lines.append(
            f"| {kind} | {rule} | {len(rs)} | "
            f"{_pct(_rate([r['detected'] for r in faulty]))} | "
            f"{_pct(_rate([r['detected_by'] >= r['robots'] - 1 for r in faulty]))} | {d} | "
            f"{_pct(_rate([r['excluded_faulty'] for r in faulty]))} | "
            f"{m['false_flags']} / {m['false_flags_premises_held']} | "
            f"{m['healthy_exclusions']} |"
        )
    return [*lines, ""]


#: what each ``kept_why`` of :func:`~.task.kept_why` means, in the report's words
KEPT_WORDS = {
    "never_flagged": "no teammate flagged it",
    "due_after_end": "its t_r (first flag + Δt_d,max) came after the end",
    "run_stopped": "the run stopped before its t_r",
    "cancelled_not_flagged": "nobody flagged it any more at its t_r",
    "cancelled_flagged_only_by_itself": "only it flagged itself at its t_r",
    "cancelled_systemic_anomaly": "a systemic anomaly held at its t_r (more robots flagged "
    "than fdir.max_faults)",
    "postponed_contact": "postponed by a contact",
    "postponed_decaying": "postponed: its flags were a contact's decaying trace",
    "postponed_estimate": "postponed: its own fault estimate never left its bound",
}


def _kept_table(ok: list[dict[str, Any]]) -> list[str]:
    """The faulty robots still in the team when their run ended, by why (each fault's
    ``kept_why``) and fault kind: what the recovery said of each."""
    faults = [f for r in ok for f in json.loads(r.get("faults") or "[]")]
    kept = [f for f in faults if f.get("kept_why")]
    if not kept:
        return []
    kinds = sorted({f["kind"] for f in faults})
    lines = [
        "Faulty robots still in the team at the end of their run, by why (of "
        f"{len(faults)} faults):",
        "",
        "| why | " + " | ".join(kinds) + " |",
        "|---|" + "---|" * len(kinds),
    ]
    for why in sorted({f["kept_why"] for f in kept}):
        counts = [sum(f["kind"] == k and f["kept_why"] == why for f in kept) for k in kinds]
        words = KEPT_WORDS.get(why, why.replace("_", " "))
        lines.append(f"| {words} | " + " | ".join(str(c) for c in counts) + " |")
    return [*lines, ""]


def _scale_table(ok: list[dict[str, Any]], figs: Path) -> list[str]:
    """Stop detection by threshold rule, team size and graph family, with the figure."""
    stops = [{**r, "thresholds": _rule(r)} for r in ok if r["fault_kind"] == "stop"]
    groups = _by(stops, "thresholds", "robots", "graph_family")
    if len(groups) <= 1:
        return []
    lines = [
        "| rule | N | graph | stop runs | detected | by all | first flag: median / p95 / max "
        "[s] | last flag: max [s] | excluded: max [s] | false alarms per robot-hour | margin |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (rule, n, fam), rs in groups.items():
        s = summarise(rs)
        d = _delays(s)
        lines.append(
            f"| {rule} | {n} | {fam} | {len(rs)} | {_pct(s['detection_rate'])} | "
            f"{_pct(s['detected_by_all_rate'])} | {d} | {_num(s['delay_last_max'], 2)} | "
            f"{_num(s['exclusion_delay_max'], 2)} | "
            f"{_num(s['false_alarms_per_robot_hour'], 2)} | {_num(s['margin_max'], 2)} |"
        )
    fig, axes = new_figure(figsize=(9, 3.5), ncols=2)
    for rule, fam in sorted({(k[0], k[2]) for k in groups}):
        ns = sorted(k[1] for k in groups if k[0] == rule and k[2] == fam)
        rates = [np.mean([r["detected"] for r in groups[(rule, n, fam)]]) for n in ns]
        med = [
            np.median([r["delay_first"] for r in groups[key] if r["detected"]] or [np.nan])
            for key in ((rule, n, fam) for n in ns)
        ]
        axes[0].plot(ns, rates, "o-", label=f"{rule}, {fam}")
        axes[1].plot(ns, med, "o-", label=f"{rule}, {fam}")
    axes[0].set_ylabel("stop detection rate")
    axes[0].set_ylim(-0.05, 1.05)
    axes[1].set_ylabel("median first-flag delay [s]")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_xlabel("N")
    axes[1].legend(fontsize=7)
    fig.suptitle("Detection against team size, graph and threshold rule")
    _save(fig, figs / "scale.png")
    return [*lines, "", "![scale](figures/scale.png)", ""]


#: the network's factors a campaign may vary (dotted keys), in the table's order
NETWORK_KEYS = ("network.latency", "network.loss")


def _network_table(ok: list[dict[str, Any]], figs: Path) -> list[str]:
    """Detection and false alarms per threshold rule against the network's latency and
    loss, with the figure ("how much network can DFTC take"), when a campaign varies them."""
    if not any(k in r for r in ok for k in NETWORK_KEYS):
        return []
    rows = [
        {
            **r,
            "thresholds": _rule(r),
            **{k: float(r.get(k, 0.0)) for k in NETWORK_KEYS},
        }
        for r in ok
    ]
    groups = _by(rows, "thresholds", *NETWORK_KEYS)
    lines = [
        "| rule | latency [s] (drawn) | loss (drawn) | R [periods] | measured: loss / largest "
        "delay [s] | runs | stops detected | by all | first flag: median / max [s] | last flag: "
        "max [s] | runs with a false alarm | healthy flags: all / premises held | healthy "
        "excluded | network premise broken (runs) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (rule, lat, loss), rs in groups.items():
        m = summarise(rs)
        d = (
            "n/a"
            if m["delay_median"] is None
            else f"{m['delay_median']:.2f} / {m['delay_max']:.2f}"
        )
        broken = sum("network" in json.loads(r.get("premises_violated") or "[]") for r in rs)
        rounds = sorted({int(r.get("round_periods") or 1) for r in rs})
        measured = [r["loss_measured"] for r in rs if r.get("loss_measured") is not None]
        late = [r["delay_max_measured"] for r in rs if r.get("delay_max_measured") is not None]
        seen = (
            f"{_pct(float(np.mean(measured)) if measured else None)} / "
            f"{_num(max(late) if late else None, 3)}"
        )
        lines.append(
            f"| {rule} | {lat:g} | {loss:g} | {', '.join(map(str, rounds))} | {seen} | "
            f"{len(rs)} | {_pct(m['detection_rate'])} | "
            f"{_pct(m['detected_by_all_rate'])} | {d} | {_num(m['delay_last_max'], 2)} | "
            f"{_pct(m['false_alarm_rate_per_run'])} | {m['false_flags']} / "
            f"{m['false_flags_premises_held']} | {m['healthy_exclusions']} | {broken} |"
        )
    fig, axes = new_figure(figsize=(9, 3.5), ncols=2)
    for rule in sorted({k[0] for k in groups}):
        for lat in sorted({k[1] for k in groups if k[0] == rule}):
            keys = sorted(k for k in groups if k[0] == rule and k[1] == lat)
            loss = [k[2] for k in keys]
            med = [summarise(groups[k])["delay_median"] for k in keys]
            alarm = [summarise(groups[k])["false_alarm_rate_per_run"] for k in keys]
            label = f"{rule}, {1000 * lat:g} ms"
            style = "o-" if rule == "l1" else "s--"
            axes[0].plot(loss, [np.nan if v is None else v for v in med], style, label=label)
            axes[1].plot(loss, [np.nan if v is None else v for v in alarm], style, label=label)
    axes[0].set_ylabel("median first-flag delay of a stop [s]")
    axes[1].set_ylabel("runs with a healthy robot flagged")
    axes[1].set_ylim(-0.05, 1.05)
    for ax in axes:
        ax.set_xlabel("message loss probability")
    axes[0].legend(fontsize=7)
    fig.suptitle("How much network DFTC takes: detection and false alarms against latency and loss")
    _save(fig, figs / "network.png")
    return [*lines, "", "![network](figures/network.png)", ""]


def _method_table(ok: list[dict[str, Any]], figs: Path) -> list[str]:
    """The campaign's ``[methods]`` side by side: each met the same draws (seeds, layouts,
    faults), so their rows differ by the method only; with the figure."""
    if not any("method" in r for r in ok):
        return []
    groups = _by(ok, "method")
    lines = [
        "Methods side by side (each on the same draws: seeds, start layouts and faults):",
        "",
        "| method | runs | stops detected | by all | first flag: median / p95 / max [s] | "
        "last flag: max [s] | excluded: max [s] | biases detected | healthy flags: all / "
        "premises held | by premise | healthy excluded | final formation error: median [m] | "
        "estimation error: largest, median over runs [m] | missions completed | faults: "
        "excluded / detected / compensated / missed / undecided |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (name,), rs in groups.items():
        m = summarise(rs)
        d = _delays(m)
        formation = [r["final_formation"] for r in rs if r.get("final_formation") is not None]
        est = [r["estimation_error_max"] for r in rs if r.get("estimation_error_max") is not None]
        premise = ", ".join(f"{p} {n}" for p, n in m["false_flags_by_premise"].items()) or "none"
        lines.append(
            f"| {name} | {len(rs)} | {_pct(m['detection_rate'])} | "
            f"{_pct(m['detected_by_all_rate'])} | {d} | {_num(m['delay_last_max'], 2)} | "
            f"{_num(m['exclusion_delay_max'], 2)} | {_pct(m['bias_detection_rate'])} | "
            f"{m['false_flags']} / {m['false_flags_premises_held']} | {premise} | "
            f"{m['healthy_exclusions']} | "
            f"{_num(float(np.median(formation)) if formation else None, 3)} | "
            f"{_num(float(np.median(est)) if est else None, 3)} | "
            f"{_pct(m['mission_completed_rate'])} | "
            + " / ".join(str(m["fault_outcomes"][o]) for o in OUTCOMES)
            + " |"
        )
    fig, axes = new_figure(figsize=(9, 3.5), ncols=2)
    names = [k[0] for k in groups]
    delays = [
        [r["delay_first"] for r in groups[(k,)] if r.get("delay_first") is not None] for k in names
    ]
    axes[0].boxplot([d or [np.nan] for d in delays], tick_labels=names)
    axes[0].set_ylabel("first flag after the fault [s]")
    axes[0].set_title("Detection delay")
    flags = [summarise(groups[(k,)])["false_flags"] for k in names]
    axes[1].bar(names, flags, color="tab:red")
    axes[1].set_ylabel("flags on healthy robots")
    axes[1].set_title("False flags")
    fig.suptitle("Methods on the same draws")
    _save(fig, figs / "methods.png")
    return [*lines, "", "![methods](figures/methods.png)", ""]


def _save(fig, path: Path) -> None:
    fig.tight_layout()
    atomic_write(path, lambda fh: fig.savefig(fh, dpi=100, format="png"))
