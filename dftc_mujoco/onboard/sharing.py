"""One pass over the team's robots shared between threads, with other work beside it.

The pass over the N × N state (:func:`~.period.team_rows`) treats each robot's row apart
from the others, so disjoint ranges of robots can run at once in threads (the compiled
pass holds no lock on Python), and the numbers do not depend on who ran which row. The
caller's thread takes one share of the robots; each helper thread another, and the first
helper first runs the work given *beside* the pass (the simulation's physics step, which
needs the period's commands and nothing the pass writes: MuJoCo holds no lock on Python
while it steps either). Its share of robots is set from the last period's timings so that
every thread ends at about the same time: with two cores the physics and the pass share
them instead of taking turns.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor, wait
from typing import Any

import numba

#: a team of this many members or more shares its pass between threads (below it, handing
#: work to a thread costs more than it saves)
PARALLEL_FROM = 200

_pool: ThreadPoolExecutor | None = None
_pool_of = (0, 0)  # the process that made it, and its threads


def _helpers(count: int) -> ThreadPoolExecutor:
    """The process's helper threads (made again in a child process: a fork keeps no threads)."""
    global _pool, _pool_of
    if _pool is None or _pool_of[0] != os.getpid() or _pool_of[1] < count:
        _pool = ThreadPoolExecutor(max_workers=count, thread_name_prefix="dftc-pass")
        _pool_of = (os.getpid(), count)
    return _pool


def workers() -> int:
    """How many threads a shared pass runs in: numba's thread count (every core by default,
    ``NUMBA_NUM_THREADS`` to limit it)."""
    return max(1, numba.get_num_threads())


class Sharing:
    """Runs ``rows(lo, hi, b)`` over robots 0 .. m - 1 in ``threads`` threads (``b``: the
    thread's scratch row), the caller's included, with ``beside()`` run first by one helper.
    """

    def __init__(self, threads: int) -> None:
        self.threads = threads
        self.beside_rows = -1  # robots the helper running the beside work takes (-1: m / threads)
        self.timings = (0.0, 0.0, 0.0)  # the last period: beside work, its helper, the caller

    def run(
        self,
        rows: Callable[[int, int, int], int],
        m: int,
        beside: Callable[[], None] | None = None,
    ) -> int:
        """The pass over robots 0 .. m - 1 and ``beside()``, at once; returns the sum of what
        ``rows`` returned. An exception in either is raised once both have ended."""
        w = self.threads
        if w < 2:
            count = rows(0, m, 0)
            if beside is not None:
                beside()
            return count
        share = m // w if self.beside_rows < 0 or beside is None else self.beside_rows
        share = min(max(share, 0), m)
        rest = m - share  # robots 0 .. rest - 1 for the caller and the other helpers
        cuts = [rest * j // (w - 1) for j in range(w)]
        pool = _helpers(w - 1)
        first: Future[tuple[int, float, float]] = pool.submit(_first, rows, beside, rest, m, w - 1)
        others = [pool.submit(rows, cuts[j], cuts[j + 1], j) for j in range(1, w - 1)]
        pending: list[Future[Any]] = [first, *others]
        try:
            t0 = time.perf_counter()
            count = rows(cuts[0], cuts[1], 0)
            own = time.perf_counter() - t0
        finally:  # nothing is left running on the team's arrays or the physics
            _join(pending)
        done, spent, total = first.result()
        count += done + sum(f.result() for f in others)
        self.timings = (spent, total, own)
        if beside is not None and cuts[1] > 0 and own > 0.0:
            # the helper's share that ends with the others: t_beside + s·r = (m - s)/(w - 1)·r
            per_row = own / cuts[1]
            target = (m - (w - 1) * spent / per_row) / w
            old = share if self.beside_rows >= 0 else m // w
            self.beside_rows = round(0.5 * old + 0.5 * min(max(target, 0.0), m))
        return count


def _join(pending: list[Future[Any]]) -> None:
    """Wait until every helper has ended, through a KeyboardInterrupt too (raised after)."""
    interrupted: BaseException | None = None
    while True:
        try:
            wait(pending)
            break
        except BaseException as exc:  # the helpers still write the team's arrays and MuJoCo's
            interrupted = exc
    if interrupted is not None:
        raise interrupted


def _first(
    rows: Callable[[int, int, int], int],
    beside: Callable[[], None] | None,
    lo: int,
    hi: int,
    b: int,
) -> tuple[int, float, float]:
    """The first helper: the beside work, then robots lo .. hi - 1 (those even if the beside
    work raised, which is raised after them); returns what ``rows`` returned, the beside
    work's time and the whole time."""
    t0 = time.perf_counter()
    error: BaseException | None = None
    if beside is not None:
        try:
            beside()
        except BaseException as exc:  # raised once the team's rows are whole
            error = exc
    t1 = time.perf_counter()
    count = rows(lo, hi, b) if hi > lo else 0
    if error is not None:
        raise error
    return count, t1 - t0, time.perf_counter() - t0
