"""Compile the one-call control period in a background process, for the runs that follow.

On a cold numba cache a small team runs the general path (:mod:`.execution`), which
compiles in a third of the time, while this module, started as ``python -m
dftc_mujoco.warm`` at low priority, builds the same scenario and steps it once on the
compiled path: numba compiles exactly what the next run of such a team needs and keeps
it in its cache. The run itself does not wait for it; the process outlives the run if it
must (about half a minute on a 2-core machine) and then exits. One such process at a
time per cache: a lock file beside numba's cache.

The scenario reaches the process pickled on its standard input; what it prints goes to
``dftc-warm.log`` beside the lock, which a failed compilation leaves for a bug report.
"""

from __future__ import annotations

import fcntl
import os
import pickle
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING

if TYPE_CHECKING:
    from .scenario import Scenario

LOCK = "dftc-warm.lock"
LOG = "dftc-warm.log"


@dataclass
class Warming:
    """A background compilation under way (:func:`start`)."""

    process: subprocess.Popen[bytes]
    log: Path

    @property
    def done(self) -> bool:
        """The process has exited."""
        return self.process.poll() is not None


def _folder() -> Path:
    """numba's cache folder for the compiled period (where the lock and the log live)."""
    from .onboard.period import team_period_flat

    return Path(str(team_period_flat.stats.cache_path))


def _lock(folder: Path) -> IO[str] | None:
    """The lock file, held (None: another process holds it, or it cannot be made)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        f = open(folder / LOCK, "a")
    except OSError:
        return None
    try:
        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        f.close()
        return None
    return f


def start(scenario: Scenario, search: Sequence[Path] = ()) -> Warming | None:
    """Start compiling the compiled period for teams like ``scenario``'s in the background;
    None where another process is at it already or no process can be started."""
    folder = _folder()
    probe = _lock(folder)
    if probe is None:  # another one compiles now
        return None
    probe.close()  # the child takes it
    log = folder / LOG
    try:
        payload = pickle.dumps((scenario, [str(p) for p in search]))
        with open(log, "wb") as out:
            process = subprocess.Popen(
                [sys.executable, "-m", "dftc_mujoco.warm"],
                stdin=subprocess.PIPE,
                stdout=out,
                stderr=subprocess.STDOUT,
                start_new_session=True,  # a Ctrl-C of the run does not stop it
            )
        assert process.stdin is not None
        process.stdin.write(payload)
        process.stdin.close()
    except (OSError, pickle.PicklingError, TypeError, AttributeError):
        return None  # the run goes on; its next one will try again
    return Warming(process, log)


def main() -> int:
    """The background process: take the lock, build the scenario, step it once compiled."""
    try:
        os.nice(10)  # leave the machine to the run that started it
    except OSError:
        pass
    lock = _lock(_folder())
    if lock is None:
        return 0
    scenario, search = pickle.load(sys.stdin.buffer)
    from . import numba_cache
    from .execution import Execution
    from .loop import Simulation

    t0 = time.perf_counter()
    with Simulation(scenario, search=search, execution=Execution("compiled")) as sim:
        sim.step(1)
    spent = numba_cache.clock().total()
    print(f"compiled the control period for {scenario.name} in {spent:.1f} s "
          f"({time.perf_counter() - t0:.1f} s in all)")  # fmt: skip
    lock.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
