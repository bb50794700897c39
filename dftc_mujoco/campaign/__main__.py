"""``python -m dftc_mujoco.campaign SPEC.toml [--workers N] [--ray [ADDRESS]] [--out DIR]``.

Runs a Monte-Carlo campaign (see :mod:`dftc_mujoco.campaign.spec`), appending
each finished run to ``DIR/results.jsonl`` and ``DIR/results.parquet``, and
writes ``DIR/report.md`` with its figures. Running it again resumes: runs
already recorded are skipped. The folder belongs to one campaign
(:mod:`dftc_mujoco.campaign.folder`): another spec is refused unless ``--overwrite``.
SIGINT (Ctrl-C) or SIGTERM stops it within seconds, keeping every finished run and
an up-to-date report. Exit codes: 0 done, 2 bad input (the spec, its base scenario,
the options), 5 an output, disk or OS problem (the folder is a file, holds something
else or another campaign, is being written by another process, the disk is full, Ray
is missing or the cluster cannot be joined), 130 / 143 interrupted by SIGINT / SIGTERM.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
from pathlib import Path
from typing import Any

from ..errors import EXIT_INPUT, EXIT_OK, EXIT_OUTPUT, EXIT_PHYSICS, OutputError, ScenarioError
from ..runtime import cli, interrupt, output
from ..runtime.interrupt import Interrupted, Signals


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    p = cli.parser(
        "dftc_mujoco.campaign",
        "dftc-campaign",
        "Run a Monte-Carlo fault campaign: many runs of a scenario with drawn faults, starts "
        "and seeds, and a report of what the fault detection made of them.",
        epilog="""\
examples:
  %(prog)s campaigns/tiny.toml                 a small campaign, on this machine's cores
  %(prog)s campaigns/stop_faults.toml --workers 2 --limit 10   (run again to resume)
  %(prog)s campaigns/stop_faults.toml --ray    on Ray (pip install -e ".[cluster]")

