"""``python -m dftc_mujoco.calibrate MODEL`` (and ``dftc-calibrate``): the command line."""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from ..errors import EXIT_OK, EXIT_OUTPUT, ScenarioError
from .compensation import (
    acceleration,
    acceleration_report,
    compensation,
    compensation_report,
    range_fit,
    range_fit_report,
)
from .drift import REPLAN_WINDOW, drift
from .files import Change, check_writable, values_of, write
from .mismatch import (
    PAPER_XI_BAR,
    TIMESTEP,
    Calibration,
    detectability,
    measure,
    report,
    robot_with,
)
from .physics import CHATTER_SHARE, CHATTER_STEPS_DOWN_TO, STEPS, OffPlane, Trouble, limits
from .track import skid_track


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    from ..runtime import cli
    from ..sim import robots

    p = cli.parser(
        "dftc_mujoco.calibrate",
        "dftc-calibrate",
        "Measure how a robot model departs from ẋ = u (its mismatch, lag, drift) on MuJoCo "
        "physics, and store it in its robot file.",
        epilog="""\
examples:
  %(prog)s disk                               measure a built-in robot, print the figures
  %(prog)s mylab/bot.robot.toml --write       measure your robot, store [calibration]
  %(prog)s mylab/bot.robot.toml --scenario paper_case --set mission.scale=2

Documentation: the project's docs/ folder (robots and calibration).
""",
    )
    p.add_argument(
        "model",
        help=f"a built-in model ({', '.join(robots.available())}), a robot file "
        "(NAME.robot.toml) or an MJCF path",
    )
    p.add_argument(
        "--write",
        action="store_true",
        help="store the results in the robot file's [calibration] table (its other keys, "
        "comments and tables stay as they are; values it replaces are listed first)",
    )
    p.add_argument(
        "--keep",
        action="store_true",
        help="with --write: keep the values [calibration] already has (set by hand or by an "
        "earlier calibration), add only the keys it lacks",
    )
    p.add_argument(
        "--scenario",
        default="paper_case",
        help="the mission for the detectability warning and the drift (default paper_case)",
    )
    cli.add_set_option(p, "that scenario (as with run)")
    p.add_argument(
        "--runs", type=int, default=3, help="fault-free runs of the scenario for the drift"
    )
    args = p.parse_args(argv)
    from ..runtime import interrupt

    written: list[Path] = []  # the file, once a write of this command replaced it
    with interrupt.catch():  # a signal stops it at once: nothing is half written (atomic)
        try:
            return _calibrate(args, written)
        except interrupt.Interrupted as exc:
            said = (
                f"; {written[0]} holds the calibration measured so far (before the drift)"
                if written
                else ("; nothing written" if args.write else "")
            )
            print(f"interrupted by {exc.name}{said}", file=sys.stderr)
            return exc.exit_code


