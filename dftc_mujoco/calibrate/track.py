"""A skid steer's effective track: its wheels slip sideways as it turns, so it turns slower
than its wheels' speeds say over the distance between them.

A differential drive with several wheels a side (MuJoCo Menagerie's TIAGo++: four plain
wheels) is spun in place, its rims at ±:data:`SPIN_SHARE` of its command range, and the
track that its measured turn rate implies, 2 × rim speed / turn rate, is what the drive
then steers with (``[calibration] track``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import ScenarioError
from .mismatch import CONTROL_PERIOD, robot_with, step_for

SPIN_SHARE = 0.5
SETTLE, SPIN = 1.0, 4.0  # s at rest, then s spinning (the turn rate is read over its last half)
#: an effective track beyond this many times the wheels' own is a base that can hardly turn:
#: skid steers slip to 1.5-2.5 times theirs (a four-wheel test base: 2.0); a turn then asks
#: wheel speeds that many times those of a two-wheel drive, and the base scrubs off the plane
TRACK_RATIO_MAX = 4.0


def skid_track(name: str, measured: dict[str, float] | None = None) -> float | None:
    """The effective track of a skid steer [m] (None for any other robot)."""
    import mujoco

    from ..sim import scene
    from ..sim.plant import Plant

    robot = robot_with(name, measured)
    if robot.drive != "diffdrive" or robot.params.get("wheels", 2.0) <= 2:
        return None
    sc = scene.compose(robot, np.zeros((1, 2)), timestep=step_for(robot))
    data = Plant.initial_data(sc)
    drive: Any = robot.adapter(sc, data, CONTROL_PERIOD)
    rim = SPIN_SHARE * drive.command_limit
    spin = (drive.side * rim * drive.sign / drive.r)[None]  # right forward, left back
    nsub = round(CONTROL_PERIOD / sc.model.opt.timestep)
    ids, body = drive.controlled()[0], int(sc.body[0])
    yaw = []
    for k in range(round((SETTLE + SPIN) / CONTROL_PERIOD)):
        wheels = spin if k * CONTROL_PERIOD >= SETTLE else np.zeros_like(spin)
        data.ctrl[ids] = drive.actuation.command(wheels)[0]
        mujoco.mj_step(sc.model, data, nstep=nsub)
        mat = data.xmat[body]
        yaw.append(np.arctan2(mat[3], mat[0]))
    turned = np.unwrap(np.array(yaw))
    half = round(SPIN / 2 / CONTROL_PERIOD)
    rate = (turned[-1] - turned[-half]) / ((half - 1) * CONTROL_PERIOD)
    if not abs(rate) > 1e-3:
        raise ScenarioError(
            f"{robot.path}: calibration refused, nothing written: spun in place with its rims "
            f"at ±{rim:.3g} m/s, the skid steer does not turn (yaw rate {rate:.2g} rad/s): its "
            "wheels slip on the floor; it cannot be steered"
        )
    track = float(2.0 * rim / abs(rate))
    geometric = float(robot.params["axle_width"])
    if track > TRACK_RATIO_MAX * geometric:
        rot = data.xmat[body].reshape(3, 3)
        psi = robot.params.get("forward_angle", 0.0)
        ahead = rot @ np.array([np.cos(psi), np.sin(psi), 0.0])
        wheels = sc.model.dof_jntid[drive.actuation.dof_adr[0]]
        along = data.xanchor[wheels] @ ahead
        base = float(along.max() - along.min())
        raise ScenarioError(
            f"{robot.path}: calibration refused, nothing written: spun in place with its rims "
            f"at ±{rim:.3g} m/s, the skid steer turns at {geometric / track:.0%} of the rate "
            f"its wheels' speeds give over their {geometric:.3g} m track (its effective track "
            f"is {track:.3g} m, {track / geometric:.0f} times that; skid steers slip to 1.5-2.5 "
            f"times): its plain wheels, {base:.3g} m apart front to back, scrub sideways as it "
            "turns, so every turn would ask wheel speeds that many times a two-wheel drive's "
            "and drag the base off the plane. Model the rollers of its wheels (a mecanum or "
            'omni base is drive = "omni"), or drive it on one pair of wheels with the others '
            "free to swivel or slide (casters)"
        )
    return track
