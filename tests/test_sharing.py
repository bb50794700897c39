"""The pass shared between threads (onboard/sharing.py): real threads, real sleeps."""

from __future__ import annotations

import time

from dftc_mujoco.onboard.sharing import Sharing


def _rows(per_row: dict[int, float]):
    """A pass whose thread ``b`` takes ``per_row[b]`` seconds a robot (a sleep: it holds no
    lock on Python, as the compiled pass does not); returns the robots it took."""

    def rows(lo: int, hi: int, b: int) -> int:
        time.sleep((hi - lo) * per_row[b])
        return hi - lo

    return rows


def test_the_callers_share_comes_back_after_a_helper_was_slow():
    """A helper much slower than the calling thread moves the caller's share up; the helpers
    still keep rows (or their timings, which move the share, would stop), and once they are
    as fast as the caller the share comes back to about half."""
    m = 100
    sharing = Sharing(2)
    slow = _rows({0: 1e-6, 1: 2e-3})
    for _ in range(12):
        assert sharing.run(slow, m) == m  # every robot's row, once
        assert sharing.own_rows <= m - 1
    assert sharing.own_rows >= 90
    sharing.own_rows = m  # every robot, as the code before could leave it
    even = _rows({0: 2e-4, 1: 2e-4})  # 10 ms a thread at half each: a sleep's noise is small
    for _ in range(12):
        assert sharing.run(even, m) == m
    assert 30 <= sharing.own_rows <= 70
