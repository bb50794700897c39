"""The team's log row (onboard/log_row.py): the compiled row of a whole team writes the
numbers the placement in Python writes, on real runs."""

from __future__ import annotations

import copy

import numpy as np

from dftc_mujoco import Simulation, load_scenario
from dftc_mujoco.onboard.log_row import FIELDS, placed_row, write_row


def test_the_compiled_row_writes_what_the_placement_writes():
    """paper_case at 19.5 s (robot 2's bias acting, robots avoiding a cylinder): one row and
    one N × N row written both ways, field by field, bit for bit (float32 where the log is)."""
    with Simulation(load_scenario("paper_case", {"duration": 21.0})) as sim:
        sim.step(1950)  # the snapshot after step() holds the estimates
        team, log = sim.team, sim.log.data
        assert len(team.members) == team.n
        fast = {name: log[name].copy() for name in FIELDS}
        slow = copy.deepcopy(fast)
        write_row(team, fast, 3, True, 2)
        placed_row(team, slow, 3, True, 2, np.zeros((2, team.n), bool))
        assert team.log_tables  # the fast path kept its table
    for name in FIELDS:
        a, b = fast[name], slow[name]
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), name
    assert np.isfinite(fast["threshold"][2]).all() and np.isfinite(fast["x_hat"][2]).all()
    assert fast["phi_hat"][3, 1].any()  # robot 2's estimate of its bias is in the row


def test_after_an_exclusion_the_robot_that_left_is_filled():
    """paper_case to 55 s: robot 1 was excluded at 50.07 s; its rows are NaN and False."""
    r = Simulation(load_scenario("paper_case", {"duration": 55.0})).run(progress=False)
    last = r.log["u"].shape[0] - 1
    assert not r.log["active"][last, 0] and r.log["active"][last, 1:].all()
    assert np.isnan(r.log["x_d"][last, 0]).all() and np.isfinite(r.log["x_d"][last, 1:]).all()
    assert np.isnan(r.log["residual"][-1, 0]).all() and np.isnan(r.log["residual"][-1, :, 0]).all()
    assert np.isfinite(r.log["residual"][-1, 1:, 1:]).all()
