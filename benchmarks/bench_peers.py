"""Peers side by side: the same formation task on MuJoCo with a plain numpy controller, on
PyBullet, on VMAS, and as the full DFTC loop.

    python benchmarks/bench_peers.py [--n 4 100 400] [--duration 10] [--peers ...]

The task is :mod:`bench_scale`'s scene (one run of its ``scene(n, duration)`` gives it): N
robots of 0.1 m radius start on a grid of 0.5 m spacing with 5 cm of jitter, and each tracks
its slot of the grid formation while the centroid moves along x at 0.1 m/s, commanding the
velocity u_i = ẋ_d,i + k_c (x_d,i − x_i) (k_c = 4) at 100 Hz, with the physics at 2 ms (5
steps a period) and robot–robot contacts on. Every peer is given the same starts and the same
desired positions and velocities, computed before its timing.

- ``mujoco``: the scene's own MJCF (the disk robot's x/y velocity servos), the controller in
  numpy, ``mj_step`` 5 steps a period: what a user writes without this project.
- ``pybullet``: N cylinders on a frictionless plane in ``DIRECT`` mode, each told its velocity
  every period (``resetBaseVelocity``), 5 ``stepSimulation`` calls a period.
- ``vmas``: N disk agents in one CPU environment (``num_envs=1``), world dt 0.01 s in 5
  substeps, no drag, each agent's force a velocity servo (50 N·s/m) on the same command.
- ``dftc``: this project's closed loop on the scene itself (observers, controller,
  supervisor, fault estimator, decision, the premises monitor and the log; the scene's stop
  fault at half time and its exclusion included).

Reported per peer and N: µs per control period of the loop alone (best of ``--repeat``,
after a warm-up), the real-time factor that gives, and the largest distance of a robot from
its slot at the end (each peer does the task; the DFTC row's faulty robot is left out, and
its slots are the re-planned formation's once the stop is excluded).
PyBullet and VMAS are not dependencies of this project: a peer that is not installed is
reported as such (``pip install pybullet vmas``).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

KC = 4.0  # the scene's k_c (bench_scale: gains.kc)
PEERS = ("mujoco", "pybullet", "vmas", "dftc")
MODULE = {"mujoco": "mujoco", "pybullet": "pybullet", "vmas": "vmas", "dftc": "dftc_mujoco"}


@dataclass
class Task:
    """The formation task of bench_scale's scene for ``n`` robots over ``periods`` periods."""

    n: int
    dt: float  # the control period [s]
    nsub: int  # physics steps a period
    start: np.ndarray  # (N, 2) the robots' start positions
    x_d: np.ndarray  # (K, N, 2) the desired positions of every period
    xd_dot: np.ndarray  # (K, N, 2) and velocities
    scenario: object  # bench_scale's scenario (the DFTC row runs it)

    @property
    def periods(self) -> int:
        return len(self.x_d)


def task(n: int, duration: float) -> Task:
    """The task, read from the scene's own mission (its slots blend in over its transient)."""
    from bench_scale import scene

    from dftc_mujoco import Simulation

    s = scene(n, duration)
    with Simulation(s) as sim:
        start = sim.plant.positions()
        k = sim.steps
        x_d, xd_dot = np.empty((k, n, 2)), np.empty((k, n, 2))
        for j in range(k):
            offsets, rates = sim.team.plan.at(j * sim.dt)
            x_d[j] = sim.path.position[j] + offsets
            xd_dot[j] = sim.path.velocity[j] + rates
        return Task(n, sim.dt, s.physics.substeps, start, x_d, xd_dot, s)


def run_mujoco(t: Task) -> tuple[float, float]:
    """(seconds of the loop, final largest slot error): the scene's MJCF, numpy control."""
    import mujoco

    from dftc_mujoco import Simulation
    from dftc_mujoco.sim.plant import Plant

    with Simulation(t.scenario) as sim:
        model, data = sim.model, Plant.initial_data(sim.scene)
        site = np.array(sim.plant._site)
    ctrl = data.ctrl  # robot i's vx, vy at 2i, 2i + 1 (the disk's velocity servos)
    if ctrl.size != 2 * t.n:
        raise SystemExit(f"mujoco peer: expected 2 actuators a robot, the model has {ctrl.size}")
    x_d, xd_dot, nsub = t.x_d, t.xd_dot, t.nsub
    t0 = time.perf_counter()
    for k in range(t.periods):
        x = data.site_xpos[site, :2]
        u = xd_dot[k] + KC * (x_d[k] - x)
        ctrl[:] = u.ravel()
        mujoco.mj_step(model, data, nstep=nsub)
    wall = time.perf_counter() - t0
    return wall, float(np.abs(data.site_xpos[site, :2] - x_d[-1]).max())


