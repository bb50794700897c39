"""A large team's run on a busy machine: the shared pass against one thread, alone and beside
CPU-bound processes.

    python benchmarks/bench_busy.py [--n 1000] [--duration 5] [--hogs 2] [--repeat 2]

The scale benchmark's scene (``bench_scale.scene``) at ``--n`` robots, its loop stepped
``--duration`` s after a warm-up (numba's cache loaded, κ/λ computed), in this process:
with its pass over the N × N state shared between threads (``Execution(threads=None)``,
every core) and in one thread (``Execution(threads=1)``), alternately, ``--repeat`` times
each; first alone, then beside ``--hogs`` processes that each keep a core busy (a Python
loop). Printed: the median wall time of the loop and the CPU time the process used.

A process among 1 + hogs CPU-bound ones on C cores is given C / (1 + hogs) of a core:
its *fair share* of time is its one-thread time alone times (1 + hogs) / C. The shared pass
degrades gracefully when, beside the hogs, it takes no more than that (nothing in it spins:
a helper that is not scheduled leaves its rows to the calling thread).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

from bench_scale import scene

from dftc_mujoco.closed_loop.execution import Execution
from dftc_mujoco.closed_loop.loop import Simulation

HOG = "while True: pass"


def timed(n: int, duration: float, threads: int | None) -> tuple[float, float, int]:
    """(wall s, CPU s, threads the pass ran in) of ``duration`` s of the loop at N = ``n``."""
    with Simulation(scene(n, duration + 3.0), execution=Execution(threads=threads)) as sim:
        sim.step(10)  # the first periods: caches warm
        periods = round(duration / sim.dt)
        w0, c0 = time.perf_counter(), time.process_time()
        sim.step(periods)
        used = sim.team.config.threads if sim.team.shares else 1
        return time.perf_counter() - w0, time.process_time() - c0, used


def measure(n: int, duration: float, repeat: int) -> dict[str, tuple[float, float, int]]:
    """Median (wall, CPU, threads) of each way, alternately."""
    runs: dict[str, list[tuple[float, float, int]]] = {"shared": [], "one thread": []}
    for _ in range(repeat):
        runs["shared"].append(timed(n, duration, None))
        runs["one thread"].append(timed(n, duration, 1))
    return {
        k: (statistics.median(r[0] for r in v), statistics.median(r[1] for r in v), v[0][2])
        for k, v in runs.items()
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=1000)
    p.add_argument("--duration", type=float, default=5.0)
    p.add_argument("--hogs", type=int, default=2)
    p.add_argument("--repeat", type=int, default=2)
    args = p.parse_args()
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    timed(args.n, 1.0, None)  # set-up and caches, outside the timings
    alone = measure(args.n, args.duration, args.repeat)
    hogs = [subprocess.Popen([sys.executable, "-c", HOG]) for _ in range(args.hogs)]
    try:
        time.sleep(0.5)
        busy = measure(args.n, args.duration, args.repeat)
    finally:
        for h in hogs:
            h.kill()
            h.wait()
    print(f"N = {args.n}, {args.duration:g} s of the loop, {cores} cores, medians of {args.repeat}")
    for label, got in (("alone", alone), (f"beside {args.hogs} CPU-bound processes", busy)):
        for way, (wall, cpu, threads) in got.items():
            print(
                f"  {label:32s} {way:10s} ({threads} threads)  wall {wall:8.4f} s  CPU {cpu:8.4f} s"
            )
    fair = alone["one thread"][0] * (1 + args.hogs) / (cores or 1)
    shared = busy["shared"][0]
    print(
        f"  fair share beside the hogs: {fair:.4f} s (one thread alone × {1 + args.hogs} / "
        f"{cores}); the shared pass took {shared:.4f} s, {shared / fair:.2f} of it; "
        f"sharing saves {1 - alone['shared'][0] / alone['one thread'][0]:.0%} alone, "
        f"{1 - shared / busy['one thread'][0]:.0%} beside the hogs"
    )


if __name__ == "__main__":
    main()
