"""The team's log row (onboard/execution/log_row.py): the compiled row writes the numbers the
placement in Python writes, before and after an exclusion, on real runs."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from dftc_mujoco import Simulation, load_scenario
from dftc_mujoco.onboard.execution.log_row import FIELDS, placed_row, write_row


@pytest.mark.parametrize("periods", [1950, 5200])
def test_the_compiled_row_writes_what_the_placement_writes(periods):
    """paper_case at 19.5 s (every robot a member, robot 2's bias acting) and at 52 s (robot
    1 excluded at 50.07 s: its rows NaN and False): one row and one N × N row written both
    ways, field by field, bit for bit (float32 where the log is)."""
    with Simulation(load_scenario("paper_case", {"duration": 53.0})) as sim:
        sim.step(periods)  # the snapshot after step() holds the estimates
        team, log = sim.team, sim.log.data
        assert team.compiled and len(team.members) == (4 if periods < 5000 else 3)
        fast = {name: log[name].copy() for name in FIELDS}
        slow = copy.deepcopy(fast)
        write_row(team, fast, 3, True, 2)
        placed_row(team, slow, 3, True, 2)
    for name in FIELDS:
        a, b = fast[name], slow[name]
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), name
    left = [] if periods < 5000 else [0]
    kept = [i for i in range(4) if i not in left]
    assert np.isfinite(fast["threshold"][2][np.ix_(kept, kept)]).all()
    assert np.isnan(fast["residual"][2][left]).all() and np.isnan(fast["x_d"][3][left]).all()
    assert fast["active"][3].tolist() == [i in kept for i in range(4)]
    assert fast["phi_hat"][3, 1].any()  # robot 2's estimate of its bias is in the row
