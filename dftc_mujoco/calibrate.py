"""``python -m dftc_mujoco.calibrate MODEL``: measure a robot model's mismatch ‖ẋ − u‖.

The paper models every robot as ẋ = u + φ + ξ with ‖ξ‖ ≤ ξ̄ (eqs. 1-2). A
real body (mass, actuator lag, wheels, friction) is not an integrator: this
drives one robot of the model, alone and noise-free, through representative
planar velocity commands at the control rate, and measures how far the
velocity of its controlled point is from the command. Command programme:
ramps to the paper's speed (0.1 m/s) and beyond (0.3, 0.5 m/s) at 0.25 m/s²,
turns on circles of 0.5 and 1 m, a figure-eight, and command jumps (steps,
a 90° switch, a reversal). Samples within ``JUMP_WINDOW`` s after a jump
count as "with jumps" only.

The recommended ξ̄ is the largest mismatch on smooth commands, rounded up to
0.5 mm/s, and never below the paper's 5 mm/s; ``--write`` stores the measured
mismatch and the recommendation in the model file. Exit codes: 0, 2 bad input.
"""

from __future__ import annotations

import math
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import ScenarioError

PAPER_XI_BAR = 0.005
JUMP_WINDOW = 0.5  # s after a command jump that count as jump-affected
CONTROL_PERIOD = 0.01
TIMESTEP = 0.002


@dataclass(frozen=True)
class Programme:
    """Planar commands (K, 2) at the control rate, and where they jump."""

    u: np.ndarray
    jump: np.ndarray  # (K,) bool: sample within JUMP_WINDOW after a jump


def programme(dt: float = CONTROL_PERIOD) -> Programme:
    """The command programme described in the module docstring."""
    parts: list[np.ndarray] = []
    jumps: list[int] = []

    def add(u: np.ndarray, jump: bool = False) -> None:
        if jump:
            jumps.append(sum(len(p) for p in parts))
        parts.append(np.atleast_2d(u))

    def hold(v, seconds, jump=False):
        add(np.tile(v, (round(seconds / dt), 1)), jump)

    def ramp(v0, v1, accel=0.25):
        v0, v1 = np.asarray(v0, float), np.asarray(v1, float)
        k = max(1, round(np.linalg.norm(v1 - v0) / accel / dt))
        add(v0 + np.outer(np.arange(1, k + 1) / k, v1 - v0))

    hold([0.0, 0.0], 1.0)
    ramp([0, 0], [0.1, 0])
    hold([0.1, 0.0], 3.0)
    ramp([0.1, 0], [0.3, 0])
    hold([0.3, 0.0], 2.0)
    ramp([0.3, 0], [0.5, 0])
    hold([0.5, 0.0], 1.0)
    ramp([0.5, 0], [0.1, 0])
    for radius, speed in ((0.5, 0.1), (1.0, 0.3)):  # turns: direction rotates at v/R
        ramp([0.1, 0], [speed, 0])
        k = round(2 * np.pi * radius / speed / dt)
        ang = np.arange(1, k + 1) * dt * speed / radius
        add(speed * np.stack([np.cos(ang), np.sin(ang)], axis=1))
        ramp([speed, 0], [0.1, 0])
    k = round(20 / dt)  # figure-eight at up to ~0.25 m/s
    tt = np.arange(1, k + 1) * dt
    w = 2 * np.pi / 20
    fig8 = np.stack([0.1 * np.cos(w * tt), 0.2 * np.sin(2 * w * tt)], axis=1)
    add(fig8)
    ramp(fig8[-1], [0, 0])
    hold([0.3, 0.0], 2.0, jump=True)  # step 0 -> 0.3 m/s
    hold([0.0, 0.3], 2.0, jump=True)  # 90° switch
    hold([0.0, -0.3], 2.0, jump=True)  # reversal
    hold([0.0, 0.0], 1.0, jump=True)  # stop
    u = np.vstack(parts)
    jump = np.zeros(len(u), bool)
    width = round(JUMP_WINDOW / dt)
    for j in jumps:
        jump[j : j + width] = True
    return Programme(u, jump)


