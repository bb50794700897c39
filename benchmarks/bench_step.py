"""Speed of the closed loop as a ratio to bare ``mj_step`` replaying the run's own commands.

    python benchmarks/bench_step.py [SCENARIO] [--repeat R] [--general]

See ``benchmarks/replay.py`` for what is timed. ``--general`` forces the
general path (the blocks' Python methods, as with a user's block) instead of
the compiled period. Target for paper_case: ratio <= 3.
"""

from __future__ import annotations

import argparse
import os

import numpy as np
from replay import measure
from targets import cpu_name

from dftc_mujoco import load_scenario


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenario", nargs="?", default="paper_case")
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--general", action="store_true", help="force the general (Python) path")
    args = p.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    s = load_scenario(args.scenario)
    if args.general:
        os.environ["DFTC_PERIOD"] = "general"
    r = measure(s, args.repeat)
    print(f"{cpu_name()}, {os.cpu_count()} cores, numpy {np.__version__}")
    print(
        f"{s.name}: N = {s.team.robots}, {r['periods']} control periods, path {r['path']}, "
        f"{args.repeat} repeats (median, best)"
    )
    print(f"  loop  {r['loop_us']:7.1f} us  {r['loop_best_us']:7.1f} us per control period")
    print(
        f"  bare  {r['bare_us']:7.1f} us  {r['bare_best_us']:7.1f} us (mj_step replaying the run"
        f"{', its final state bit-identical' if r['exact'] else ', NOT the same final state'})"
    )
    print(f"  ratio {r['ratio']:7.2f}")
    print(
        f"  set-up {r['setup_s'] * 1e3:.0f} ms, post-run derivation {r['derive_s'] * 1e3:.0f} ms, "
        f"real time x{s.duration / (r['loop_us'] * r['periods'] * 1e-6):.0f} (loop only)"
    )


if __name__ == "__main__":
    main()
