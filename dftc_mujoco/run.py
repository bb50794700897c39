"""``python -m dftc_mujoco.run SCENARIO``: run a scenario and write its records.

Writes ``summary.json``, ``log.npz``, the scenario that ran (``scenario.toml``,
overrides applied), the paper's figures and (unless ``--no-video``)
``video.mp4`` to ``renders/<name>/`` (or ``--out``), and prints a short table
of the run. ``--viewer`` also shows the run live in MuJoCo's viewer, ``--web`` in a web
browser (``watch/web.py``). Exit
codes: 0 success, 2 bad input (scenario file or command line), 3 the physics
failed (the records written so far are kept and ``summary.json`` says what
went wrong), 4 no OpenGL backend for the video, 5 an output, disk or OS problem (the
folder holds another run without ``--overwrite``, is being written by another
process, is not writable, or the disk is full, also while drawing the figures or the
video: the records are then kept without them; ``--web`` without MuJoCo Studio's web
viewer or with its port taken), 130 / 143 interrupted by SIGINT /
SIGTERM (during the simulation the records so far are kept; during the figures or
the video, the records and what was complete).

MuJoCo reads ``MUJOCO_GL`` when it is imported, so this module imports the
simulator only after ``--gl`` has been applied.
"""

from __future__ import annotations

import argparse
import re
import shutil
import sys
import tomllib
import traceback
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .errors import (
    EXIT_BUG,
    EXIT_OK,
    EXIT_OUTPUT,
    EXIT_PHYSICS,
    ScenarioError,
    ServeError,
    exit_interrupted,
)
from .render import gl
from .reporting.report import report
from .runtime import cli, interrupt
from .runtime.interrupt import Interrupted, Signals
from .runtime.output import (
    OutputError,
    destination,
    free_space_check,
    os_problem,
    publish,
    run_folder,
)

if TYPE_CHECKING:
    from .reporting.results import RunResult


EXAMPLES = """\
examples:
  %(prog)s paper_case
      the paper's case study: records, figures and a video in ./renders/paper_case/
  %(prog)s paper_case --no-video --duration 20 --seed 3
  %(prog)s paper_case --robot diffdrive --set onboard.thresholds=l1
  %(prog)s ../mine/case.toml --out results/case1 --overwrite
  %(prog)s paper_case --web --port 8080
      the run live in a web browser: open the address it prints
  %(prog)s --list
      the built-in scenarios, robot models and threshold rules

Documentation: the project's docs/ folder (user guide, command line, every scenario key).
"""

#: the threshold rules in a few words (--list)
RULES = {
    "auto": "the default: paper for robots within the paper's ξ̄, else block_row (l1 on a network)",
    "paper": "eq. 40 of the paper",
    "block_row": "a tighter bound, row by row (up to 64 robots)",
    "l1": "a tight bound that scales to hundreds of robots",
    "drive": "from the fault estimator's own identity (compensation on)",
}


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    p = cli.parser(
        "dftc_mujoco.run",
        "dftc-run",
        "Run a DFTC scenario on MuJoCo physics: the team's mission, its faults and what the "
        "onboard fault detection made of them; writes records, figures and a video.",
        epilog=EXAMPLES,
    )
    p.add_argument(
        "scenario",
        nargs="?",
        help="scenario name (one of --list) or path to a .toml file",
    )
    p.add_argument(
        "--list",
        action="store_true",
        help="list the built-in scenarios, robot models and threshold rules, then exit",
    )
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
    live = p.add_mutually_exclusive_group()
    live.add_argument(
        "--viewer",
        action="store_true",
        help="also show the run live in MuJoCo's viewer (needs a display)",
    )
    live.add_argument(
        "--web",
        action="store_true",
        help="also serve the run live to a web browser (MuJoCo Studio's web viewer; no "
        "display needed): prints the address to open, steps in real time once it is opened",
    )
    add_port_option(p)
    add_video_options(p)
    p.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    p.add_argument(
        "--verbose",
        action="store_true",
        help="also print every premise span, the task errors, set-up and compile times and "
        "the onboard path",
    )
    return p


