"""Executing a campaign: one row per run, appended as each run finishes.

Results live in ``OUT/results.jsonl`` (one JSON object per line, appended and
fsync'ed as soon as a run finishes: the source of truth) and
``OUT/results.parquet`` (the same rows, columnar, rewritten atomically after
each run). Running a campaign again skips every run already in the JSON lines
(a torn last line from a crash is dropped). Engines: one run after another in
this process (one worker), local worker processes (:mod:`pool`) or Ray
(:mod:`cluster`); the rows do not depend on the engine. A stop request (a SIGINT or
SIGTERM caught by the command line) ends the campaign within a second or so: queued
runs are not started, running ones are ended and not recorded, finished ones are all
kept.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
import traceback
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tqdm.auto import tqdm

from .spec import Spec, draw, scenario_for

if TYPE_CHECKING:
    from ..interrupt import Signals
    from .cluster import Connection

TIMING_COLUMNS = ("wall_time",)


def run_one(spec: Spec, params: dict[str, Any], signals: Signals | None = None) -> dict[str, Any]:
    """Simulate one run and reduce it to a row of facts; never raises (a signal caught by
    ``signals`` stops the simulation: the row then says "interrupted")."""
    from ..loop import Simulation

    t0 = time.perf_counter()
    row: dict[str, Any] = dict(params)
    try:
        s = scenario_for(spec, params)
        with Simulation(s, search=spec_folders(spec)) as sim:
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
    horizon = summary.get("dt_d_max") if isinstance(summary.get("dt_d_max"), dict) else {}
    settle = horizon.get("settle_time")  # T_s (None: not within the run)
    n = int(summary.get("robots") or 0)
    end = float(summary.get("simulated_time") or summary.get("duration") or 0.0)
    out = []
    for f in (e for e in events if e["kind"] == "fault"):
        robot, t_f = f["robot"], f["t"]
        gone_before = sum(1 for e in summary["exclusions"] if e["t"] < t_f)
        dt = horizon.get("value")
        # eq. 46 predicted a finite delay (not the 5 s fallback) on the graph of the moment
        promised = horizon.get("predicted_delays_max") is not None
        for e in events:  # Δt_d,max as recomputed by the exclusions before the fault
            if e["kind"] == "detection_horizon" and e["t"] < t_f:
                dt = e["value"]
        for later in horizon.get("after_exclusions", []):
            if later["t"] < t_f:
                promised = later.get("predicted_delays_max") is not None
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
                "after_settle": settle is not None and t_f >= settle,  # eq. 46's domain
                "dt_d_max": dt,
                "command": told,
                # eq. 46's promise applies: a finite prediction, a stop at least the reference
                # fault at onset, after T_s, and Δt_d,max ends within the run (observable)
                "in_domain": bool(
                    promised
                    and settle is not None
                    and t_f >= settle
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


def _facts(p: dict[str, Any], summary: dict[str, Any], dt_d_max: float) -> dict[str, Any]:
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
        "settle_time": (horizon or {}).get("settle_time") if isinstance(horizon, dict) else None,
        "final_centroid": err["final_centroid"],
        "final_formation": err["final_formation"],
        "success": bool(
            summary["status"] == "ok"
            and err["final_centroid"] is not None
            and err["final_centroid"] < 0.05
            and err["final_formation"] < 0.05
        ),
        "margin": summary.get("margin"),
        "min_obstacle_clearance": summary["min_obstacle_clearance"],
        "warnings": len(summary["warnings"]),
        "onboard_path": summary.get("onboard", {}).get("path"),
        "thresholds": summary.get("onboard", {}).get("blocks", {}).get("thresholds"),
        "blocks": json.dumps(summary.get("onboard", {}).get("blocks", {}), sort_keys=True),
        "duration": summary["duration"],
    }


# --------------------------------------------------------------------------- the store


class Results:
    """The campaign's results folder: JSON lines (appended) and Parquet (rewritten)."""

    def __init__(self, out: Path) -> None:
        self.out = out
        self.jsonl = out / "results.jsonl"
        self.parquet = out / "results.parquet"
        out.mkdir(parents=True, exist_ok=True)
        self.rows = self._read()

    def _read(self) -> list[dict[str, Any]]:
        if not self.jsonl.exists():
            return []
        rows, good = [], []
        # bytes that are not UTF-8 (a torn write) make their line unreadable, not the file
        text = self.jsonl.read_bytes().decode("utf-8", errors="replace")
        for line in text.splitlines():
            try:
                row = json.loads(line)
            except json.JSONDecodeError:
                continue  # a line torn by a crash: that run is run again
            if not isinstance(row, dict) or "run" not in row:
                continue  # not a row of ours
            if row.get("run") in {r["run"] for r in rows}:
                continue
            rows.append(row)
            good.append(line)
        cleaned = "".join(g + "\n" for g in good)
        if cleaned != text:  # drop torn or duplicate lines before appending more
            tmp = self.jsonl.with_suffix(".jsonl.tmp")
            tmp.write_text(cleaned)
            os.replace(tmp, self.jsonl)
        return rows

    def done(self) -> set[int]:
        return {r["run"] for r in self.rows}

    def append(self, row: dict[str, Any]) -> None:
        """Record one finished run: JSON line first (fsync), then the Parquet copy."""
        with open(self.jsonl, "a") as fh:
            fh.write(json.dumps(row, default=float) + "\n")
            fh.flush()
            os.fsync(fh.fileno())
        self.rows.append(row)
        self.write_parquet()

    def write_parquet(self) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        rows = sorted(self.rows, key=lambda r: r["run"])
        keys = sorted({k for r in rows for k in r})
        table = pa.table({k: [r.get(k) for r in rows] for k in keys})
        tmp = self.parquet.with_suffix(".parquet.tmp")
        pq.write_table(table, tmp)
        os.replace(tmp, self.parquet)