def _calibrate(args: argparse.Namespace, written: list[Path]) -> int:
    from ..run import parse_overrides
    from ..runtime import cli
    from ..sim import robots

    try:
        if args.runs < 1:  # it ran one run without a word
            raise ScenarioError(f"--runs: expected at least 1 fault-free run, got {args.runs}")
        if args.keep and not args.write:
            raise ScenarioError("--keep: keeps the file's values when writing: add --write")
        overrides = parse_overrides(args.overrides)  # bad input fails before measuring
        from ..scenario import load_scenario

        load_scenario(args.scenario, overrides)
        path = robots.resolve(args.model, where="MODEL") if args.write else None
        if path is not None:
            check_writable(path)
        cal, measured = on_plane(args.model)
        print(report(cal))
        line, warn = detectability(cal, args.scenario, args.model, overrides)
        print(f"WARNING: {line}" if warn else line)
        if cal.lag > 0:  # the missions below run the drive model the robot will run
            overrides.setdefault("fdir.drive_lag", cal.lag)
        _say("the compensation loop, closed on the robot at each gain tried")
        loop_results = compensation(
            args.model, args.scenario, overrides=overrides, lag=cal.lag, measured=measured
        )
        line, warn = compensation_report(loop_results)
        print(f"WARNING: {line}" if warn else line)
        g = loop_results[-1].G
        xi_bar = float(overrides.get("noise.xi_bar", cal.recommended_xi_bar))
        lags = (cal.lag, cal.fast_lag)  # the paper's rules model lag, the drive rule either
        G, phi, phi_g = range_fit(g, cal.command_limit, args.scenario, overrides, xi_bar, lags)
        widened = range_fit_report(g, G, phi, phi_g, cal.command_limit)
        if widened:
            print(widened)
        if (loop_results[0].rings or widened) and "gains.G" not in overrides:
            overrides["gains.G"] = G
        overrides.setdefault("noise.xi_bar", cal.recommended_xi_bar)  # split for the new ξ̄
        cal = dataclasses.replace(cal, compensation_G=G)
        _say("jumping commands, at each acceleration tried")
        jumps = acceleration(args.model, G, lag=cal.lag, measured=measured)
        line, warn = acceleration_report(jumps)
        print(f"WARNING: {line}" if warn else line)
        if not jumps[-1][1].runs_away:
            cal = dataclasses.replace(cal, accel=jumps[-1][0])

        def say(changes: list[Change]) -> None:
            print(
                f"replacing values of {path}'s calibration (set by hand or by an earlier "
                "calibration; --keep keeps them):"
            )
            for change in changes:
                print(f"  {change.line()}")

        if path is not None:  # the drift runs then see the robot's new mismatch
            write(path, values_of(path, cal), keep=args.keep, complete=False, say=say)
            written.append(path)
        _say(f"the drift: {args.runs} fault-free runs of {args.scenario} with the robot")
        try:
            d = drift(args.model, args.scenario, overrides, args.runs)
        except ScenarioError as exc:  # e.g. a robot too big for the scenario as it is
            d = None
            first = str(exc).splitlines()[0]
            print(
                f"WARNING: the drift was not measured: {args.scenario} cannot run with this "
                f"robot ({first}); give the scenario keys it needs with --set"
            )
        if d is not None:
            print(
                f"drift in {d.scenario} ({d.runs} fault-free runs, noise at its bounds, "
                f"{', '.join(f'{k} = {v}' for k, v in overrides.items()) or 'as it is'}): "
                f"per period up to {d.period_max:.3g} m/s; split for xi_bar = {d.xi_bar:g} m/s, "
                f"a bounded offset of {d.drift_bound * 1000:.2f} mm from {d.settle:g} s on "
                f"({d.startup * 1000:.2f} mm with the start-up)"
            )
            if d.replan is not None:
                print(
                    f"re-plan transient: {d.excluded} exclusions in {d.replan_runs} runs with a "
                    f"stop; the healthy robots' offset within {REPLAN_WINDOW:g} s of each "
                    f"exclusion reached {d.replan * 1000:.2f} mm (avoidance switches are in "
                    "every run above)"
                )
            else:
                print(
                    "WARNING: re-plan transient not measured: no exclusion happened in the "
                    "runs with a stop"
                )
        cal = dataclasses.replace(cal, drift=d)
        if path is not None:
            write(path, values_of(path, cal), keep=args.keep, say=say)
            robots.load(path)  # it must still load
            print(f"written to {path}")
    except ScenarioError as exc:
        return cli.fail(exc)
    except OSError as exc:
        print(f"error: cannot write the calibration: {exc}", file=sys.stderr)
        return EXIT_OUTPUT
    return EXIT_OK


