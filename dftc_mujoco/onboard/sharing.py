"""One pass over the team's robots shared between threads, with other work beside it.

The pass over the N × N state (:func:`~.period.team_rows`) treats each robot's row apart
from the others, so disjoint ranges of robots can run at once in threads (the compiled
pass holds no lock on Python), and the numbers do not depend on who ran which row. Helper
threads take their shares of the robots first; the calling thread meanwhile runs the work
given *beside* the pass (the team's commands, then the simulation's physics step under
them: neither needs anything the pass writes, and MuJoCo holds no lock on Python while it
steps either), then takes the last share. The caller's share is set from the last
period's timings so that the helpers end a little before it: waking a thread costs
35-80 µs on this machine, and the caller then never waits to be woken. With two cores the
physics and the pass share them instead of taking turns. Whatever the caller runs beside
the pass in compiled code must hold no lock on Python either (``nogil``): a helper needs
the lock to begin its rows, and began 0.31 ms late at N = 1000 while the commands held it.

Where they run (x86-64 Linux), the helpers' shares go to *resident* helpers instead of the
pool's threads (:mod:`.resident`): they stay in compiled code between passes and need no
lock on Python at all, so they begin 0.01-0.02 ms after the post (0.16-0.21 ms for the
pool's at N = 1000, 2026-12-01); their timings come from the processor's counter.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor, wait
from typing import Any

import numba

from . import resident

#: a team of this many members or more shares its pass between threads (below it, handing
#: work to a thread costs more than it saves: N = 100, 303 µs a period alone, 407 shared;
#: N = 150, 503-543 alone, 442-447 shared)
PARALLEL_FROM = 150

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


#: False keeps the pool's helpers where resident ones could run (benchmarks, tests)
RESIDENT_ALLOWED = True

#: [s] how much earlier than the caller the helpers aim to end (a thread's wake-up)
MARGIN = 1e-4

#: what :attr:`Sharing.sums` adds up over the shared passes, in order [s]: the caller's
#: work beside the pass, when the last helper ended, when the caller's rows ended, when the
#: last helper began, one helper's time on its rows (their mean), when the helpers were
#: joined (each but the fifth from the pass's start; ``benchmarks/bench_pass.py``)
SUMMED = ("beside", "helpers_end", "caller_end", "helpers_start", "helper_work", "joined")


class Sharing:
    """Runs ``rows(lo, hi, b)`` over robots 0 .. m - 1 in ``threads`` threads (``b``: the
    thread's scratch row), the caller's included, and ``beside()`` in the caller first."""

    def __init__(self, threads: int) -> None:
        self.threads = threads
        self.own_rows = -1  # robots the caller takes after the beside work (-1: m / threads;
        # at most m - threads + 1: a helper without rows has no timing to move it back)
        self.timings = (0.0, 0.0, 0.0)  # the last period: beside work, helpers, the caller
        self.passes = 0  # shared passes run, and the sums of their timings (SUMMED)
        self.engine = ""  # who ran the helpers' shares last: "resident" or "pool"
        self.sums = (0.0,) * len(SUMMED)

    def run(
        self,
        rows: Callable[[int, int, int], int],
        m: int,
        beside: Callable[[], None] | None = None,
        posted: tuple | None = None,
    ) -> int:
        """The pass over robots 0 .. m - 1 and ``beside()``, at once; returns the sum of what
        ``rows`` returned. An exception in ``beside`` is raised once the pass has ended.
        ``posted``: the pass as resident helpers take it (:func:`.resident.post`'s table,
        mu, timer, numbers and flags; the same rows as ``rows``): they run the helpers' shares
        where they can (:func:`.resident.residents`), else the pool's threads do."""
        w = self.threads
        if w < 2:
            count = rows(0, m, 0)
            if beside is not None:
                beside()
            return count
        most = max(m - (w - 1), 0)  # a row for each helper: its timing moves the share
        share = m // w if self.own_rows < 0 else min(self.own_rows, most)
        rest = m - share  # robots 0 .. rest - 1 for the helpers, the last ones for the caller
        cuts = [rest * j // (w - 1) for j in range(w)]
        crew = None
        if posted is not None and RESIDENT_ALLOWED:
            crew = resident.residents(w - 1, posted[2].dtype)
        if crew is not None:
            self.engine = "resident"
            count, now, error = self._resident(crew, posted, rows, share, rest, m, cuts, beside)
        else:
            self.engine = "pool"
            count, now, error = self._pooled(rows, share, rest, m, cuts, beside)
        helper_end, caller_end, spent = now[1], now[2], now[4] * (w - 1)
        self.timings = now[:3]
        self.passes += 1
        self.sums = tuple(s + x for s, x in zip(self.sums, now, strict=True))
        if rest > 0 and spent > 0.0:  # the caller's share that ends MARGIN after the helpers
            per_row = spent / rest  # one thread's time for a robot
            late = helper_end - caller_end + MARGIN
            target = share + late / per_row * (w - 1) / w
            self.own_rows = round(0.5 * share + 0.5 * min(max(target, 0.0), most))
        if error is not None:
            raise error
        return count

    def _pooled(self, rows, share, rest, m, cuts, beside) -> tuple:
        """The pass with the pool's helpers: (count, the timings of SUMMED, beside's error)."""
        w = self.threads
        pool = _helpers(w - 1)
        t0 = time.perf_counter()
        helpers: list[Future[Any]] = [
            pool.submit(_timed, rows, cuts[j], cuts[j + 1], j + 1) for j in range(w - 1)
        ]
        try:
            t1, count, t2, error = _beside_then_rows(
                beside, rows, share, rest, m, time.perf_counter
            )
        finally:  # nothing is left running on the team's arrays
            _join(helpers)
        t3 = time.perf_counter()
        ends = [f.result() for f in helpers]
        count += sum(c for c, _, _ in ends)
        helper_end = max(end for _, _, end in ends) - t0
        spent = sum(end - start for _, start, end in ends)
        began = max(start for _, start, _ in ends) - t0
        return count, (t1 - t0, helper_end, t2 - t0, began, spent / (w - 1), t3 - t0), error

    def _resident(self, crew, posted, rows, share, rest, m, cuts, beside) -> tuple:
        """The pass with resident helpers (:mod:`.resident`), timed by the processor's
        counter: (count, the timings of SUMMED, beside's error)."""
        started: list[resident.Resident] = []
        ends: list[tuple[int, int, int, int]] = []
        try:
            try:
                t0 = resident.now()
                for j, helper in enumerate(crew):
                    helper.start(posted, cuts[j], cuts[j + 1], j + 1)
                    started.append(helper)
                t1, count, t2, error = _beside_then_rows(beside, rows, share, rest, m, resident.now)
            finally:  # nothing is left running on the team's arrays: every helper waited for
                failed: BaseException | None = None
                for helper in started:
                    try:
                        ends.append(helper.finish())
                    except Exception as exc:  # the first one's raised once all have ended
                        failed = failed or exc
                if failed is not None:
                    raise failed
        finally:
            for helper in crew:
                helper.lock.release()
        rate = resident.tick_rate()
        count += sum(e[0] for e in ends)
        helper_end = (max(e[2] for e in ends) - t0) / rate
        spent = sum(e[2] - e[1] for e in ends) / rate
        began = (max(e[1] for e in ends) - t0) / rate
        joined = (max(e[3] for e in ends) - t0) / rate
        timings = ((t1 - t0) / rate, helper_end, (t2 - t0) / rate, began)
        return count, (*timings, spent / len(crew), joined), error


def _beside_then_rows(beside, rows, share, rest, m, clock) -> tuple:
    """The caller's part of a shared pass: ``beside()``, then its rows ``rest`` .. ``m - 1``;
    (``clock()`` between the two, the rows' count, ``clock()`` after them, beside's error,
    kept to be raised once the team's rows are whole)."""
    error: BaseException | None = None
    if beside is not None:
        try:
            beside()
        except Exception as exc:  # raised once the team's rows are whole
            error = exc
    t1 = clock()
    count = rows(rest, m, 0) if share else 0
    return t1, count, clock(), error


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


def _timed(rows: Callable[[int, int, int], int], lo: int, hi: int, b: int) -> tuple:
    """A helper's share: what ``rows`` returned, and when it began and ended."""
    t0 = time.perf_counter()
    count = rows(lo, hi, b) if hi > lo else 0
    return count, t0, time.perf_counter()