@dataclass(frozen=True)
class Calibration:
    """What calibrate measured for one model."""

    model: str
    smooth_max: float
    smooth_p99: float
    all_max: float
    all_p99: float
    samples: int
    jump_samples: int

    @property
    def recommended_xi_bar(self) -> float:
        """ξ̄ that follows: the smooth-command maximum, up to 0.5 mm/s, at least the paper's."""
        return max(PAPER_XI_BAR, math.ceil(self.smooth_max / 0.0005 - 1e-9) * 0.0005)


def measure(name: str) -> Calibration:
    """Drive one robot of model ``name`` through :func:`programme` and measure ‖ẋ − u‖."""
    import mujoco

    from .sim import robots, scene

    robot = robots.get(name, where="MODEL")
    sc = scene.compose(robot, np.zeros((1, 2)), timestep=TIMESTEP)
    data = mujoco.MjData(sc.model)
    adapter = robot.adapter(sc, data)
    mujoco.mj_forward(sc.model, data)
    prog = programme()
    nsub = round(CONTROL_PERIOD / TIMESTEP)
    mismatch = np.empty(len(prog.u))
    vel = np.empty(6)
    site = int(sc.site[0])
    for k, u in enumerate(prog.u):
        data.ctrl[sc.actuator[0]] = adapter.command(u[None])[0]
        mujoco.mj_step(sc.model, data, nstep=nsub)
        mujoco.mj_objectVelocity(sc.model, data, mujoco.mjtObj.mjOBJ_SITE, site, vel, 0)
        mismatch[k] = np.hypot(vel[3] - u[0], vel[4] - u[1])
        if data.warning.number.any() or not np.isfinite(data.qvel).all():
            raise ScenarioError(
                f"{robot.path}: the physics failed during calibration at t = {data.time:.2f} s"
            )
    smooth = mismatch[~prog.jump]
    return Calibration(
        robot.name,
        float(smooth.max()),
        float(np.percentile(smooth, 99)),
        float(mismatch.max()),
        float(np.percentile(mismatch, 99)),
        len(mismatch),
        int(prog.jump.sum()),
    )


def write(path: Path, cal: Calibration) -> None:
    """Store the measured mismatch and the recommended ξ̄ in the model file's <custom>."""
    text = path.read_text()
    for key, value in (("dftc_mismatch", cal.smooth_max), ("dftc_xi_bar", cal.recommended_xi_bar)):
        line = f'<numeric name="{key}" data="{value:.6g}"/>'
        pattern = re.compile(rf'<numeric name="{key}" data="[^"]*"\s*/>')
        if pattern.search(text):
            text = pattern.sub(line, text)
        elif "<custom>" in text:
            text = text.replace("<custom>", f"<custom>\n    {line}", 1)
        else:
            raise ScenarioError(f"{path}: no <custom> block to write {key} into")
    path.write_text(text)


def report(cal: Calibration) -> str:
    """The table printed by the command."""
    mm = 1000.0
    return "\n".join(
        [
            f"model {cal.model}: ‖ẋ − u‖ of the controlled point over {cal.samples} commands "
            f"at {1 / CONTROL_PERIOD:g} Hz ({cal.jump_samples} within {JUMP_WINDOW:g} s of a jump)",
            f"{'':24}{'max':>10}{'99th pct':>10}   [mm/s]",
            f"{'smooth commands':24}{cal.smooth_max * mm:10.2f}{cal.smooth_p99 * mm:10.2f}",
            f"{'with command jumps':24}{cal.all_max * mm:10.2f}{cal.all_p99 * mm:10.2f}",
            f"recommended xi_bar: {cal.recommended_xi_bar:g} m/s "
            f"(smooth maximum rounded up, at least the paper's {PAPER_XI_BAR:g})",
        ]
    )


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    from . import cli
    from .sim import robots

    p = cli.parser(
        "dftc_mujoco.calibrate", "dftc-calibrate", "Measure a robot model's mismatch from ẋ = u."
    )
    p.add_argument("model", help=f"a model name ({', '.join(robots.available())}) or an MJCF path")
    p.add_argument(
        "--write",
        action="store_true",
        help="store the measured mismatch and the recommended xi_bar in the model file",
    )
    args = p.parse_args(argv)
    try:
        cal = measure(args.model)
        print(report(cal))
        if args.write:
            path = robots.get(args.model, where="MODEL").path
            write(path, cal)
            print(f"written to {path}")
    except ScenarioError as exc:
        cli.print_error(exc)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
