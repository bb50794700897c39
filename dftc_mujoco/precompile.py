"""``python -m dftc_mujoco.precompile``: compile the onboard code in the background.

Started by :func:`.warm.start` with a scenario pickled on its standard input, beside a first
run on the general path: it takes the lock beside numba's cache (or leaves at once when
another process holds it) and

1. compiles the general path's functions for the scenario in the opposite order to the
   run's: it steps a copy of the team two periods as plain Python to learn which functions
   the run calls with which types (:func:`.numba_cache.traced_calls`), then compiles the
   last first. The run, compiling from the first, loads from numba's cache each one this
   process finished, so the two share the compilation on a machine of two cores or more;
2. then, at low priority, builds the scenario and steps it once on the compiled path, so
   numba compiles and caches what the next run of such a team needs.

It says how long each took in the log :data:`.warm.LOG` beside the lock.
"""

from __future__ import annotations

import os
import pickle
import sys
import time

from .closed_loop import warm
from .closed_loop.execution import Execution
from .closed_loop.loop import Simulation
from .runtime import numba_cache
from .scenario import Scenario


def general(scenario: Scenario, search: list[str]) -> None:
    """Compile the general path's functions for ``scenario``, the run's last first."""
    t0 = time.perf_counter()
    with Simulation(scenario, search=search, execution=Execution("general")) as sim:
        calls = numba_cache.traced_calls(lambda: sim.step(2))
    for call in reversed(calls):
        call.compile()
    print(
        f"compiled the general path's {len(calls)} functions for {scenario.name} "
        f"({time.perf_counter() - t0:.1f} s in all)",
        flush=True,
    )


def main() -> int:
    """Take the lock, build the scenario read from standard input, compile its general path
    (the run's last function first), then step it once compiled."""
    held = warm.lock(warm.folder())
    if held is None:
        return 0
    scenario, search = pickle.load(sys.stdin.buffer)
    try:
        general(scenario, search)
    except Exception as exc:  # the run compiles them itself; the log keeps why
        print(f"the general path's functions were not compiled here: {exc!r}", flush=True)
    try:
        os.nice(10)  # the compiled period is for later runs: leave the machine to this one
    except OSError:
        pass
    t0, before = time.perf_counter(), numba_cache.clock().total()
    with Simulation(scenario, search=search, execution=Execution("compiled")) as sim:
        sim.step(1)
    spent = numba_cache.clock().total() - before
    print(
        f"compiled the control period for {scenario.name} in {spent:.1f} s "
        f"({time.perf_counter() - t0:.1f} s in all)"
    )
    held.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
