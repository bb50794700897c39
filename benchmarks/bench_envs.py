"""Speed of the environments: a Gymnasium step against a simulator period, and steps per
second of many teams stepped together (Gymnasium's vector API).

    python benchmarks/bench_envs.py [--steps K] [--envs 1 8 32] [--repeat R]

What is timed, in CPU time of this process (``time.process_time``) unless said otherwise:

* **period**: ``Simulation.advance(K)`` on paper_case, the team's own commands, per period
  (sensing, the four robots' onboard blocks, the commands, five ``mj_step``, the premises'
  check, the log row);
* **env step**: ``env.step(action)`` of ``gymnasium.make("dftc/PaperCase-v0")`` driving robot
  3 with the team's last command (one control period plus the observation, the reward, the
  fault labels in ``info`` and Gymnasium's wrappers); the ratio env step / period is what
  the environment adds, and where it goes: one ``advance(1)`` call a period, then with
  robot 3 driven as the environment drives it (``Simulation.drive``);
* **vector**: ``gymnasium.make_vec(..., vectorization_mode="sync")`` with E teams in this
  process, wall-clock steps per second counted per team (E steps per vector step), the
  figure VMAS reports for its batched environments;
* **VMAS** (``--vmas``, when the ``vmas`` package is installed: it is not a dependency of
  this project): its ``navigation`` scenario with 4 agents, E batched environments on the
  CPU, wall-clock steps per second counted per environment, on the same machine.

Episodes restart when they end (the reset is not timed). Nothing here is asserted.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def _period_us(steps: int) -> float:
    from dftc_mujoco import Simulation, load_scenario

    with Simulation(load_scenario("paper_case", {"duration": 600.0})) as sim:
        sim.advance(50)  # past the start-up
        t0 = time.process_time()
        sim.advance(steps)
        return (time.process_time() - t0) / steps * 1e6


def _single_us(steps: int, driven: bool) -> float:
    """``advance(1)`` a period, robot 3 driven with the team's last command or not."""
    from dftc_mujoco import Simulation, load_scenario

    with Simulation(load_scenario("paper_case", {"duration": 600.0})) as sim:
        sim.advance(50)
        t0 = time.process_time()
        for _ in range(steps):
            if driven:
                u = sim.team.u_bar[2]
                sim.drive(2, (float(u[0]), float(u[1])))
            sim.advance(1)
        return (time.process_time() - t0) / steps * 1e6


def _env_step_us(steps: int) -> float:
    import gymnasium

    import dftc_mujoco.envs  # noqa: F401  (registers the ids)

    env = gymnasium.make("dftc/PaperCase-v0", overrides={"duration": 600.0})
    _, info = env.reset(seed=1)
    for _ in range(50):
        _, _, _, _, info = env.step(info["dftc_command"])
    # the clock is read around the whole loop, as for the period (a reading costs about
    # 0.6 us here); resets are timed apart and taken off
    resets = 0.0
    t0 = time.process_time()
    for _ in range(steps):
        _, _, terminated, truncated, info = env.step(info["dftc_command"])
        if terminated or truncated:
            r0 = time.process_time()
            _, info = env.reset()
            resets += time.process_time() - r0
    spent = time.process_time() - t0 - resets
    env.close()
    return spent / steps * 1e6


def _vector_rate(n_envs: int, steps: int) -> float:
    import gymnasium

    import dftc_mujoco.envs  # noqa: F401

    envs = gymnasium.make_vec(
        "dftc/PaperCase-v0",
        num_envs=n_envs,
        vectorization_mode="sync",
        overrides={"duration": 600.0},
    )
    _, info = envs.reset(seed=1)
    for _ in range(20):
        _, _, _, _, info = envs.step(np.asarray(info["dftc_command"], np.float32))
    t0 = time.perf_counter()
    for _ in range(steps):
        _, _, _, _, info = envs.step(np.asarray(info["dftc_command"], np.float32))
    wall = time.perf_counter() - t0
    envs.close()
    return n_envs * steps / wall


def _vmas_rate(n_envs: int, steps: int) -> float | None:
    try:
        import torch
        import vmas
    except ImportError:
        return None
    torch.set_num_threads(1)
    env = vmas.make_env(
        scenario="navigation",
        num_envs=n_envs,
        device="cpu",
        continuous_actions=True,
        n_agents=4,
        seed=0,
    )
    env.reset()
    actions = [torch.zeros(n_envs, 2) for _ in env.agents]
    for _ in range(20):
        env.step(actions)
    t0 = time.perf_counter()
    for _ in range(steps):
        env.step(actions)
    return n_envs * steps / (time.perf_counter() - t0)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=3000, help="steps timed per measure")
    p.add_argument("--envs", type=int, nargs="+", default=[1, 8, 32])
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--vmas", action="store_true", help="also time VMAS's navigation scenario")
    args = p.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    from targets import cpu_name

    print(f"{cpu_name()}, {os.cpu_count()} cores")
    period, single, driven, step = [], [], [], []
    for _ in range(args.repeat):  # alternating, so that a change of load hits all
        period.append(_period_us(args.steps))
        single.append(_single_us(args.steps, False))
        driven.append(_single_us(args.steps, True))
        step.append(_env_step_us(args.steps))
    pm, sm = float(np.median(period)), float(np.median(step))
    print(f"simulator period  {pm:7.1f} us CPU (median of {args.repeat}; best {min(period):.1f})")
    print(f"Gymnasium step    {sm:7.1f} us CPU (median of {args.repeat}; best {min(step):.1f})")
    print(f"ratio             {sm / pm:7.2f} (what the environment adds: {sm - pm:.1f} us)")
    one, drv = float(np.median(single)), float(np.median(driven))
    print(f"  {'one advance(1) call a period':50s} {one:7.1f} us")
    print(f"  {'... with robot 3 driven from outside':50s} {drv:7.1f} us")
    print(f"  {'... and the observation, reward, labels, wrappers':50s} {sm:7.1f} us")
    for n in args.envs:
        rates = [_vector_rate(n, max(1, args.steps // n)) for _ in range(args.repeat)]
        print(f"vector, {n:3d} teams: {np.median(rates):8.0f} team-steps/s (wall clock, median)")
    if args.vmas:
        for n in args.envs:
            got = [_vmas_rate(n, max(50, args.steps // n)) for _ in range(args.repeat)]
            if got[0] is None:
                print("VMAS: not installed (pip install vmas)")
                break
            rate = float(np.median([g for g in got if g is not None]))
            print(f"VMAS navigation, 4 agents, {n:3d} envs: {rate:8.0f} env-steps/s (wall clock)")


if __name__ == "__main__":
    main()
