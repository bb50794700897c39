"""Cost of the run-time premise checks, timed call by call inside the closed loop.

    python benchmarks/bench_premises.py [--n 4 100] [--repeat 5] [--duration 20]

Each size runs the same scenario ``--repeat`` times in one process (numba's cache warm, a
first run discarded), ``Monitor.period`` timed at every call, and prints the median time of
one call and its share of the loop's wall time (set-up excluded).
"""

from __future__ import annotations

import argparse
import statistics
import time

from dftc_mujoco import Simulation, load_scenario
from dftc_mujoco.closed_loop import premises


def scenario(n: int, duration: float):
    if n == 4:
        return load_scenario("paper_case", {"duration": duration})
    return load_scenario(
        "paper_case",
        {
            "duration": duration,
            "obstacles": [],
            "team.robots": n,
            "team.initial_positions": {"layout": "formation", "jitter": 0.05},
            "team.graph": {"family": "ring_chords", "chords": [2]},
            "mission.formation": {"shape": "line", "side": 0.6},
            "onboard.thresholds": "l1",
            "fdir.initial_error_bound": "auto",
            "faults": [{"robot": 37, "kind": "stop", "t": duration / 2}],
        },
    )


def loop_time(s) -> float:
    with Simulation(s) as sim:
        t0 = time.perf_counter()
        sim.run(progress=False)
        return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, nargs="+", default=[4, 100])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--duration", type=float, default=20.0)
    a = ap.parse_args()
    print("| N | checks per period [us] | share of the loop |")
    print("|---|---|---|")
    for n in a.n:
        per, share = per_call(scenario(n, a.duration), a.repeat)
        print(f"| {n} | {per:.1f} | {share:.1f} % |")


def per_call(s, repeat: int) -> tuple[float, float]:
    """Median time of one ``Monitor.period`` call [us] and its share of the loop [%]."""
    original = premises.Monitor.period
    spent = [0.0, 0]

    def timed(self, *args):
        t0 = time.perf_counter()
        original(self, *args)
        spent[0] += time.perf_counter() - t0
        spent[1] += 1

    premises.Monitor.period = timed
    per, share = [], []
    try:
        for _ in range(repeat + 1):  # the first run warms the caches
            spent[:] = [0.0, 0]
            total = loop_time(s)
            per.append(1e6 * spent[0] / spent[1])
            share.append(100 * spent[0] / total)
    finally:
        premises.Monitor.period = original
    return statistics.median(per[1:]), statistics.median(share[1:])


if __name__ == "__main__":
    main()
