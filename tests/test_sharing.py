"""The pass shared between threads (onboard/execution/sharing.py): real threads, real sleeps."""

from __future__ import annotations

import threading
import time

import pytest

from dftc_mujoco.onboard.execution.sharing import Sharing


def _rows(per_row: dict[int, float], seen: list[int]):
    """A pass whose thread ``b`` takes ``per_row[b]`` seconds a robot (a sleep: it holds no
    lock on Python, as the compiled pass does not), noting each robot it took."""
    lock = threading.Lock()

    def rows(lo: int, hi: int, b: int) -> int:
        time.sleep((hi - lo) * per_row[b])
        with lock:
            seen.extend(range(lo, hi))
        return hi - lo

    return rows


def test_every_row_is_taken_once_whoever_takes_it():
    """The caller's work beside the pass, then its share: every robot's row exactly once,
    and the helper took rows while the caller was busy."""
    seen: list[int] = []
    sharing = Sharing(2)
    sharing.start(_rows({0: 1e-5, 1: 1e-5}, seen), 3000)
    time.sleep(0.02)  # the caller's commands and physics
    assert sharing.finish() == 3000
    assert sorted(seen) == list(range(3000))
    assert 0 < sharing.caller_chunks < sharing.chunks


def test_a_helper_that_is_not_scheduled_leaves_its_rows_to_the_caller():
    """A helper slower than the whole pass (a machine whose cores are taken) takes one chunk;
    the caller takes the others and waits only for that chunk, never for a share fixed in
    advance."""
    seen: list[int] = []
    sharing = Sharing(2)
    rows = _rows({0: 1e-6, 1: 1e-3}, seen)  # the helper: 1 ms a robot
    t0 = time.perf_counter()
    assert sharing.run(rows, 2000) == 2000
    spent = time.perf_counter() - t0
    assert sorted(seen) == list(range(2000))
    assert sharing.chunks - sharing.caller_chunks <= 1  # the helper's one chunk at most
    # its one chunk of 1000 robots' rows would be 1 s: the chunks are small (16 here)
    assert sharing.chunks >= 16
    assert spent < 1.0


def test_a_helpers_error_is_raised_once_every_row_has_ended():
    """An exception in a helper's rows is raised by finish(), after the caller's rows."""
    calls: list[int] = []

    def rows(lo: int, hi: int, b: int) -> int:
        calls.append(b)
        if b == 1:
            raise ValueError("a helper's rows failed")
        time.sleep(1e-3)
        return 0

    sharing = Sharing(2)
    sharing.start(rows, 400)
    time.sleep(0.01)
    with pytest.raises(ValueError, match="a helper's rows failed"):
        sharing.finish()
    assert 0 in calls and 1 in calls
    assert sharing.run(lambda lo, hi, b: hi - lo, 10) == 10  # the next pass runs as usual