def run_pybullet(t: Task) -> tuple[float, float]:
    """N cylinders on a frictionless plane, velocities set every period."""
    import pybullet as p

    cid = p.connect(p.DIRECT)
    try:
        p.setTimeStep(t.dt / t.nsub, physicsClientId=cid)
        p.setGravity(0, 0, -9.81, physicsClientId=cid)
        plane = p.createMultiBody(
            0, p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid), physicsClientId=cid
        )
        p.changeDynamics(plane, -1, lateralFriction=0.0, physicsClientId=cid)
        shape = p.createCollisionShape(p.GEOM_CYLINDER, radius=0.1, height=0.1, physicsClientId=cid)
        bodies = [
            p.createMultiBody(1.0, shape, basePosition=[x, y, 0.05], physicsClientId=cid)
            for x, y in t.start
        ]
        for b in bodies:
            p.changeDynamics(b, -1, lateralFriction=0.0, physicsClientId=cid)
        x = np.empty((t.n, 2))
        t0 = time.perf_counter()
        for k in range(t.periods):
            for i, b in enumerate(bodies):
                x[i] = p.getBasePositionAndOrientation(b, physicsClientId=cid)[0][:2]
            u = t.xd_dot[k] + KC * (t.x_d[k] - x)
            for i, b in enumerate(bodies):
                p.resetBaseVelocity(b, [u[i, 0], u[i, 1], 0.0], physicsClientId=cid)
            for _ in range(t.nsub):
                p.stepSimulation(physicsClientId=cid)
        wall = time.perf_counter() - t0
        for i, b in enumerate(bodies):
            x[i] = p.getBasePositionAndOrientation(b, physicsClientId=cid)[0][:2]
        return wall, float(np.abs(x - t.x_d[-1]).max())
    finally:
        p.disconnect(cid)


def run_vmas(t: Task) -> tuple[float, float]:
    """N disk agents in one CPU environment, forces servoing the commanded velocity."""
    import torch
    from vmas import make_env
    from vmas.simulator.core import Agent, Sphere, World
    from vmas.simulator.scenario import BaseScenario

    servo = 50.0  # N·s/m: the force that makes an agent of 1 kg follow its command

    class Formation(BaseScenario):
        def make_world(self, batch_dim, device, **kwargs):
            world = World(batch_dim, device, dt=t.dt, substeps=t.nsub, drag=0.0)
            for i in range(t.n):
                world.add_agent(Agent(name=f"robot{i + 1}", shape=Sphere(0.1), u_range=200.0))
            return world

        def reset_world_at(self, env_index=None):
            for i, agent in enumerate(self.world.agents):
                pos = torch.tensor(t.start[i], dtype=torch.float32).expand(self.world.batch_dim, 2)
                agent.set_pos(pos, batch_index=env_index)

        def observation(self, agent):
            return agent.state.pos

        def reward(self, agent):
            return torch.zeros(self.world.batch_dim)

    env = make_env(Formation(), num_envs=1, device="cpu", continuous_actions=True, seed=0)
    env.reset()
    agents = env.agents
    t0 = time.perf_counter()
    for k in range(t.periods):
        x = torch.stack([a.state.pos[0] for a in agents]).double().numpy()
        v = torch.stack([a.state.vel[0] for a in agents]).double().numpy()
        u = t.xd_dot[k] + KC * (t.x_d[k] - x)
        force = torch.from_numpy(servo * (u - v)).float()
        env.step([force[i : i + 1] for i in range(t.n)])
    wall = time.perf_counter() - t0
    x = torch.stack([a.state.pos[0] for a in agents]).double().numpy()
    return wall, float(np.abs(x - t.x_d[-1]).max())


def run_dftc(t: Task) -> tuple[float, float]:
    """The full closed loop on the scene itself."""
    from dftc_mujoco import Simulation

    with Simulation(t.scenario) as sim:
        t0 = time.perf_counter()
        sim.step(t.periods)
        wall = time.perf_counter() - t0
        # the members' own slots (the formation is re-planned once the stop is excluded), the
        # faulty robots left out
        members = sim.team.members
        healthy = ~np.isin(members, [f.robot for f in sim.scenario.faults])
        err = np.abs(sim.plant.positions()[members] - sim.team.x_d)[healthy]
    return wall, float(err.max())


RUN = {"mujoco": run_mujoco, "pybullet": run_pybullet, "vmas": run_vmas, "dftc": run_dftc}


def measure(peer: str, t: Task, repeat: int) -> tuple[float, float]:
    """(µs per period, final slot error): the best of ``repeat`` after one warm-up run."""
    RUN[peer](t)
    best, err = np.inf, np.nan
    for _ in range(repeat):
        wall, err = RUN[peer](t)
        best = min(best, wall)
    return best / t.periods * 1e6, err


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[4, 100, 400])
    ap.add_argument("--duration", type=float, default=10.0, help="simulated seconds a run")
    ap.add_argument("--peers", nargs="+", choices=PEERS, default=list(PEERS))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument(
        "--vmas-periods",
        type=int,
        default=200,
        help="VMAS runs this many periods at most (it is slow at large N)",
    )
    args = ap.parse_args()
    missing = [p for p in args.peers if importlib.util.find_spec(MODULE[p]) is None]
    for p in missing:
        print(f"{p}: not installed, left out (pip install {MODULE[p]})")
    peers = [p for p in args.peers if p not in missing]
    print(
        f"{os.cpu_count()} cores; {args.duration:g} s of the task per N (VMAS at most "
        f"{args.vmas_periods} periods); µs per control period, best of {args.repeat}"
    )
    print(f"{'N':>5} {'peer':>9} {'µs/period':>11} {'real time':>10} {'slot error':>11}")
    for n in args.n:
        t = task(n, args.duration)
        for peer in peers:
            tp = t
            if peer == "vmas" and t.periods > args.vmas_periods:
                k = args.vmas_periods
                tp = Task(n, t.dt, t.nsub, t.start, t.x_d[:k], t.xd_dot[:k], t.scenario)
            us, err = measure(peer, tp, args.repeat)
            rtf = t.dt * 1e6 / us
            print(f"{n:>5} {peer:>9} {us:>11.1f} {rtf:>9.3g}x {err:>10.3f}m", flush=True)


if __name__ == "__main__":
    main()
