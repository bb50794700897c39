"""A pass over the team's robots shared between threads, while the caller does other work.

The pass over the N × N state (:func:`~.period.team_rows`) treats each robot's row apart
from the others, so disjoint ranges of robots can run at once in threads (the compiled
pass holds no lock on Python), and the numbers do not depend on who ran which row.
:meth:`Sharing.start` hands the pass to helper threads, which take it in chunks of rows;
the calling thread meanwhile sends the period's commands and steps the physics (neither
needs anything the pass writes), then :meth:`Sharing.finish` has it take the chunks that
are left and waits for the helpers' last ones.

Nothing spins: a helper that finds no chunk left returns to the pool and sleeps, and the
caller waits on the helpers' futures. On a busy machine a helper that is not scheduled
takes fewer chunks and the caller more; the caller never waits longer than one chunk
for a helper that has begun one (``benchmarks/bench_busy.py``).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor, wait
from itertools import count
from typing import Any

#: robot pairs a chunk of rows holds at least (the pass costs a few ns a pair; a chunk's
#: compiled call a few µs): about 0.1 ms of work a chunk
PAIRS = 1 << 15

_pool: ThreadPoolExecutor | None = None
_pool_of = (0, 0)  # the process that made it, and its threads


def _helpers(count: int) -> ThreadPoolExecutor:
    """The process's helper threads (made again in a child process: a fork keeps no threads)."""
    global _pool, _pool_of
    if _pool is None or _pool_of[0] != os.getpid() or _pool_of[1] < count:
        _pool = ThreadPoolExecutor(max_workers=count, thread_name_prefix="dftc-pass")
        _pool_of = (os.getpid(), count)
    return _pool


class Sharing:
    """Runs ``rows(lo, hi, b)`` over robots 0 .. m - 1 in ``threads`` threads, the caller's
    included (``b``: the thread's scratch row, 0 for the caller)."""

    def __init__(self, threads: int) -> None:
        if threads < 2:
            raise ValueError(f"Sharing(threads): expected 2 or more, got {threads}")
        self.threads = threads
        self.caller_chunks = 0  # chunks the caller took, over every pass (how busy helpers were)
        self.chunks = 0  # chunks over every pass
        self._rows: Callable[[int, int, int], int] | None = None
        self._helpers: list[Future[tuple[int, int]]] = []
        self._next: Any = None  # the chunks' numbers, during a pass
        self._m = self._size = 0

    def start(self, rows: Callable[[int, int, int], int], m: int) -> None:
        """Hand the pass over robots 0 .. m - 1 to the helpers; :meth:`finish` ends it."""
        if self._rows is not None:
            raise RuntimeError("Sharing.start: the last pass has not been finished")
        chunks = min(m, max(self.threads, m * m // PAIRS))
        self._rows, self._m, self._size = rows, m, -(-m // max(chunks, 1))
        self._next = count()
        pool = _helpers(self.threads - 1)
        self._helpers = [pool.submit(self._take, b) for b in range(1, self.threads)]

    def finish(self) -> int:
        """The chunks no helper took, in this thread, then the helpers' ends: the sum of
        what ``rows`` returned. A helper's exception is raised once every helper has ended."""
        if self._rows is None:
            raise RuntimeError("Sharing.finish: no pass was started")
        try:
            mine = self._take(0)
        finally:  # nothing is left running on the team's arrays
            _join(self._helpers)
            self._rows = self._next = None
        self.caller_chunks += mine[1]
        self.chunks += mine[1]
        total = mine[0]
        for f in self._helpers:
            found, taken = f.result()
            total += found
            self.chunks += taken
        self._helpers = []
        return total

    def run(self, rows: Callable[[int, int, int], int], m: int) -> int:
        """The whole pass, the caller taking chunks beside the helpers."""
        self.start(rows, m)
        return self.finish()

    def _take(self, b: int) -> tuple[int, int]:
        """Chunks of the pass until none is left, with scratch row ``b``: (what ``rows``
        returned over them, how many)."""
        rows, m, size, nxt = self._rows, self._m, self._size, self._next
        assert rows is not None
        found = taken = 0
        while True:
            lo = next(nxt) * size  # one chunk to one thread: a call Python's lock keeps whole
            if lo >= m:
                return found, taken
            found += rows(lo, min(lo + size, m), b)
            taken += 1


def _join(pending: list[Future[Any]]) -> None:
    """Wait until every helper has ended, through a KeyboardInterrupt too (raised after)."""
    interrupted: BaseException | None = None
    while True:
        try:
            wait(pending)
            break
        except BaseException as exc:  # the helpers still write the team's arrays
            interrupted = exc
    if interrupted is not None:
        raise interrupted