Documentation: the project's docs/ folder (campaigns: every key of a spec).
""",
    )
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
        help="run on Ray: alone, the Ray instance running here (ray start --head) or a new "
        "private one with --workers CPUs; or the cluster at ADDRESS (HOST:PORT, or "
        "ray://HOST:PORT with the cluster extra)",
    )
    p.add_argument(
        "--ray-timeout",
        type=float,
        default=None,
        metavar="SECONDS",
        help="give joining the cluster this long before giving up (default: 60; a ray:// "
        "client starts a server per driver, tens of seconds on a busy head node)",
    )
    p.add_argument("--out", type=Path, help="results folder (default: ./renders/campaigns/NAME)")
    p.add_argument("--runs", type=int, help="override the spec's number of runs")
    p.add_argument(
        "--seed",
        type=int,
        help="override the spec's campaign seed: a new draw of the same battery (default "
        "folder: ./renders/campaigns/NAME_seedSEED)",
    )
    p.add_argument("--limit", type=int, help="stop after this many new runs (resume later)")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="start over: replace the campaign folder as a whole, whichever campaign it holds "
        "(never a folder that holds no campaign); without it the same spec resumes",
    )
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    args = p.parse_args(argv)
    return interrupt.guarded(
        lambda signals: _main(args, signals),
        " before the campaign started: no run was started",
    )


def _checked(args: argparse.Namespace, spec: Any) -> Any:
    """The campaign ``spec`` with the command line's --runs and --seed, once every option
    is checked (one line each for what cannot run; a note for more workers than CPUs)."""
    if args.runs is not None:
        if args.runs < 1:
            raise ScenarioError(f"--runs: expected at least 1, got {args.runs}")
        spec = dataclasses.replace(spec, runs=args.runs)
    if args.seed is not None:
        if not 0 <= args.seed <= 2**63 - 1:
            raise ScenarioError(f"--seed: expected an integer from 0 to 2**63 - 1, got {args.seed}")
        spec = dataclasses.replace(spec, seed=args.seed)
    if args.limit is not None and args.limit < 1:
        raise ScenarioError(f"--limit: expected at least 1, got {args.limit}")
    if args.workers < 1:
        raise ScenarioError(f"--workers: expected at least 1, got {args.workers}")
    cpus = os.cpu_count() or 1
    if args.ray is None and args.workers > cpus:  # said: each is a process of its own
        print(
            f"note: --workers {args.workers} is more than the {cpus} CPUs here: the runs share "
            "them, each worker a process with its own memory (one worker per run at most)",
            file=sys.stderr,
        )
    if args.ray_timeout is not None:
        if args.ray is None:
            raise ScenarioError("--ray-timeout: only with --ray")
        if not 0 < args.ray_timeout <= 3600:  # also refuses nan
            raise ScenarioError(
                f"--ray-timeout: expected seconds in (0, 3600], got {args.ray_timeout:g}"
            )
    return spec


def _main(args: argparse.Namespace, signals: Signals) -> int:
    from ..errors import ClusterError
    from . import folder, report, runner
    from . import spec as spec_mod

    engine: Any = False
    try:
        with signals.active():
            spec = _checked(args, spec_mod.load(args.spec))
        name = spec.name if args.seed is None else f"{spec.name}_seed{spec.seed}"
        out = Path(args.out or Path.cwd() / "renders" / "campaigns" / name).absolute()
        if args.ray is not None:  # join the cluster first: a failure leaves no folder behind
            from . import cluster

            with signals.active():
                deadline = args.ray_timeout or cluster.CONNECT_DEADLINE
                engine = cluster.connect(args.ray or None, args.workers, deadline)
            signals.install()  # ray.init replaces the SIGTERM handler with its own
        with output.locked(out):
            with signals.active():
                state = folder.prepare(out, spec, args.overwrite)
            if state == "replaced":
                print(f"note: {out} held a campaign; replaced (--overwrite)", file=sys.stderr)
            before = len(runner.Results(out).rows)
            outcome = runner.Outcome()
            results = runner.run(
                spec,
                out,
                workers=args.workers,
                ray_address=engine,
                progress=not args.no_progress and sys.stderr.isatty(),
                limit=args.limit,
                signals=signals,
                outcome=outcome,
            )
            rows = [r for r in results.rows if r["run"] < spec.runs]
            path = report.write(rows, out, spec.name, spec.description)
    except (ScenarioError, OutputError, ClusterError) as exc:
        return cli.fail(exc)
    except OSError as exc:
        cli.print_error(output.os_problem(exc, "writing the campaign"))
        return EXIT_OUTPUT
    finally:
        if engine is not False:  # left by runner.run already, unless it never started
            from .cluster import disconnect

            disconnect(engine)
    failed = sum(r.get("status") == "failed" for r in rows)
    if outcome.stopped_by is not None:
        name = Interrupted(outcome.stopped_by).name
        print(
            f"interrupted by {name}: {len(rows)}/{spec.runs} runs recorded in {out} "
            f"({outcome.new} new, {failed} failed; report updated); {outcome.running} running "
            f"and {outcome.queued} queued runs cancelled; run the same command to resume",
            file=sys.stderr,
        )
        return 128 + outcome.stopped_by
    print(
        f"{spec.name}: {len(rows)}/{spec.runs} runs recorded ({len(rows) - before} new, "
        f"{failed} failed) on {outcome.engine} in {out}"
    )
    print(f"report: {path}")
    if rows and failed == len(rows):  # nothing was learnt: say so, and not with exit 0
        errors = [str(r.get("error", "")) for r in rows]
        refused = all(e.startswith(("InputError", "ScenarioError")) for e in errors)
        print(
            f"error: every run {'was refused' if refused else 'failed'} ({failed} of "
            f"{len(rows)}); the first: {errors[0].splitlines()[0] if errors[0] else '?'}",
            file=sys.stderr,
        )
        return EXIT_INPUT if refused else EXIT_PHYSICS
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
