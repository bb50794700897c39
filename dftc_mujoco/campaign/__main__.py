"""``python -m dftc_mujoco.campaign SPEC.toml [--workers N] [--ray [ADDRESS]] [--out DIR]``.

Runs a Monte-Carlo campaign (see :mod:`dftc_mujoco.campaign.spec`), appending
each finished run to ``DIR/results.jsonl`` and ``DIR/results.parquet``, and
writes ``DIR/report.md`` with its figures. Running it again resumes: runs
already recorded are skipped. Exit codes: 0, 2 bad input.
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

from .. import cli
from ..errors import ScenarioError


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    p = cli.parser("dftc_mujoco.campaign", "dftc-campaign", "Run a Monte-Carlo fault campaign.")
    p.add_argument("spec", type=Path, help="campaign spec (TOML), e.g. campaigns/stop_faults.toml")
    p.add_argument(
        "--workers",
        type=int,
        default=os.cpu_count() or 1,
        help="local worker processes (default: the CPU count)",
    )
    p.add_argument(
        "--ray",
        nargs="?",
        const="",
        default=None,
        metavar="ADDRESS",
        help="run on Ray: a local instance, or the cluster at ADDRESS",
    )
    p.add_argument("--out", type=Path, help="results folder (default: ./renders/campaigns/NAME)")
    p.add_argument("--runs", type=int, help="override the spec's number of runs")
    p.add_argument("--limit", type=int, help="stop after this many new runs (resume later)")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    args = p.parse_args(argv)
    from . import report, runner
    from . import spec as spec_mod

    try:
        spec = spec_mod.load(args.spec)
        if args.runs is not None:
            if args.runs < 1:
                raise ScenarioError(f"--runs: expected at least 1, got {args.runs}")
            import dataclasses

            spec = dataclasses.replace(spec, runs=args.runs)
        if args.limit is not None and args.limit < 1:
            raise ScenarioError(f"--limit: expected at least 1, got {args.limit}")
        if args.workers < 1:
            raise ScenarioError(f"--workers: expected at least 1, got {args.workers}")
        out = args.out or Path.cwd() / "renders" / "campaigns" / spec.name
        out.mkdir(parents=True, exist_ok=True)
        if args.spec.resolve() != (out / "spec.toml").resolve():
            shutil.copyfile(args.spec, out / "spec.toml")
        before = len(runner.Results(out).rows)
        results = runner.run(
            spec,
            out,
            workers=args.workers,
            ray_address=False if args.ray is None else args.ray,
            progress=not args.no_progress and sys.stderr.isatty(),
            limit=args.limit,
        )
    except ScenarioError as exc:
        cli.print_error(exc)
        return 2
    rows = [r for r in results.rows if r["run"] < spec.runs]
    path = report.write(rows, out, spec.name, spec.description)
    failed = sum(r.get("status") == "failed" for r in rows)
    print(
        f"{spec.name}: {len(rows)}/{spec.runs} runs recorded ({len(rows) - before} new, "
        f"{failed} failed) in {out}"
    )
    print(f"report: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