def on_plane(model: str) -> tuple[Calibration, dict[str, float]]:
    """:func:`.mismatch.measure` at the robot's physics step, and where the robot leaves the
    plane there, at each shorter step of :data:`.physics.STEPS` until it stays on it (the
    fix, stored as ``timestep``); with a skid steer's track measured first. A drive that
    stays on the plane (at the first step or at the one that kept it there) but whose
    mismatch on smooth commands takes more than :data:`.physics.CHATTER_SHARE` of its
    command range is measured at the shorter steps too (:func:`_calmer`). Returns the
    calibration and what it measured besides (``timestep``, ``track``); refuses in one
    line when no step keeps the robot on the plane."""
    robot = robot_with(model)
    first = min(TIMESTEP, robot.timestep)
    tried: list[tuple[float, Trouble]] = []  # (step, what went wrong there)
    for step in (first, *(s for s in STEPS if s < first)):
        measured = {"timestep": step} if step < TIMESTEP else {}
        if tried:
            _say(
                f"it left the plane at {tried[-1][0] * 1000:g} ms: measuring at {step * 1000:g} ms"
            )
        else:
            name, ms = robot.name, step * 1000
            _say(f"measuring how {name} follows its commands (one robot, a {ms:g} ms step)")
        try:
            cal = _measured_at(model, measured)
        except OffPlane as exc:
            tried.append((step, exc.trouble))
            continue
        if tried:
            step0, trouble = tried[0]
            print(
                f"WARNING: {trouble.line(step0)}, beyond what a run allows ({limits()}): its "
                f"drive runs away at that step; at {step * 1000:g} ms it stays on the plane"
            )
        cal, measured = _calmer(model, cal, measured, step)
        if tried and cal.timestep == step:  # else _calmer said where it calibrated
            print(
                f"calibrated at {step * 1000:g} ms (timestep = {step:g}: every run with this "
                "robot steps at it)"
            )
        return cal, measured
    (step0, trouble), (last, why) = tried[0], tried[-1]
    shorter = ", ".join(f"{s * 1000:g}" for s, _ in tried[1:])
    raise ScenarioError(
        f"{robot.path}: calibration refused, nothing written: {trouble.line(step0)}, beyond "
        f"what a run allows ({limits()}); at the shorter steps tried ({shorter} ms) it leaves "
        f"the plane too, {why.line(last)}: its model does not stay a planar robot under its "
        "drive's commands (check its wheels' contacts, its servos' gains and the pose its "
        "other joints hold)"
    )


def _measured_at(model: str, measured: dict[str, float]) -> Calibration:
    """:func:`.mismatch.measure` at ``measured``'s step (a skid steer's track measured
    first, into ``measured``)."""
    track = skid_track(model, measured)
    if track is not None:
        measured["track"] = track
    return measure(model, measured)


def _calmer(
    model: str, cal: Calibration, measured: dict[str, float], step: float
) -> tuple[Calibration, dict[str, float]]:
    """A drive that stayed on the plane at ``step`` but whose smooth mismatch takes more than
    :data:`.physics.CHATTER_SHARE` of its range may be a servo that chatters at that step
    (stiff velocity servos on light wheels, their force clamped: the base stays level, the
    wheels reverse every few steps). It is measured again at the shorter steps while each
    halves the mismatch again (and it is above the paper's ξ̄); the last that did is the
    fix (``timestep``). Where the first does not, the drive itself is slow: ``cal``
    stands."""
    if not cal.smooth_max > CHATTER_SHARE * cal.command_limit:
        return cal, measured
    best, kept, at = cal, measured, step
    for shorter in (s for s in STEPS if s < step and s >= CHATTER_STEPS_DOWN_TO):
        if best.smooth_max <= PAPER_XI_BAR:
            break  # calm enough: ξ̄ is the paper's whatever a shorter step gives
        again = {**measured, "timestep": shorter}
        share = best.smooth_max / best.command_limit
        _say(f"its mismatch takes {share:.0%} of its range: measuring at {shorter * 1000:g} ms")
        try:
            there = _measured_at(model, again)
        except OffPlane:
            continue
        if not there.smooth_max <= best.smooth_max / 2:
            break  # no longer the step's doing
        best, kept, at = there, again, shorter
    if best is not cal:
        mm = 1000.0
        print(
            f"WARNING: at {step * 1000:g} ms the drive's mismatch on smooth commands reaches "
            f"{cal.smooth_max * mm:.1f} mm/s, {cal.smooth_max / cal.command_limit:.0%} of its "
            f"command range: its servos chatter at that step; at {at * 1000:g} ms it is "
            f"{best.smooth_max * mm:.1f} mm/s: calibrated there (timestep = {at:g}: every run "
            "with this robot steps at it)"
        )
    return best, kept


def _say(what: str) -> None:
    """A line of progress before a measurement that takes a while (printed at once)."""
    print(f"{what} ...", flush=True)
