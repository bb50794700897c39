"""``python -m dftc_mujoco.plot RUN_DIR``: redraw a saved run's figures (and video).

Reads ``log.npz`` and ``summary.json`` (and, for ``--video``, the
``scenario.toml`` copy the run left) without re-simulating; ``--web`` replays the run in
a web browser instead (``watch/web.py``), until Ctrl-C (exit 0). Everything is drawn
into a private folder beside the run and moved into the run folder only when
complete (the figures as one folder, the video, each still), so a failure or an
interruption leaves the previous figures and video as they were. Exit codes: 0
success, 2 bad input (a missing, truncated or corrupt record file), 4 no OpenGL
backend, 5 an output, disk or OS problem (the run folder is being written by
another process, or the disk is full; ``--web`` without MuJoCo Studio's web viewer or with
its port taken), 130 / 143 interrupted by SIGINT / SIGTERM.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

from .errors import (
    EXIT_INPUT,
    EXIT_OK,
    EXIT_OUTPUT,
    OutputError,
    RenderError,
    ScenarioError,
    ServeError,
)
from .render import gl
from .run import add_port_option, add_video_options, setup_video
from .runtime import cli, interrupt, output


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    p = cli.parser(
        "dftc_mujoco.plot",
        "dftc-plot",
        "Redraw a run's figures (and video) from its records, without simulating again.",
        epilog="""\
examples:
  %(prog)s renders/paper_case                 the paper's figures again, into figures/
  %(prog)s renders/paper_case --video         and video.mp4
  %(prog)s renders/paper_case --still 45.1    the video frame at t = 45.1 s as a PNG
  %(prog)s renders/paper_case --web           the run replayed in a web browser

Documentation: the project's docs/ folder (the command line, what a run folder holds).
""",
    )
    p.add_argument("run_dir", type=Path, help="a folder written by python -m dftc_mujoco.run")
    add_video_options(p)
    p.set_defaults(no_video=True)
    p.add_argument(
        "--video",
        dest="no_video",
        action="store_false",
        help="also re-render video.mp4 (needs the run's scenario.toml)",
    )
    p.add_argument(
        "--still",
        type=float,
        action="append",
        default=[],
        metavar="T",
        help="also write the video frame at time T as still_T.png (repeatable)",
    )
    p.add_argument(
        "--web",
        action="store_true",
        help="replay the run in a web browser instead of drawing (MuJoCo Studio's web viewer; "
        "no display needed): prints the address to open; Ctrl-C stops it",
    )
    add_port_option(p)
    args = p.parse_args(argv)
    if args.port and not args.web:
        p.error("--port is the port of --web: add --web, or leave --port out")
    if args.web and (not args.no_video or args.still):
        p.error("--web replays the run; --video and --still draw it: one at a time")
    if args.web:
        return interrupt.guarded(lambda signals: _web(args, signals), "")
    return interrupt.guarded(
        lambda signals: _plot(args, signals),
        f": the figures and video in {args.run_dir} are unchanged",
    )


def _web(args, signals: interrupt.Signals) -> int:
    """Serve the run's replay until Ctrl-C (exit 0: that is how it ends)."""
    from .watch.web import check, serve_replay

    try:
        with signals.active():
            check(args.port)
            from .reporting.results import open_run

            run = open_run(args.run_dir)
        serve_replay(run, args.port, stop=lambda: signals.signum is not None)
    except (ScenarioError, ServeError, RenderError) as exc:  # RenderError: an empty log
        return cli.fail(exc)
    if signals.signum is not None:
        print(f"web: stopped by {interrupt.Interrupted(signals.signum).name}", file=sys.stderr)
    return EXIT_OK


def _plot(args, signals: interrupt.Signals) -> int:
    wants_gl = not args.no_video or bool(args.still)
    try:
        with signals.active():
            options = setup_video(args, wants_gl)
            from .reporting.results import open_run

            run = open_run(args.run_dir)  # log.npz, summary.json and the scenario that ran
        log, summary = run.log, run.summary
        scenario = run.scenario if options is not None else None
    except (ScenarioError, gl.RenderError) as exc:
        return cli.fail(exc)
    from .run import render_outputs

    try:
        with output.locked(args.run_dir) as out:
            work = output.private_folder(out)
            try:
                with signals.active():
                    code = EXIT_OK
                    if args.still:
                        code = write_stills(scenario, log, summary, work, options, args.still, out)
                    if not code:
                        code = render_outputs(
                            scenario,
                            log,
                            summary,
                            work,
                            None if args.no_video else options,
                            progress=sys.stderr.isatty(),
                            shown=out,
                        )
                if code:
                    return code
                drawn = sorted(p.name for p in work.iterdir() if p.name != output.OWNER)
                output.replace_into(work, out, drawn)
            finally:
                shutil.rmtree(work, ignore_errors=True)
    except (OutputError, ScenarioError) as exc:  # ScenarioError: the video's robot file
        return cli.fail(exc)
    except (ValueError, TypeError, KeyError, IndexError) as exc:  # records edited by hand
        print(
            f"error: {args.run_dir}: these records cannot be drawn ({type(exc).__name__}: "
            f"{str(exc).splitlines()[0] if str(exc) else ''}); were they edited, or written by "
            "another version? python -m dftc_mujoco.run writes them again",
            file=sys.stderr,
        )
        return EXIT_INPUT
    except OSError as exc:
        cli.print_error(output.os_problem(exc, "drawing the figures and video", args.run_dir))
        print(f"note: the figures and video in {args.run_dir} are unchanged", file=sys.stderr)
        return EXIT_OUTPUT
    return EXIT_OK


def write_stills(
    scenario, log, summary, out: Path, options, times: list[float], shown: Path | None = None
) -> int:
    """Write the video frames at ``times`` as PNG files in ``out`` (``shown``: the folder
    the messages name, default ``out``)."""
    shown = shown or out
    import imageio.v3 as iio

    from .render.video import FrameRenderer

    if not len(log["t"]):
        print("error: --still: the run logged no period: there is no frame", file=sys.stderr)
        return EXIT_INPUT
    try:
        with FrameRenderer(scenario, log, summary, options) as fr:
            for t in times:
                if not 0 <= t <= float(log["t"][-1]):
                    print(
                        f"error: --still {t:g}: outside the run (0 to {log['t'][-1]:g} s)",
                        file=sys.stderr,
                    )
                    return EXIT_INPUT
                path = out / f"still_{t:g}.png"
                iio.imwrite(path, fr.frame(t))
                print(f"still: {shown / path.name}")
    except gl.RenderError as exc:
        return cli.fail(exc)
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
