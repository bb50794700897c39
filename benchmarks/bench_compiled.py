"""The compiled team step (numba) against the numpy one, on paper_case.

    pip install -e ".[fast]"    # numba
    python benchmarks/bench_compiled.py

Times one control period of the onboard stacks (Team.step) both ways on the
same state, and the whole 60 s closed loop both ways (the numpy path is forced
by switching the kernel off), with bare mj_step for the ratio.
"""

from __future__ import annotations

import copy
import time

import numpy as np

from dftc_mujoco import loop, mission, scenario
from dftc_mujoco.onboard import kernel
from dftc_mujoco.onboard.team import Team


def step_us(team: Team, x: np.ndarray, c: np.ndarray, cd: np.ndarray, reps: int) -> float:
    t0 = time.perf_counter()
    for _ in range(reps):
        team.step(3.0, x, c, cd)
    return (time.perf_counter() - t0) / reps * 1e6


def loop_us(s: scenario.Scenario, repeat: int = 3) -> float:
    steps = round(s.duration / s.physics.control_period)
    best = min(
        (r.summary["wall_time"] - r.summary["build_time"])
        for r in (loop.simulate(s) for _ in range(repeat))
    )
    return best / steps * 1e6


def main() -> None:
    if not kernel.AVAILABLE:
        raise SystemExit('numba is not installed: pip install -e ".[fast]"')
    s = scenario.load("paper_case")
    dt = s.physics.control_period
    path = mission.centroid_table(s.mission.centroid, s.duration, dt)
    x = np.asarray(s.team.initial_positions, float).copy()
    fast = Team(loop.team_config(s, None, 1.0), x, path.position[0])
    for k in range(300):
        c, cd = path.at(k)
        x = x + dt * fast.step(k * dt, x, c, cd).u_bar
    slow = copy.deepcopy(fast)
    slow.compiled = False
    c, cd = path.at(300)
    fast.step(3.0, x, c, cd)  # compiled already; warm
    numpy_step = step_us(slow, x, c, cd, 20000)
    numba_step = step_us(fast, x, c, cd, 20000)
    loop.simulate(s)  # warm-up (imports, JIT cache)
    with_kernel = loop_us(s)
    kernel.AVAILABLE = False
    try:
        without = loop_us(s)
    finally:
        kernel.AVAILABLE = True
    import mujoco

    from dftc_mujoco.sim import robots, scene

    sc = scene.build(s, robots.get("disk"))
    data = mujoco.MjData(sc.model)
    steps = round(s.duration / dt)
    t0 = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(sc.model, data, nstep=s.physics.substeps)
    bare = (time.perf_counter() - t0) / steps * 1e6
    print(
        f"paper_case, N = {s.team.robots}: Team.step numpy {numpy_step:.1f} us, "
        f"numba {numba_step:.1f} us"
    )
    print(
        f"closed loop: numpy {without:.1f} us = {without / bare:.1f} x bare mj_step, "
        f"numba {with_kernel:.1f} us = {with_kernel / bare:.1f} x (bare {bare:.1f} us)"
    )


if __name__ == "__main__":
    main()
