"""Executing a campaign: one row per run, appended as each run finishes.

Results live in ``OUT/results.jsonl`` (one JSON object per line, appended and
fsync'ed as soon as a run finishes: the source of truth) and
``OUT/results.parquet`` (the same rows, columnar, rewritten atomically after
each run). Running a campaign again skips every run already in the JSON lines
(a torn last line from a crash is dropped). Engines: ``local`` (a process
pool), ``ray`` (``ray.init(address=...)``); the rows do not depend on the engine.
"""

from __future__ import annotations

import json
import os
import time
import traceback
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from tqdm.auto import tqdm

from .spec import Spec, draw, scenario_for

TIMING_COLUMNS = ("wall_time",)


def run_one(spec: Spec, params: dict[str, Any]) -> dict[str, Any]:
    """Simulate one run and reduce it to a row of facts; never raises."""
    from ..loop import simulate

    t0 = time.perf_counter()
    row: dict[str, Any] = dict(params)
    try:
        s = scenario_for(spec, params)
        result = simulate(s, search=spec_folders(spec))
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


def _facts(p: dict[str, Any], summary: dict[str, Any], dt_d_max: float) -> dict[str, Any]:
    faulty = p.get("faulty_robot")
    det = summary["detections"]
    on_faulty = [d for d in det if d["robot"] == faulty]
    false_pairs = [d for d in det if d["robot"] != faulty]
    excluded = [e["robot"] for e in summary["exclusions"]]
    err = summary["errors"]
    first = min((d["t"] for d in on_faulty), default=None)
    last = max((d["t"] for d in on_faulty), default=None)
    t_f = p.get("fault_t")
    return {
        "detected": bool(on_faulty),
        "detected_by": len({d["by"] for d in on_faulty}),
        "delay_first": None if first is None or t_f is None else first - t_f,
        "delay_last": None if last is None or t_f is None else last - t_f,
        "dt_d_max": dt_d_max,
        "false_alarms": len(false_pairs),
        "false_alarm_robots": len({d["robot"] for d in false_pairs}),
        "excluded": json.dumps(excluded),
        "excluded_faulty": faulty in excluded,
        "wrong_isolation": any(r != faulty for r in excluded),
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
        text = self.jsonl.read_text()
        for line in text.splitlines():
            try:
                row = json.loads(line)
            except json.JSONDecodeError:
                continue  # a line torn by a crash: that run is run again
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


def _local(spec: Spec, todo: list[dict[str, Any]], workers: int) -> Iterator[dict[str, Any]]:
    if workers <= 1:
        for p in todo:
            yield run_one(spec, p)
        return
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as pool:
        futures = [pool.submit(run_one, spec, p) for p in todo]
        for f in as_completed(futures):
            yield f.result()


def _ray(
    spec: Spec, todo: list[dict[str, Any]], address: str | None, workers: int
) -> Iterator[dict[str, Any]]:
    try:
        import ray
    except ImportError:
        from ..errors import ScenarioError

        raise ScenarioError(
            "--ray: Ray is not installed; install the cluster extra: pip install -e '.[cluster]'"
        ) from None
    started_here = not ray.is_initialized()
    if started_here:
        kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False}
        if address:
            ray.init(address=address, **kwargs)
        else:
            ray.init(num_cpus=workers if workers > 0 else None, **kwargs)
    try:
        remote = ray.remote(num_cpus=1)(run_one)
        spec_ref = ray.put(spec)
        pending = [remote.remote(spec_ref, p) for p in todo]
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            yield ray.get(ready[0])
    finally:
        if started_here:
            ray.shutdown()


def run(
    spec: Spec,
    out: Path,
    *,
    workers: int = 2,
    ray_address: str | bool | None = False,
    progress: bool = True,
    on_row: Callable[[dict[str, Any]], None] | None = None,
    limit: int | None = None,
) -> Results:
    """Run every run of ``spec`` not yet in ``out``; returns the results.

    ``ray_address``: False for the local pool, None (or "") for a local Ray
    instance, or a cluster address. ``limit`` stops after that many new runs
    (to split a campaign in parts).
    """
    results = Results(out)
    done = results.done()
    todo = [draw(spec, i) for i in range(spec.runs) if i not in done]
    if limit is not None:
        todo = todo[:limit]
    if ray_address is False:
        rows = _local(spec, todo, workers)
    else:
        rows = _ray(spec, todo, ray_address or None, workers)
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
            failures += row.get("status") == "failed"
            bar.set_postfix(failures=failures)
            bar.update(1)
            if on_row is not None:
                on_row(row)
    finally:
        bar.close()
    return results
