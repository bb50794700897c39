"""Resident helpers (onboard/resident.py): real threads in compiled loops, real teams."""

from __future__ import annotations

import time

import numpy as np
import pytest

from dftc_mujoco.graph import Graph
from dftc_mujoco.onboard import resident
from dftc_mujoco.onboard import team as team_mod
from dftc_mujoco.onboard.locality import demo_team
from tests.conftest import ring_with_chords

pytestmark = pytest.mark.skipif(not resident.available(), reason="x86-64 Linux only")

N = 12


def _team(shared: bool, monkeypatch):
    monkeypatch.setattr(team_mod, "PARALLEL_FROM", 8)
    monkeypatch.setattr(team_mod, "PARALLEL_ALLOWED", shared)
    graph = Graph(N, tuple((a - 1, b - 1) for a, b in ring_with_chords(N)))
    team, x = demo_team(N, None, graph, False, seed=N, command_limit=1.0)
    assert team.shares == shared
    return team, x


def _step_both(a, b, x, periods, between=None):
    """Step teams ``a`` and ``b`` on the same measurements, robot 2 pushed beyond the
    command range from 8 s (a detection); every output the same at every period."""
    rng = np.random.default_rng(5)
    v = np.array([0.1, 0.0])
    xs = x.copy()
    for k in range(periods):
        t = k * 0.01
        if between is not None:
            between(k)
        x_m = xs + rng.uniform(-1e-3, 1e-3, xs.shape)
        a.step(t, x_m, v * t, v)
        b.step(t, x_m, v * t, v)
        out_a, out_b = a.outputs(), b.outputs()
        for name in out_a:
            kind = out_a[name].dtype.kind == "f"
            assert np.array_equal(out_a[name], out_b[name], equal_nan=kind), f"{name} at {k}"
        assert a.events == b.events
        phi = np.zeros_like(xs)
        if t > 8.0:
            phi[1] = [1.5, 0.0]
        xs = xs + 0.01 * (np.clip(a.u_bar, -1.0, 1.0) + phi)
    assert a.recovery.detected == b.recovery.detected and a.recovery.detected


def test_a_helper_gone_to_sleep_is_woken_by_the_next_pass(monkeypatch):
    """A helper that waited longer than its patience sleeps; the next pass wakes it, and
    the rows it runs, awake or woken, are bit for bit those of one thread."""
    resident.close_all()
    monkeypatch.setattr(resident, "PATIENCE", 2e-3)
    split, x = _team(True, monkeypatch)
    one, _ = _team(False, monkeypatch)
    asleep = []

    def pause(k):
        if k % 97 == 50:  # longer than the patience, then the next pass
            time.sleep(0.02)
            crew = resident._residents.get((1, split.decision.timer.dtype), [])
            asleep.extend(r.mail[resident.STATE] == resident.ASLEEP for r in crew)

    try:
        _step_both(split, one, x, 1500, pause)
        assert split._sharing.engine == "resident"
        assert len(asleep) >= 5 and all(asleep)
    finally:
        resident.close_all()  # the next ones wait with the usual patience


def test_a_second_caller_while_the_helpers_are_taken_runs_the_pool(monkeypatch):
    """A second simulation stepping while another holds the resident helpers (another
    thread) runs its helpers' rows on the pool's threads, with the same numbers."""
    split, x = _team(True, monkeypatch)
    one, _ = _team(False, monkeypatch)
    crew = resident.residents(1, split.decision.timer.dtype)
    assert crew is not None
    try:
        _step_both(split, one, x, 1500)
        assert split._sharing.engine == "pool"
    finally:
        for r in crew:
            r.lock.release()
    split.step(5.0, x, np.zeros(2), np.zeros(2))
    assert split._sharing.engine == "resident"


def test_a_helper_that_fails_raises_in_the_caller_instead_of_hanging(monkeypatch):
    """A table that does not hold what its reader expects raises the reader's TypeError in
    the calling thread; the next shared pass has a helper again."""
    split, x = _team(True, monkeypatch)
    split.step(0.0, x, np.zeros(2), np.zeros(2))
    table, mu, timer, numbers = split._flat_records()
    wrong = table.copy()
    wrong[0, 1] = np.dtype(np.int32).num  # ŷ's row read as float64 by its reader
    crew = resident.residents(1, timer.dtype)
    assert crew is not None
    try:
        crew[0].start((wrong, mu, timer, numbers, 0), 0, 1, 1)
        with pytest.raises(TypeError, match="address table"):
            crew[0].finish()
    finally:
        crew[0].lock.release()
    split.step(0.01, x, np.zeros(2), np.zeros(2))
    assert split._sharing.engine == "resident"


def test_a_failed_helper_is_replaced_while_its_thread_is_still_ending():
    """A helper that failed keeps its error and ends its thread; until the thread has ended
    it looked alive, and CI once posted the next pass to it, which raised the old error
    again. A crew with a failed helper is made anew whether or not its thread has ended."""
    crew = resident.residents(1, np.dtype(np.uint8))
    if crew is None:
        pytest.skip("no resident helpers on this platform")
    old = crew[0]
    old.lock.release()
    old.error = TypeError("its pass failed")  # what _loop sets just before its thread ends
    try:
        assert old._thread.is_alive()  # idle in its loop: the moment the race found
        again = resident.residents(1, np.dtype(np.uint8))
        assert again is not None and again[0] is not old and again[0].error is None
        again[0].lock.release()
    finally:
        old.close()
