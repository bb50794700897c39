"""Speed baseline: µs per control step of the whole closed loop vs bare ``mj_step``.

    python benchmarks/bench_step.py [SCENARIO] [--repeat R]

Both are measured on the same compiled scene: "bare" holds constant actuator
commands and calls ``mj_step(model, data, nstep=substeps)`` once per control
period; "loop" is :func:`dftc_mujoco.loop.simulate` (faults, sensing, the N
onboard stacks, logging at 50 Hz) minus its scene build time. The best of R
repeats is reported.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import mujoco
import numpy as np

from dftc_mujoco import loop, scenario
from dftc_mujoco.sim import robots, scene


def bare_step_us(s: scenario.Scenario, repeat: int) -> tuple[float, float]:
    """µs per control period of bare mj_step, and scene build time [s]."""
    t0 = time.perf_counter()
    sc = scene.build(s, robots.get(s.team.robot_model))
    build = time.perf_counter() - t0
    nsub = s.physics.substeps
    steps = round(s.duration / s.physics.control_period)
    best = np.inf
    for _ in range(repeat):
        data = mujoco.MjData(sc.model)
        data.ctrl[:] = 0.1
        t0 = time.perf_counter()
        for _ in range(steps):
            mujoco.mj_step(sc.model, data, nstep=nsub)
        best = min(best, time.perf_counter() - t0)
    return best / steps * 1e6, build


def loop_step_us(s: scenario.Scenario, repeat: int) -> tuple[float, float]:
    """µs per control period of the closed loop, and the run's real-time factor."""
    steps = round(s.duration / s.physics.control_period)
    best = np.inf
    for _ in range(repeat):
        r = loop.simulate(s)
        best = min(best, r.summary["wall_time"] - r.summary["build_time"])
    return best / steps * 1e6, s.duration / best


def cpu_name() -> str:
    """The CPU model from /proc/cpuinfo (Linux), else what platform knows."""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenario", nargs="?", default="paper_case")
    p.add_argument("--repeat", type=int, default=3)
    args = p.parse_args()
    s = scenario.load(args.scenario)
    bare, build = bare_step_us(s, args.repeat)
    full, rtf = loop_step_us(s, args.repeat)
    print(
        f"machine: {cpu_name()}, {os.cpu_count()} cores, {platform.system()}, "
        f"python {platform.python_version()}, mujoco {mujoco.__version__}, "
        f"numpy {np.__version__}"
    )
    print(
        f"scenario: {s.name}, N = {s.team.robots}, {s.duration:g} s, control period "
        f"{s.physics.control_period * 1e3:g} ms = {s.physics.substeps} x mj_step"
    )
    print(f"{'scene build':>24}: {build * 1e3:8.1f} ms")
    print(f"{'bare mj_step':>24}: {bare:8.1f} us per control step")
    print(f"{'closed loop':>24}: {full:8.1f} us per control step")
    print(f"{'ratio loop / bare':>24}: {full / bare:8.1f}")
    print(f"{'real-time factor':>24}: {rtf:8.1f} x")


if __name__ == "__main__":
    main()
