"""Arrays handed to compiled code by address (:mod:`dftc_mujoco.onboard.addresses`): the views
are the caller's memory, a row that is not what its reader expects raises, and the team's
compiled period takes its records' arrays that way."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from numba import njit, types

from dftc_mujoco.loop import Simulation
from dftc_mujoco.onboard.addresses import address_table, view1, view2, view3
from dftc_mujoco.onboard.period import team_period_flat
from tests.conftest import make, scenario_dict


@njit
def _touch(table):
    """Read every array of the table and write into it: 1-D bool, 2-D int64, 3-D float64,
    1-D int8."""
    flags, counts, values, small = (
        view1(table, 0, np.bool_),
        view2(table, 1, np.int64),
        view3(table, 2, np.float64),
        view1(table, 3, np.int8),
    )
    flags[1] = not flags[1]
    counts[2, 1] += 7
    values[1, 2, 0] = values.sum()
    small[-1] = -small[0]
    return values.shape[0] * 100 + values.shape[1] * 10 + values.shape[2]


def test_views_are_the_callers_arrays():
    flags = np.array([True, False, True])
    counts = np.arange(6).reshape(3, 2)
    values = np.arange(24, dtype=float).reshape(2, 3, 4)
    small = np.array([5, 0], np.int8)
    total = values.sum()
    table = address_table([flags, counts, values, small])
    assert table.dtype == np.int64 and table.shape == (4, 6)
    assert _touch(table) == 234  # the shape came through
    assert flags.tolist() == [True, True, True]
    assert counts[2, 1] == 5 + 7 and counts.sum() == 15 + 7
    assert values[1, 2, 0] == total
    assert small.tolist() == [5, -5]


@pytest.mark.parametrize(
    "wrong",
    [
        np.zeros(3, np.int32),  # int32 where bool is read
        np.zeros((3, 1), bool),  # 2-D where 1-D is read
    ],
)
def test_a_row_that_is_not_what_its_reader_expects_raises(wrong):
    arrays = [wrong, np.zeros((3, 2), np.int64), np.zeros((2, 3, 4)), np.zeros(2, np.int8)]
    with pytest.raises(TypeError, match="does not hold the array its reader expects"):
        _touch(address_table(arrays))


def test_an_array_that_is_not_contiguous_is_refused():
    strided = np.zeros((4, 4))[:, 1]
    with pytest.raises(ValueError, match=r"array 1 .*expected a C-contiguous"):
        address_table([np.zeros(2), strided])
    with pytest.raises(ValueError, match="at most 3 dimensions"):
        address_table([np.zeros((1, 1, 1, 1))])


def test_the_team_period_takes_its_records_by_address():
    """The compiled period's arrays are its inputs, the table, μ, the timers and the records'
    numbers; every cached table points into the arrays kept beside it (they live as long as
    the table)."""
    with Simulation(make(scenario_dict())) as sim:
        sim.step(5)
        team = sim.team
    assert team.path == "compiled"
    assert team_period_flat.signatures  # one per argument types met so far in this process
    for signature in team_period_flat.signatures:
        arrays = [a for a in signature if isinstance(a, types.Array)]
        assert len(arrays) == 10 and len(signature) == 15
    assert team._flat
    for kept, table, *_ in team._flat.values():
        assert table[:, 0].tolist() == [a.__array_interface__["data"][0] for a in kept]
        assert table[:, 1].tolist() == [a.dtype.num for a in kept]


def test_a_copied_team_builds_its_own_tables():
    """``copy.deepcopy`` copies a team's arrays, not the addresses written in its tables: the
    copy starts without tables, and its periods leave the original's state alone."""
    with Simulation(make(scenario_dict())) as sim:
        sim.step(5)
        team = sim.team
        assert team._flat
        copied = copy.deepcopy(team)
        assert not copied._flat
        before = [a.copy() for a in (team.observer.y_hat, team.x_hat, team.u)]
        x_m = sim._x_m + 0.3
        copied.step(0.05, x_m, np.array([0.5, 0.0]), np.array([0.1, 0.0]))
        after = (team.observer.y_hat, team.x_hat, team.u)
        assert all(np.array_equal(a, b) for a, b in zip(before, after, strict=True))
        for kept, table, *_ in copied._flat.values():
            assert table[:, 0].tolist() == [a.__array_interface__["data"][0] for a in kept]


def test_a_copied_log_samples_into_its_own_arrays():
    """The log writes its rows by address (``Log.sample``): a copy (or an unpickled log)
    builds its own table, so sampling into the copy leaves the original's rows alone."""
    import pickle

    with Simulation(make(scenario_dict())) as sim:
        sim.step(5)
        log = sim.log
        before = log.data["x"].copy()
        for twin in (copy.deepcopy(log), pickle.loads(pickle.dumps(log))):
            twin.sample(9.0, np.full((4, 2), 7.0), np.zeros(2), np.full((4, 2), 50.0), 1.0)
            assert np.array_equal(log.data["x"], before, equal_nan=True)
            row = twin.size
            assert (twin.data["x"][row] == 7.0).all() and twin.data["t"][row] == 9.0
            assert (twin.data["v_cmd"][row] == 1.0).all()  # within the drives' range


def test_a_log_row_returns_the_largest_coordinate_as_numpy_would():
    """``Log.sample`` returns ``np.abs(x).max()``: the loop's test of the floor's edge reads
    it, so a NaN anywhere must come back NaN (never beyond the floor), as numpy's does."""
    with Simulation(make(scenario_dict())) as sim:
        log = sim.log
        cmd, c = np.zeros((4, 2)), np.zeros(2)
        rng = np.random.default_rng(3)
        for x in (
            rng.uniform(-60.0, 60.0, (4, 2)),
            np.array([[1.0, -2.0], [-70.0, 3.0], [0.0, 0.0], [4.0, 5.0]]),
            np.array([[np.nan, 1.0], [80.0, 0.0], [0.0, 0.0], [0.0, 0.0]]),
            np.array([[80.0, 1.0], [0.0, 0.0], [0.0, -np.nan], [0.0, 0.0]]),
            np.zeros((4, 2)),
        ):
            far = log.sample(1.0, x, c, cmd, 1.0)
            assert far == np.abs(x).max() or (np.isnan(far) and np.isnan(np.abs(x).max()))
            assert not far > 50.0 or np.abs(x).max() > 50.0
