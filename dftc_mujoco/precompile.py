"""``python -m dftc_mujoco.precompile``: compile the one-call control period in the background.

Started by :func:`.warm.start` at low priority with a scenario pickled on its standard
input: it takes the lock beside numba's cache (or leaves at once when another process
holds it), builds the scenario and steps it once on the compiled path, so numba compiles
and caches what the next run of such a team needs, then says how long it took (in the log
:data:`.warm.LOG` beside the lock).
"""

from __future__ import annotations

import os
import pickle
import sys
import time

from . import numba_cache, warm
from .execution import Execution
from .loop import Simulation


def main() -> int:
    """Take the lock, build the scenario read from standard input, step it once compiled."""
    try:
        os.nice(10)  # leave the machine to the run that started it
    except OSError:
        pass
    held = warm.lock(warm.folder())
    if held is None:
        return 0
    scenario, search = pickle.load(sys.stdin.buffer)
    t0 = time.perf_counter()
    with Simulation(scenario, search=search, execution=Execution("compiled")) as sim:
        sim.step(1)
    spent = numba_cache.clock().total()
    print(
        f"compiled the control period for {scenario.name} in {spent:.1f} s "
        f"({time.perf_counter() - t0:.1f} s in all)"
    )
    held.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
