"""``python -m dftc_mujoco.run SCENARIO``: run a scenario and write its records.

Writes ``summary.json``, ``log.npz``, the scenario that ran (``scenario.toml``,
overrides applied), the paper's figures and (unless ``--no-video``)
``video.mp4`` to ``renders/<name>/`` (or ``--out``), and prints a short table
of the run. ``--viewer`` also shows the run live in MuJoCo's viewer. Exit
codes: 0 success, 2 bad input (scenario file or command line), 3 the physics
failed (the records written so far are kept and ``summary.json`` says what
went wrong), 4 no OpenGL backend for the video, 5 an output, disk or OS problem (the
folder holds another run without ``--overwrite``, is being written by another
process, is not writable, or the disk is full, also while drawing the figures or the
video: the records are then kept without them), 130 / 143 interrupted by SIGINT /
SIGTERM (during the simulation the records so far are kept; during the figures or
the video, the records and what was complete).

MuJoCo reads ``MUJOCO_GL`` when it is imported, so this module imports the
simulator only after ``--gl`` has been applied.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tomllib
import traceback
from pathlib import Path
from typing import TYPE_CHECKING, Any

from . import cli, interrupt
from .errors import (
    EXIT_BUG,
    EXIT_OK,
    EXIT_OUTPUT,
    EXIT_PHYSICS,
    ScenarioError,
    exit_interrupted,
)
from .events import describe
from .interrupt import Interrupted, Signals
from .output import OutputError, destination, free_space_check, os_problem, run_folder
from .render import gl

if TYPE_CHECKING:
    from .results import RunResult


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    p = cli.parser("dftc_mujoco.run", "dftc-run", "Run a DFTC scenario on MuJoCo physics.")
    p.add_argument("scenario", help="scenario name (scenarios/NAME.toml) or path to a .toml file")
    p.add_argument(
        "--out", type=Path, help="output folder (default: ./renders/<name>/ in this directory)"
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an existing run folder at --out (as a whole; never a non-run folder)",
    )
    cli.add_set_option(p, "the scenario")
    p.add_argument("--seed", type=int, help="override the scenario's seed")
    p.add_argument(
        "--duration",
        type=float,
        help="override the duration [s]; faults that "
        "would start after the new end are dropped (and listed)",
    )
    p.add_argument("--robot", metavar="MODEL", help="override team.robot_model")
    p.add_argument(
        "--viewer",
        action="store_true",
        help="also show the run live in MuJoCo's viewer (needs a display)",
    )
    add_video_options(p)
    p.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    return p


def add_video_options(p: argparse.ArgumentParser) -> None:
    """Video options shared by the run and plot commands."""
    p.add_argument(
        "--no-video",
        action="store_true",
        help="skip the video (figures are still drawn); needs no OpenGL",
    )
    p.add_argument(
        "--gl",
        choices=gl.BACKENDS,
        help="OpenGL backend for offscreen rendering (default: $MUJOCO_GL, else egl)",
    )
    p.add_argument("--fps", type=float, default=30.0, help="video frame rate (default 30)")
    p.add_argument(
        "--size", default="640x480", metavar="WxH", help="video frame size (default 640x480)"
    )
    p.add_argument(
        "--quality", action="store_true", help="shadows, multisampling and a slower, finer encoding"
    )


def setup_video(args: argparse.Namespace, wanted: bool):
    """Choose the GL backend (before mujoco is imported), read the video options and probe.

    Returns the VideoOptions, or None when no video is wanted. Raises
    ScenarioError (bad flags) or RenderError (no backend).
    """
    if not wanted:
        return None
    gl.select(args.gl)  # before anything imports mujoco
    options = video_options(args)
    gl.probe()  # fail before simulating, not after
    return options


def video_options(args: argparse.Namespace):
    """VideoOptions from the command line, or a ScenarioError naming the bad flag."""
    from .render.options import VideoOptions

    try:
        w, h = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        raise ScenarioError(
            f"--size: expected WIDTHxHEIGHT such as 640x480, got {args.size!r}"
        ) from None
    if not (16 <= w <= 4096 and 16 <= h <= 4096) or w % 2 or h % 2:
        raise ScenarioError(f"--size: expected even sizes between 16 and 4096, got {args.size}")
    if not 1 <= args.fps <= 240:
        raise ScenarioError(f"--fps: expected 1 to 240 frames per second, got {args.fps:g}")
    return VideoOptions(width=w, height=h, fps=args.fps, quality=args.quality)


def parse_overrides(items: list[str]) -> dict[str, Any]:
    """``KEY=VALUE`` pairs into dotted overrides; VALUE is TOML (a bare word is a string)."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ScenarioError(f"--set {item}: expected KEY=VALUE, e.g. gains.ko=3")
        try:
            value = tomllib.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            value = text  # a bare word: a string
        except RecursionError:
            raise ScenarioError(f"--set {key.strip()}: the value is nested too deep") from None
        out[key.strip()] = value
    return out


