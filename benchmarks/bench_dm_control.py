"""The scene in dm_control: does ``Physics`` load it and step it as the simulator does, and
what would composing it with dm_control's ``mjcf`` cost?

    python benchmarks/bench_dm_control.py [--n 4 100] [--repeat 3]

For each built-in robot (paper_case's scene): dm_control's version, whether
``dm_control.mujoco.Physics.from_xml_string(sim.scene_xml())`` loads the scene, and the
largest difference of qpos from the simulator's own model over 300 MuJoCo steps driven by
the same commands (paper_case's first 0.6 s, the commands the team applied).

For each N (disk robots on a grid 0.5 m apart), the median over ``--repeat`` of: composing
and compiling the scene with ``MjSpec`` (``sim.scene.compose``, what the simulator does),
writing it as MJCF (``scene_xml``), loading that text in dm_control's ``Physics``, and
composing the same robots with dm_control's ``mjcf`` (``attach`` of each robot's model into
an arena, then ``Physics.from_mjcf_model``), with the bodies each way gives.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np


def parity(robot: str) -> float:
    """Largest |qpos - qpos'| over 300 steps: the simulator against dm_control's Physics."""
    from dm_control import mujoco as dm_mujoco

    from dftc_mujoco import Simulation, load_scenario

    applied = []
    with Simulation(
        load_scenario("paper_case", {"team.robot_model": robot}),
        hook=lambda t, plant: applied.append((plant.data.ctrl.copy(), plant.data.qpos.copy())),
    ) as sim:
        xml, substeps = sim.scene_xml(), sim.scenario.physics.substeps
        sim.step(60)
    physics = dm_mujoco.Physics.from_xml_string(xml)
    physics.reset(0)
    worst = 0.0
    for ctrl, qpos in applied:
        physics.data.ctrl[:] = ctrl
        physics.step(substeps)
        worst = max(worst, float(np.abs(physics.data.qpos - qpos).max()))
    return worst


def timings(n: int) -> dict[str, float]:
    """Seconds for each way of making the scene of n disks, and the bodies it has."""
    from dm_control import mjcf
    from dm_control import mujoco as dm_mujoco

    from dftc_mujoco.runtime.paths import MODELS
    from dftc_mujoco.sim import mjcf as scene_mjcf
    from dftc_mujoco.sim import robots, scene

    side = int(np.ceil(np.sqrt(n)))
    positions = np.array([[0.5 * (i % side), 0.5 * (i // side)] for i in range(n)])
    disk = robots.get("disk")
    out: dict[str, float] = {}
    t0 = time.perf_counter()
    made = scene.compose(disk, positions)
    out["MjSpec compose"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    text = scene_mjcf.scene_xml(made)
    out["scene_xml"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    physics = dm_mujoco.Physics.from_xml_string(text)
    out["Physics from the text"] = time.perf_counter() - t0
    out["bodies (MjSpec)"] = physics.model.nbody
    t0 = time.perf_counter()
    arena = mjcf.from_path(str(MODELS / "arena.xml"))
    for i, (x, y) in enumerate(positions):
        robot = mjcf.from_path(str(disk.mjcf))
        robot.model = f"robot{i + 1}"
        arena.attach(robot).pos = [x, y, 0.0]
    composed = mjcf.Physics.from_mjcf_model(arena)
    out["dm_control mjcf compose"] = time.perf_counter() - t0
    out["bodies (mjcf)"] = composed.model.nbody
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, nargs="+", default=[4, 100])
    p.add_argument("--repeat", type=int, default=3)
    args = p.parse_args()
    from importlib.metadata import version

    print(f"mujoco {version('mujoco')}, dm_control {version('dm-control')}")
    for robot in ("disk", "hexbot", "diffdrive"):
        print(f"{robot:<10} Physics.from_xml_string(sim.scene_xml()): loads; largest qpos "
              f"difference over 300 steps: {parity(robot):.3g} m")  # fmt: skip
    for n in args.n:
        runs = [timings(n) for _ in range(args.repeat)]
        cells = [f"{k} {statistics.median(r[k] for r in runs):.4g}" for k in runs[0]]
        print(f"N = {n:<4} " + ", ".join(cells) + " (seconds; bodies)")


if __name__ == "__main__":
    main()
