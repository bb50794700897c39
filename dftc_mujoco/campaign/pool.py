"""The local engine: worker processes that run one campaign run at a time.

Each worker is a fresh interpreter (``spawn``) connected to the campaign by a pipe:
the campaign sends it a run's parameters, the worker sends back the run's row.
Unlike a ``concurrent.futures`` pool, the campaign decides what happens to every
run:

- it stops within a second when told to (a SIGINT / SIGTERM caught by the command
  line): queued runs are never sent, running ones are ended (SIGTERM, then SIGKILL)
  and nothing of theirs is recorded, so that running the campaign again runs them;
- a worker that dies (killed, out of memory, a crash in native code) costs only its
  run, recorded as failed with the cause, and is replaced;
- a worker never outlives the campaign, ``kill -9`` of the campaign included
  (:mod:`lifeline`), and ignores the terminal's Ctrl-C, which is the campaign's to
  handle.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import threading
import time
from collections.abc import Callable, Generator
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from typing import TYPE_CHECKING, Any

from . import lifeline
from .spec import Spec

if TYPE_CHECKING:
    from ..closed_loop.execution import Execution

POLL = 0.2  # s between two looks at the stop request while waiting for rows
GRACE = 3.0  # s a worker gets to end after SIGTERM before SIGKILL


def serve(conn: Connection, spec: Spec, parent: int, execution: Execution | None = None) -> None:
    """A worker's life: run what the campaign sends until it sends None or goes away, each
    run with ``execution`` (:meth:`Pool.execution`)."""
    lifeline.die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole process group
    from tqdm import tqdm

    # tqdm's default lock is a multiprocessing semaphore: a worker ended mid-run would
    # leave it to the resource tracker, which then warns about "leaked semaphores"
    tqdm.set_lock(threading.RLock())
    from .task import run_one

    while True:
        try:
            params = conn.recv()
        except (EOFError, OSError):
            return
        if params is None:
            return
        conn.send(run_one(spec, params, execution=execution))


@dataclass
class _Worker:
    process: Any  # multiprocessing's SpawnProcess
    conn: Connection
    params: dict[str, Any] | None = None


@dataclass
class Pool:
    """``workers`` processes running the runs of ``spec``; ``stop()`` True ends them."""

    spec: Spec
    workers: int
    stop: Callable[[], bool] = lambda: False
    running: int = 0  # runs that were running when the pool stopped early
    queued: int = 0  # runs never started because the pool stopped early
    _procs: list[_Worker] = field(default_factory=list)

    def _start(self) -> _Worker:
        ctx = mp.get_context("spawn")
        mine, theirs = ctx.Pipe(duplex=True)
        process = ctx.Process(
            target=serve,
            args=(theirs, self.spec, os.getpid(), self.execution()),
            name="dftc-campaign-worker",
        )
        # SIGINT is blocked while the worker starts, so that a Ctrl-C in that instant
        # neither reaches its half-started interpreter (it inherits the blocked mask and
        # then ignores SIGINT) nor is lost for the campaign (delivered when unblocked).
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            process.start()
        finally:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        theirs.close()
        worker = _Worker(process, mine)
        self._procs.append(worker)
        return worker

    def execution(self) -> Execution:
        """How each worker's runs execute: a large team's pass shared between threads only
        where every worker's threads have cores of their own (the cores this process may run
        on, shared by the workers; ``NUMBA_NUM_THREADS`` caps a worker's threads as it caps
        numba's); otherwise the workers share the cores between them, one thread each."""
        from ..closed_loop.execution import Execution

        if hasattr(os, "sched_getaffinity"):
            cores = len(os.sched_getaffinity(0))
        else:
            cores = os.cpu_count() or 1
        cap = int(os.environ.get("NUMBA_NUM_THREADS", "0")) or cores
        return Execution(threads=max(1, min(cap, cores // max(self.workers, 1))))

    def pids(self) -> list[int]:
        """The worker processes' ids."""
        return [w.process.pid for w in self._procs]

    def rows(self, todo: list[dict[str, Any]]) -> Generator[dict[str, Any], None, None]:
        """The rows of the runs ``todo``, in the order they finish."""
        queue = list(todo)
        try:
            for _ in range(min(self.workers, len(queue))):
                self._give(self._start(), queue)
            while any(w.params is not None for w in self._procs):
                if self.stop():
                    break
                ready = wait([w.conn for w in self._procs if w.params is not None], POLL)
                for conn in ready:
                    worker = next(w for w in self._procs if w.conn is conn)
                    row = self._receive(worker)
                    if row is None:  # the pool is stopping: the run is not recorded
                        break
                    yield row
                    if worker.process.is_alive():
                        self._give(worker, queue)
                    else:
                        self._procs.remove(worker)
                        if queue:
                            self._give(self._start(), queue)
            self.running = sum(w.params is not None for w in self._procs)
            self.queued = len(queue)
        finally:
            self._end()

    def _give(self, worker: _Worker, queue: list[dict[str, Any]]) -> None:
        worker.params = queue.pop(0) if queue else None
        if worker.params is not None:
            worker.conn.send(worker.params)

    def _receive(self, worker: _Worker) -> dict[str, Any] | None:
        """The worker's row; a failed row if it died; None if it died because the
        campaign is being stopped (a signal to the whole process group)."""
        params, worker.params = worker.params, None
        try:
            return worker.conn.recv()
        except (EOFError, OSError):
            pass
        worker.process.join(GRACE)
        deadline = time.monotonic() + 0.5  # a group-wide signal reaches the campaign too
        while time.monotonic() < deadline and not self.stop():
            time.sleep(0.05)
        if self.stop():
            worker.params = params  # still counted as running when the pool stops
            return None
        code = worker.process.exitcode
        cause = (
            f"killed by {signal.Signals(-code).name}"
            if code is not None and code < 0 and -code in signal.valid_signals()
            else f"exit code {code}"
        )
        row = dict(params or {})
        row["status"] = "failed"
        row["error"] = (
            f"the worker process running this run died ({cause}; out of memory?); "
            "the campaign went on"
        )
        row["wall_time"] = None
        return row

    def _end(self) -> None:
        """Every worker gone: asked to leave, then SIGTERM, then SIGKILL."""
        for w in self._procs:
            if w.params is None and w.process.is_alive():
                try:
                    w.conn.send(None)
                except OSError:
                    pass
            elif w.process.is_alive():
                w.process.terminate()
        deadline = time.monotonic() + GRACE
        for w in self._procs:
            w.process.join(max(0.0, deadline - time.monotonic()))
            if w.process.is_alive():
                w.process.kill()
                w.process.join(1.0)
            w.conn.close()
        self._procs.clear()