def _factor(x: float) -> str:
    """A real-time factor as 325x, 3.2x or 0.053x."""
    return f"{x:.0f}x" if x >= 10 else f"{x:.2g}x"


def report(result: RunResult, out: Path) -> str:
    """The human-readable table printed at the end of a run."""
    s = result.summary
    lines = [
        f"{s['scenario']} (seed {s['seed']}, {s['robots']} x {s['robot_model']}): "
        f"{s['simulated_time']:.2f} s simulated in {s['wall_time']:.2f} s "
        f"({_factor(s['real_time_factor'])} real time)  status: {s['status']}",
        "",
        "   t [s]  event",
    ]
    for e in result.events.ordered():
        lines.append(f"{e['t']:8.2f}  {describe(e)}")
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
    table = s.get("premises")
    if table:
        broken = [
            f"{p} ({v['spans']} span{'s' * (v['spans'] != 1)}, worst {v['worst']:.4g} vs "
            f"{v['bound']:.4g}" + (f", robot {v['robot']})" if v["robot"] else ")")
            for p, v in table.items()
            if not v["held"]
        ]
        lines.append(
            "premises: all held" if not broken else "premises violated: " + "; ".join(broken)
        )
    if s.get("healthy_flags_premises_held"):
        lines.append(
            f"DEFECT OF THE THRESHOLD RULE: {s['healthy_flags_premises_held']} flag(s) on "
            "robots without a fault while every premise held (see docs/thresholds.md)"
        )
    for f in s.get("fault_estimates", []):  # one entry per robot, however many biases
        mean = ", ".join(f"{v:.4f}" for v in f["mean_error"])
        windows = f.get("windows", [f["window"]])
        when = (
            f"from {windows[0][0]:g} s"
            if len(windows) == 1
            else f"{len(f['faults'])} biases, " + ", ".join(f"{a:g}-{b:g} s" for a, b in windows)
        )
        lines.append(f"fault estimate on robot {f['robot']} ({when}): mean error [{mean}] m/s")
    o = s.get("onboard", {})
    custom = {k: v for k, v in o.get("blocks", {}).items() if v != "paper"}
    lines.append(
        f"onboard: {o.get('path', '?')} path"
        + (f", blocks {', '.join(f'{k} = {v}' for k, v in custom.items())}" if custom else "")
    )
    lines.append(f"records: {out / 'summary.json'}, {out / 'log.npz'}")
    return "\n".join(lines)


def write_records(result: RunResult, out: Path) -> None:
    """Write ``log.npz``, ``scenario.toml`` then ``summary.json`` (atomically) into ``out``
    (figures and video follow, in :func:`render_outputs`)."""
    result.write(out, figures=False)


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    args = build_parser().parse_args(argv)
    # the records are never cut in two: the work defers signals where it must
    return interrupt.guarded(
        lambda signals: _main(args, signals), " before the run started: nothing was written"
    )


def _main(args: argparse.Namespace, signals: Signals) -> int:
    progress = not args.no_progress and sys.stderr.isatty()
    try:
        with signals.active():
            options = setup_video(args, not args.no_video)
    except (ScenarioError, gl.RenderError) as exc:
        return cli.fail(exc)

    try:
        with signals.active():
            from . import scenario as scenario_mod
            from .loop import Simulation
            from .sim import robots

            overrides = parse_overrides(args.overrides)
            original = scenario_mod.load_scenario(args.scenario, overrides)
            if args.robot is not None:
                robots.get(args.robot, where="--robot")
            s = original.with_overrides(
                seed=args.seed, duration=args.duration, robot_model=args.robot
            )
        for f in scenario_mod.dropped_faults(original, s):
            print(
                f"note: the {f.kind} fault on robot {f.robot + 1} at {f.t:g} s is after "
                f"--duration {s.duration:g} s and will not happen",
                file=sys.stderr,
            )
        out = args.out if args.out is not None else Path.cwd() / "renders" / s.name
        with run_folder(out, args.overwrite) as work:
            # from here on a signal stops the run and keeps its records (none yet when it
            # came while the simulation was being built: signals are deferred until then)
            with Simulation(s) as sim, signals.stopping(sim):
                free_space_check(work, sum(a.nbytes for a in sim.log.data.values()) + 50 * 2**20)
                long = [e for e in sim.events.items if "will take at least" in e.get("message", "")]
                for e in long:  # said now, not after the hours it announces
                    print(f"note: {e['message']}", file=sys.stderr)
                if args.viewer:
                    from .viewer import ViewerUnavailable, watch

                    try:
                        watch(sim)
                    except ViewerUnavailable as exc:
                        print(f"note: {exc}; running without the viewer", file=sys.stderr)
                result = sim.run(progress=progress)
            return _finish(result, work, destination(out), signals, options, progress)
    except (ScenarioError, OutputError) as exc:
        return cli.fail(exc)
    except OSError as exc:
        cli.print_error(os_problem(exc, "writing the run"))
        return EXIT_OUTPUT