def add_port_option(p: argparse.ArgumentParser) -> None:
    """``--port`` of ``--web``, shared by the run and plot commands."""
    p.add_argument(
        "--port",
        type=port_number,
        default=0,
        metavar="P",
        help="with --web: the HTTP port to serve on (default 0: the first free one from 8080)",
    )


def port_number(text: str) -> int:
    """A TCP port (0 to 65535) from the command line."""
    try:
        port = int(text)
    except ValueError:
        port = -1
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port number from 0 to 65535, got {text!r}")
    return port


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


_CONTROL = re.compile(r"[\x00-\x1f\x7f]")


def parse_overrides(items: list[str]) -> dict[str, Any]:
    """``KEY=VALUE`` pairs into dotted overrides; VALUE is TOML (a bare word is a string)."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ScenarioError(f"--set {item}: expected KEY=VALUE, e.g. gains.ko=3")
        name = key.strip()
        if _CONTROL.search(name):
            raise ScenarioError(f"--set {name!r}: a key has no line breaks or control characters")
        try:
            doc = tomllib.loads(f"v = {text}")
        except tomllib.TOMLDecodeError:
            if _CONTROL.search(text):  # "x\ny" is not one bare word
                raise ScenarioError(
                    f"--set {name}: {text!r} is not a TOML value, and a bare word (a string) "
                    'has no line breaks or control characters; quote a string ("...")'
                ) from None
            doc = {"v": text}  # a bare word: a string
        except RecursionError:
            raise ScenarioError(f"--set {name}: the value is nested too deep") from None
        if set(doc) != {"v"}:  # "3\nduration = 1" set a second key in silence
            extra = ", ".join(k for k in doc if k != "v")
            raise ScenarioError(
                f"--set {name}: {text!r} holds more than one value (a line break starts "
                f"another key: {extra}); give one value per --set"
            )
        out[name] = doc["v"]
    return out


def write_records(result: RunResult, out: Path) -> None:
    """Write ``log.npz``, ``scenario.toml`` then ``summary.json`` (atomically) into ``out``
    (figures and video follow, in :func:`render_outputs`)."""
    result.write(out, figures=False)


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:  # an argument argparse does not know: say why in one line
        parser.error(cli.stray_arguments(extra, args.overrides))
    if args.list:
        print(catalogue())
        return EXIT_OK
    if args.scenario is None:
        parser.error("the scenario is required (a name such as paper_case, or --list)")
    if args.port and not args.web:
        parser.error("--port is the port of --web: add --web, or leave --port out")
    # the records are never cut in two: the work defers signals where it must
    return interrupt.guarded(
        lambda signals: _main(args, signals), " before the run started: nothing was written"
    )


def catalogue() -> str:
    """What ``--list`` prints: the built-in scenarios, robot models and threshold rules."""
    from .blocks import BUILTIN
    from .runtime.paths import SCENARIOS
    from .sim.robots import available, get

    lines = ["built-in scenarios (python -m dftc_mujoco.run NAME):"]
    for path in sorted(SCENARIOS.glob("*.toml")):
        data = tomllib.loads(path.read_text(encoding="utf-8"))
        lines.append(f"  {path.stem:<22} {data.get('description', '')}")
    lines.append("robot models (team.robot_model, or --robot NAME):")
    for name in available():
        model = get(name)
        lines.append(f"  {name:<22} {model.drive} drive, {model.footprint_radius:.2f} m radius")
    lines.append("threshold rules (--set onboard.thresholds=NAME):")
    lines += [f"  {name:<22} {RULES.get(name, '')}" for name in ("auto", *BUILTIN["thresholds"])]
    lines.append("and your own: a robot file (--robot path/to/bot.robot.toml) or a block")
    lines.append('("module:Class" in [onboard]); see the documentation')
    return "\n".join(lines)


def _main(args: argparse.Namespace, signals: Signals) -> int:
    progress = not args.no_progress and sys.stderr.isatty()
    try:
        with signals.active():
            if args.web:  # before anything is built: the viewer is there and the port free
                from .watch.web import check

                check(args.port)
            options = setup_video(args, not args.no_video)
    except (ScenarioError, gl.RenderError, ServeError) as exc:
        return cli.fail(exc)

    try:
        with signals.active():
            from . import scenario as scenario_mod
            from .closed_loop.loop import Simulation
            from .sim import robots

            overrides = parse_overrides(args.overrides)
            original = scenario_mod.load_scenario(args.scenario, overrides)
            if args.robot is not None:
                robots.get(args.robot, where="--robot")
            if "team.robot_model" in overrides:  # said as the command line's, not the file's
                given = overrides["team.robot_model"]
                for name in given if isinstance(given, list) else [given]:
                    if isinstance(name, str):
                        robots.get(name, where="--set team.robot_model")
            s = original.with_overrides(
                seed=args.seed, duration=args.duration, robot_model=args.robot
            )
        print(  # the first line, before anything is built or compiled
            f"{s.name}: {s.team.robots} robots ({s.team.robot_model}), {s.duration:g} s of "
            f"mission, seed {s.seed}",
            flush=True,
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
            # the set-up and the first period compile the run's code: the notice says so
            with cli.CompileNotice() as notice, Simulation(s) as sim, signals.stopping(sim):
                free_space_check(work, sum(a.nbytes for a in sim.log.data.values()) + 50 * 2**20)
                long = [e for e in sim.events.items if "will take at least" in e.get("message", "")]
                for e in long:  # said now, not after the hours it announces
                    print(f"note: {e['message']}", file=sys.stderr)
                if args.web:
                    from .watch.web import serve_live

                    serve_live(sim, args.port)
                elif args.viewer:
                    from .watch.viewer import ViewerUnavailable, watch

                    try:
                        watch(sim)
                    except ViewerUnavailable as exc:
                        print(f"note: {exc}; running without the viewer", file=sys.stderr)
                if not sim.done:
                    sim.step(1)
                notice.close()  # before the progress bar
                result = sim.run(progress=progress)
            verbose = args.verbose
            return _finish(
                result, work, destination(out), signals, options, progress, verbose, args.overwrite
            )
    except (ScenarioError, OutputError, ServeError) as exc:
        return cli.fail(exc)
    except OSError as exc:
        cli.print_error(os_problem(exc, "writing the run"))
        return EXIT_OUTPUT


def _finish(
    result,
    work: Path,
    out: Path,
    signals: Signals,
    options,
    progress: bool,
    verbose=False,
    overwrite=False,
) -> int:
    """Write the records into ``work`` and move them to ``out`` at once, print the report,
    draw the figures and video into ``work`` (which joins ``out`` once this returns); the
    exit code. A signal during the figures or the video, or a full disk there, keeps the
    records (and the figures when they were complete) and drops the rest; SIGKILL there
    leaves the records at ``out``."""
    if signals.signum is not None and len(result.log["t"]) <= 1:
        # stopped before its first control period: nothing ran, no run folder (the signal
        # ends the command: "interrupted by SIGINT before the run started: nothing was written")
        raise interrupt.Interrupted(signals.signum)
    write_records(result, work)
    if signals.signum is None:  # (signals are deferred here: only recorded)
        publish(work, out, overwrite)
    print(report(result, out, verbose))
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
    print(f"figures:      {len(paths)} in {shown / 'figures'} ({time.perf_counter() - t0:.1f} s)")
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
        print("video:        none: the run logged no period")
        return EXIT_OK
    print(
        f"video:        {shown / 'video.mp4'} ({frames} frames at {options.fps:g} fps, "
        f"{options.width}x{options.height}, rendered and encoded at {frames / wall:.0f} "
        f"frames/s)"
    )
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
