"""Compile the onboard code in a background process, beside a first run and for the runs
that follow.

On a cold numba cache a small team runs the general path (:mod:`.execution`), which
compiles in a third of the time, while :func:`start` runs ``python -m
dftc_mujoco.precompile``: it compiles the general path's functions from the other end
(the run loads each one it finished from the cache), then, at low priority, builds the
same scenario and steps it once on the compiled path, so numba compiles exactly what the
next run of such a team needs and keeps it in its cache. The run itself does not wait
for it; the process outlives the run if it must (about half a minute on a 2-core
machine) and then exits. One such process at a time per cache: a lock file beside
numba's cache.

The scenario reaches the process pickled on its standard input; what it prints goes to
``dftc-warm.log`` beside the lock, which a failed compilation leaves for a bug report.
"""

from __future__ import annotations

import fcntl
import pickle
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING

if TYPE_CHECKING:
    from ..scenario import Scenario

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


def folder() -> Path:
    """numba's cache folder for the compiled period (where the lock and the log live)."""
    from ..onboard.execution.period import team_period_call

    return Path(str(team_period_call.stats.cache_path))


def lock(where: Path) -> IO[str] | None:
    """The lock file in ``where``, held (None: another process holds it, or it cannot be
    made)."""
    try:
        where.mkdir(parents=True, exist_ok=True)
        f = open(where / LOCK, "a")
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
    where = folder()
    probe = lock(where)
    if probe is None:  # another one compiles now
        return None
    probe.close()  # the child takes it
    log = where / LOG
    try:
        payload = pickle.dumps((scenario, [str(p) for p in search]))
        with open(log, "wb") as out:
            process = subprocess.Popen(
                [sys.executable, "-m", "dftc_mujoco.precompile"],
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
