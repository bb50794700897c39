"""The two paths of the onboard control period, on paper_case.

    python benchmarks/bench_compiled.py [--reps 20000]

Times one control period of the team (``Team.step``, thresholds included) on
the compiled path (the paper's blocks' compiled functions composed in one
call, ``onboard/execution/period.py``) and on the general path (the same blocks called
one by one through their Python methods, as with a user's block), on the same
state after 10 s of paper_case. Both compute the same numbers bit for bit.
"""

from __future__ import annotations

import argparse
import copy
import statistics
import time

from dftc_mujoco import Simulation, load_scenario
from dftc_mujoco.onboard.execution import team as team_mod


def period_us(team: team_mod.Team, x, c, cd, reps: int) -> float:
    """Median of 5 timings of ``reps`` periods, µs per period."""
    times = []
    for _ in range(5):
        t = copy.deepcopy(team)
        t0 = time.perf_counter()
        for _ in range(reps):
            t.step(10.0, x, c, cd, x)
        times.append((time.perf_counter() - t0) / reps * 1e6)
    return statistics.median(times)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--reps", type=int, default=20000)
    args = p.parse_args()
    s = load_scenario("paper_case")
    with Simulation(s) as sim:
        sim.step(1000)
        team = sim.team
        x = sim.plant.positions()
        c, cd = sim.path.position[1000], sim.path.velocity[1000]
        compiled = period_us(team, x, c, cd, args.reps)
        team.compiled = False
        general = period_us(team, x, c, cd, args.reps)
    print(f"paper_case onboard period (N = {s.team.robots}), median of 5 x {args.reps}:")
    print(f"  compiled path {compiled:6.1f} us")
    print(f"  general path  {general:6.1f} us  ({general / compiled:.1f}x)")


if __name__ == "__main__":
    main()
