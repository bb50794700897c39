"""``python -m dftc_mujoco.plot RUN_DIR``: redraw a saved run's figures (and video).

Reads ``log.npz`` and ``summary.json`` (and, for ``--video``, the
``scenario.toml`` copy the run left) without re-simulating. Exit codes: 0
success, 2 bad input (missing or unreadable records), 4 no OpenGL backend.
"""

from __future__ import annotations

import sys
from pathlib import Path

from . import cli
from .errors import ScenarioError
from .render import gl
from .run import EXIT_INPUT, EXIT_OK, EXIT_RENDER, add_video_options, setup_video


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    p = cli.parser(
        "dftc_mujoco.plot", "dftc-plot", "Redraw a run's figures (and video) from its records."
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
    args = p.parse_args(argv)
    wants_gl = not args.no_video or bool(args.still)
    try:
        options = setup_video(args, wants_gl)
        from .results import open_run

        run = open_run(args.run_dir)  # log.npz, summary.json and the scenario that ran
        log, summary = run.log, run.summary
        scenario = run.scenario if options is not None else None
    except ScenarioError as exc:
        cli.print_error(exc)
        return EXIT_INPUT
    except gl.RenderError as exc:
        cli.print_error(exc)
        return EXIT_RENDER
    from .run import render_outputs

    if args.still:
        code = write_stills(scenario, log, summary, args.run_dir, options, args.still)
        if code:
            return code
    code = render_outputs(
        scenario,
        log,
        summary,
        args.run_dir,
        None if args.no_video else options,
        progress=sys.stderr.isatty(),
    )
    return code if code else EXIT_OK


def write_stills(scenario, log, summary, out: Path, options, times: list[float]) -> int:
    """Write the video frames at ``times`` as PNG files in ``out``."""
    import imageio.v3 as iio

    from .render.video import FrameRenderer

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
                print(f"still: {path}")
    except gl.RenderError as exc:
        cli.print_error(exc)
        return EXIT_RENDER
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
