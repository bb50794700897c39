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

import json
import os
from collections.abc import Callable, Generator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tqdm.auto import tqdm

from ..runtime.atomic import atomic_write, write_text
from .spec import Spec, draw
from .task import fault_facts, run_one, spec_folders

__all__ = ["Outcome", "Results", "fault_facts", "run", "run_one", "spec_folders"]

if TYPE_CHECKING:
    from ..runtime.interrupt import Signals
    from .cluster import Connection

TIMING_COLUMNS = ("wall_time",)


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
        rows: list[dict[str, Any]] = []
        good: list[str] = []
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
            write_text(self.jsonl, cleaned)
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
        atomic_write(self.parquet, lambda fh: pq.write_table(table, fh))


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
) -> Generator[dict[str, Any], None, None]:
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
    ``signals`` (:class:`dftc_mujoco.runtime.interrupt.Signals`): a signal it catches stops
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
            address = ray_address if isinstance(ray_address, str) and ray_address else None
            connection = cluster.connect(address, workers)
        if signals is not None:
            signals.install()  # ray.init replaces the SIGTERM handler with its own
        engine = cluster.RayRuns(spec, stop)
        rows: Generator[dict[str, Any], None, None] = engine.rows(todo)
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