# --------------------------------------------------------------------------- engines


@dataclass
class Outcome:
    """How :func:`run` ended: ``stopped_by`` the signal that stopped it (or None), with
    the runs that were ``running`` (ended, not recorded) and ``queued`` (not started)."""

    new: int = 0
    stopped_by: int | None = None
    running: int = 0
    queued: int = 0
    engine: str = "local"


def _here(
    spec: Spec, todo: list[dict[str, Any]], signals: Signals | None, outcome: Outcome
) -> Iterator[dict[str, Any]]:
    """One run after another in this process."""
    for i, p in enumerate(todo):
        if signals is not None and signals.signum is not None:
            outcome.queued = len(todo) - i
            return
        row = run_one(spec, p, signals)
        if row.get("status") == "interrupted":
            outcome.running = 1
            outcome.queued = len(todo) - i - 1
            return
        yield row


def run(
    spec: Spec,
    out: Path,
    *,
    workers: int = 2,
    ray_address: str | bool | Connection | None = False,
    progress: bool = True,
    on_row: Callable[[dict[str, Any]], None] | None = None,
    limit: int | None = None,
    signals: Signals | None = None,
    outcome: Outcome | None = None,
) -> Results:
    """Run every run of ``spec`` not yet in ``out``; returns the results.

    ``ray_address``: False for local workers (``workers`` of them; 1 runs in this
    process), None (or "") for the local Ray instance or a new one, a cluster
    address, or a :class:`~dftc_mujoco.campaign.cluster.Connection` already made
    (left at the end either way). ``limit`` stops after that many new runs (to split a
    campaign in parts).
    ``signals`` (:class:`dftc_mujoco.interrupt.Signals`): a signal it catches stops
    the campaign early, keeping every finished run; ``outcome`` (an :class:`Outcome`)
    is filled in with how it ended.
    """
    outcome = outcome if outcome is not None else Outcome()
    results = Results(out)
    done = results.done()
    todo = [draw(spec, i) for i in range(spec.runs) if i not in done]
    if limit is not None:
        todo = todo[:limit]

    def stop() -> bool:
        return signals is not None and signals.signum is not None

    engine: Any = None
    connection = None
    if ray_address is not False:
        from . import cluster

        if isinstance(ray_address, cluster.Connection):
            connection = ray_address  # joined by the caller (before preparing the folder)
        else:
            connection = cluster.connect(ray_address or None, workers)
        if signals is not None:
            signals.install()  # ray.init replaces the SIGTERM handler with its own
        engine = cluster.RayRuns(spec, stop)
        rows: Iterator[dict[str, Any]] = engine.rows(todo)
        outcome.engine = f"Ray at {connection.address}"
    elif workers > 1 and len(todo) > 1:
        from .pool import Pool

        engine = Pool(spec, workers, stop)
        rows = engine.rows(todo)
        outcome.engine = f"{min(workers, len(todo))} local workers"
    else:
        rows = _here(spec, todo, signals, outcome)
        outcome.engine = "this process"
    failures = sum(r.get("status") == "failed" for r in results.rows)
    bar = tqdm(
        total=spec.runs,
        initial=len(done),
        disable=not progress,
        unit="run",
        desc=spec.name,
        dynamic_ncols=True,
    )
    try:
        for row in rows:
            results.append(row)
            outcome.new += 1
            failures += row.get("status") == "failed"
            bar.set_postfix(failures=failures)
            bar.update(1)
            if on_row is not None:
                on_row(row)
    finally:
        rows.close()  # ends the workers (or cancels the Ray tasks) at once
        bar.close()
        if connection is not None:
            from . import cluster

            cluster.disconnect(connection)
    if stop():
        outcome.stopped_by = signals.signum if signals is not None else None
        if engine is not None and hasattr(engine, "running"):
            outcome.running, outcome.queued = engine.running, engine.queued
        elif engine is not None:
            outcome.queued = engine.cancelled
    return results