def _finish(result, work: Path, out: Path, signals: Signals, options, progress: bool) -> int:
    """Write the records (and figures, video) into ``work``, print the report; the exit code.

    ``out`` is where ``work`` is moved once this returns (the paths printed). A signal
    during the figures or the video, or a full disk there, keeps the records (and the
    figures when they were complete) and drops the rest."""
    write_records(result, work)
    print(report(result, out))
    if signals.signum is not None:
        print(
            f"interrupted by {interrupt.Interrupted(signals.signum).name}: the records up to "
            f"t = {result.summary['simulated_time']:.2f} s are in {out} (no figures or video)",
            file=sys.stderr,
        )
        return exit_interrupted(signals.signum)
    code = EXIT_OK
    if not result.ok:
        print(f"error: {result.error}", file=sys.stderr)
        code = EXIT_PHYSICS
    try:
        with signals.active():
            drawn = render_outputs(
                result.scenario, result.log, result.summary, work, options, progress, shown=out
            )
    except Interrupted as exc:
        kept = _drop_incomplete(work)
        again = f"python -m dftc_mujoco.plot {out}" + (" --video" if options else "")
        print(
            f"interrupted by {exc.name} while drawing: {kept} are in {out}; {again} draws the rest",
            file=sys.stderr,
        )
        return exc.exit_code
    except OSError as exc:
        kept = _drop_incomplete(work)
        cli.print_error(os_problem(exc, "drawing the figures and video", where=out))
        print(f"note: {kept} are in {out}", file=sys.stderr)
        return EXIT_OUTPUT
    except Exception:  # a bug of the drawing code: it must not cost the run its records
        kept = _drop_incomplete(work)
        traceback.print_exc()
        print(
            f"error: drawing the figures and video failed (a bug in dftc_mujoco: please report "
            f"the traceback above); {kept} are in {out}",
            file=sys.stderr,
        )
        return EXIT_BUG
    return max(code, drawn)


def _drop_incomplete(work: Path) -> str:
    """Remove a figure set or video that is not complete from ``work``; says what is left."""
    from .render.figures import FIGURES

    figures = work / "figures"
    complete = figures.is_dir() and all((figures / f"{n}.png").is_file() for n in FIGURES)
    if figures.exists() and not complete:
        shutil.rmtree(figures, ignore_errors=True)
    for tmp in work.glob(".*.tmp*"):
        tmp.unlink(missing_ok=True)
    return "the records and figures" if complete else "the records (no figures)"


def render_outputs(
    scenario, log, summary, out: Path, options, progress: bool, shown: Path | None = None
) -> int:
    """Draw the figures and (if ``options``) the video of a run into ``out``; returns an
    exit code. ``shown`` is the folder named in the messages (default ``out``)."""
    shown = shown or out
    import time

    from .render import figures

    t0 = time.perf_counter()
    paths = figures.draw_all(log, summary, out / "figures")
    print(f"figures: {len(paths)} in {shown / 'figures'} ({time.perf_counter() - t0:.1f} s)")
    if options is None:
        return EXIT_OK
    from .render.video import write_video

    t0 = time.perf_counter()
    try:
        frames = write_video(out / "video.mp4", scenario, log, summary, options, progress)
    except gl.RenderError as exc:
        return cli.fail(exc)
    wall = time.perf_counter() - t0
    if not frames:
        print("video: none: the run logged no period")
        return EXIT_OK
    print(
        f"video: {shown / 'video.mp4'} ({frames} frames at {options.fps:g} fps, "
        f"{options.width}x{options.height}, rendered and encoded at {frames / wall:.0f} "
        f"frames/s)"
    )
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
