"""``python -m dftc_mujoco.run SCENARIO``: run a scenario and write its records.

Writes ``summary.json`` and ``log.npz`` to ``renders/<name>/`` (or ``--out``)
and prints a short table of the run. Exit codes: 0 success, 2 bad input
(scenario file or command line), 3 the physics failed (the records written so
far are kept and ``summary.json`` says what went wrong).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from . import scenario as scenario_mod
from .errors import ScenarioError
from .loop import RunResult, simulate
from .paths import RENDERS
from .record import write_json, write_npz
from .sim import robots

EXIT_OK, EXIT_INPUT, EXIT_PHYSICS = 0, 2, 3


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    p = argparse.ArgumentParser(
        prog="python -m dftc_mujoco.run",
        description="Run a DFTC scenario on MuJoCo physics.",
    )
    p.add_argument("scenario", help="scenario name (scenarios/NAME.toml) or path to a .toml file")
    p.add_argument("--out", type=Path, help="output folder (default: renders/<name>/)")
    p.add_argument("--seed", type=int, help="override the scenario's seed")
    p.add_argument(
        "--duration",
        type=float,
        help="override the duration [s]; faults that "
        "would start after the new end are dropped (and listed)",
    )
    p.add_argument("--robot", metavar="MODEL", help="override team.robot_model")
    p.add_argument(
        "--no-video",
        action="store_true",
        help="do not render a video (no video renderer exists yet: "
        "runs write summary.json and log.npz only)",
    )
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return p


def _fmt_event(e: dict) -> str:
    k = e["kind"]
    r = e.get("robot", -1) + 1
    if k == "fault":
        return f"fault: {e['fault']} on robot {r}"
    if k == "reactive_on":
        return f"robot {r} switches to obstacle avoidance ({e.get('obstacle', '?')})"
    if k == "reactive_off":
        return f"robot {r} back to the global mission"
    if k == "detection":
        return f"robot {e['by'] + 1} flags robot {r}"
    if k == "exclusion_scheduled":
        return f"robot {r} will be excluded at t_r = {e['t_r']:.2f} s unless nobody flags it then"
    if k == "exclusion":
        by = ", ".join(str(b + 1) for b in e["flagged_by"])
        return f"robot {r} excluded from the team (still flagged by {by})"
    if k == "exclusion_cancelled":
        return f"robot {r} kept: nobody flags it any more at t_r"
    if k == "graph_not_strongly_connected":
        left = ", ".join(str(b + 1) for b in e["robots"])
        return (
            f"WARNING: the graph of robots {left} is not strongly connected: "
            "estimates and thresholds of some robots are no longer bounded"
        )
    if k == "simulation_error":
        return f"SIMULATION ERROR: {e['message']}"
    return f"{k} {e}"


def report(result: RunResult, out: Path) -> str:
    """The human-readable table printed at the end of a run."""
    s = result.summary
    lines = [
        f"{s['scenario']} (seed {s['seed']}, {s['robots']} x {s['robot_model']}): "
        f"{s['simulated_time']:.2f} s simulated in {s['wall_time']:.2f} s "
        f"({s['real_time_factor']:.0f}x real time)  status: {s['status']}",
        "",
        "   t [s]  event",
    ]
    for e in result.events.ordered():
        lines.append(f"{e['t']:8.2f}  {_fmt_event(e)}")
    err = s["errors"]

    def m(v: float | None) -> str:
        return "n/a" if v is None else f"{v:.4f} m"

    lines += [
        "",
        f"errors from t = {err['window'][0]:g} s: centroid rms {m(err['centroid_rms'])}, "
        f"formation rms {m(err['formation_rms'])}; final: centroid {m(err['final_centroid'])}, "
        f"formation {m(err['final_formation'])}",
    ]
    if s["min_obstacle_clearance"] is not None:
        lines.append(
            f"closest approach to a cylinder: {s['min_obstacle_clearance']:.4f} m surface gap, "
            f"{s['min_safe_distance_margin']:+.4f} m from its safe distance d"
        )
    if s.get("margin") is not None:
        lines.append(f"largest residual / threshold on robots without a fault: {s['margin']:.3f}")
    for f in s.get("fault_estimates", []):
        mean = ", ".join(f"{v:.4f}" for v in f["mean_error"])
        lines.append(
            f"fault estimate on robot {f['robot']} (from {f['window'][0]:g} s): "
            f"mean error [{mean}] m/s"
        )
    lines.append(f"records: {out / 'summary.json'}, {out / 'log.npz'}")
    return "\n".join(lines)


def write_records(result: RunResult, out: Path) -> None:
    """Write ``log.npz`` then ``summary.json`` (each atomically) into ``out``."""
    write_npz(out / "log.npz", result.log)
    write_json(out / "summary.json", result.summary)


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    args = build_parser().parse_args(argv)
    try:
        original = scenario_mod.load(args.scenario)
        if args.robot is not None:
            robots.get(args.robot, where="--robot")
        s = original.with_overrides(seed=args.seed, duration=args.duration, robot_model=args.robot)
        for f in scenario_mod.dropped_faults(original, s):
            print(
                f"note: the {f.kind} fault on robot {f.robot + 1} at {f.t:g} s is after "
                f"--duration {s.duration:g} s and will not happen",
                file=sys.stderr,
            )
        result = simulate(s, progress=not args.no_progress and sys.stderr.isatty())
    except ScenarioError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    out = args.out if args.out is not None else RENDERS / s.name
    try:
        write_records(result, out)
    except OSError as exc:
        print(f"error: cannot write the records to {out}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_INPUT
    print(report(result, out))
    if not result.ok:
        print(f"error: {result.error}", file=sys.stderr)
        return EXIT_PHYSICS
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
