"""Faults of the position sensors (sim/sensors.py): they act on the measurement only,
start and end when the scenario says, and are events."""

from __future__ import annotations

import numpy as np
import pytest

from dftc_mujoco import Simulation, load_scenario
from dftc_mujoco.errors import ScenarioError


def _sim(fault: dict) -> Simulation:
    return Simulation(load_scenario("paper_case", {"duration": 40.0, "faults": [fault]}))


def test_a_sensor_bias_moves_the_measurement_only_and_ends():
    eta = 0.001
    with _sim(
        {"robot": 3, "kind": "sensor_bias", "t": 10.0, "value": [0.2, -0.1], "end": 12.0}
    ) as sim:
        snap = sim.step(999)  # t = 9.98 s
        assert np.linalg.norm(snap.x_m[2] - snap.x[2]) <= eta * (1 + 1e-9)
        snap = sim.step(50)  # 10.48 s
        assert np.allclose(snap.x_m[2] - snap.x[2], [0.2, -0.1], atol=eta)
        assert np.all(np.linalg.norm(snap.x_m[[0, 1, 3]] - snap.x[[0, 1, 3]], axis=1) <= eta)
        snap = sim.step(200)  # 12.48 s: over
        assert np.linalg.norm(snap.x_m[2] - snap.x[2]) <= eta * (1 + 1e-9)
        kinds = [(e["kind"], e["t"]) for e in sim.events.items if e["kind"].startswith("fault")]
        assert kinds == [("fault", 10.0), ("fault_ended", 12.0)]


def test_a_sensor_drift_grows_with_time():
    with _sim({"robot": 2, "kind": "sensor_drift", "t": 5.0, "value": [0.02, 0.0]}) as sim:
        snap = sim.step(700)  # t = 6.99 s: 1.99 s of drift
        assert np.allclose(snap.x_m[1] - snap.x[1], [0.02 * 1.99, 0.0], atol=0.001)


def test_a_sensor_fault_is_checked_in_one_line():
    with pytest.raises(ScenarioError, match=r"faults\[1\]\.end: expected a time after t = 10 s"):
        load_scenario(
            "paper_case",
            {"faults": [{"robot": 1, "kind": "sensor_bias", "t": 10.0, "value": [1, 0], "end": 5}]},
        )
    with pytest.raises(
        ScenarioError, match=r"faults\[1\]\.value: expected an \[x, y\] pair in m/s"
    ):
        load_scenario(
            "paper_case", {"faults": [{"robot": 1, "kind": "sensor_drift", "t": 10, "value": 1}]}
        )
