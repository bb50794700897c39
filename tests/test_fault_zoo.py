"""Actuator faults beyond bias and stop (sim/faults.py): loss of effectiveness, intermittent
stops, and faults that end, each acting where it physically lives (the actuators'
parameters), checked on the robot's motion."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dftc_mujoco import load_scenario, simulate
from dftc_mujoco.errors import InputError, ScenarioError

DATA = Path(__file__).parent / "data" / "robots"


def _run(faults: list[dict], duration: float = 20.0):
    return simulate(load_scenario("paper_case", {"duration": duration, "faults": faults}))


def _speed_ratio(r, robot: int, t0: float, t1: float) -> float:
    """Robot's mean speed over its mean commanded speed between t0 and t1 (logged; a healthy
    disk gives about 0.8: its servo does not reach the command within a period)."""
    t, x, cmd = r.log["t"], r.log["x"][:, robot], r.log["v_cmd"][:, robot]
    w = (t >= t0) & (t < t1)
    v = np.linalg.norm(np.diff(x, axis=0) / np.diff(t)[:, None], axis=1)
    return float(v[w[1:]].mean() / np.linalg.norm(cmd[w], axis=1).mean())


def test_a_loss_of_effectiveness_delivers_that_share_of_the_command_and_ends():
    r = _run([{"robot": 1, "kind": "loss_of_effectiveness", "t": 8.0, "value": 0.4, "end": 14.0}])
    healthy = _speed_ratio(r, 0, 3.0, 8.0)
    assert 0.3 < _speed_ratio(r, 0, 9.0, 14.0) / healthy < 0.6  # 0.4 of the command
    assert 0.85 < _speed_ratio(r, 0, 15.0, 20.0) / healthy < 1.15
    kinds = [(e["kind"], e["t"]) for e in r.events.items if e["kind"].startswith("fault")]
    assert kinds == [("fault", 8.0), ("fault_ended", 14.0)]
    phi = r.log["phi"][:, 0]
    t = r.log["t"]
    assert np.allclose(phi[(t > 9) & (t < 13)], -0.6 * r.log["v_cmd"][(t > 9) & (t < 13), 0])
    assert np.all(phi[t > 14.5] == 0.0)


def test_an_intermittent_stop_stops_the_robot_in_its_on_windows_only():
    r = _run(
        [{"robot": 2, "kind": "intermittent", "t": 8.0, "period": 2.0, "duty": 0.5, "end": 16.0}]
    )
    healthy = _speed_ratio(r, 1, 3.0, 8.0)
    for a in (8.0, 10.0, 12.0, 14.0):  # on: [a, a + 1)
        assert _speed_ratio(r, 1, a + 0.3, a + 0.9) < 0.05 * healthy
        assert _speed_ratio(r, 1, a + 1.3, a + 1.9) > 0.6 * healthy  # off: it drives again
    assert _speed_ratio(r, 1, 17.0, 20.0) > 0.85 * healthy


def test_a_bias_and_a_stop_that_end_leave_the_robot_healthy():
    r = _run(
        [
            {"robot": 3, "kind": "bias", "t": 6.0, "value": [0.05, 0.0], "end": 9.0},
            {"robot": 4, "kind": "stop", "t": 6.0, "end": 9.0},
        ]
    )
    t, phi = r.log["t"], r.log["phi"]
    assert np.abs(phi[(t > 7) & (t < 8.9), 2, 0] - 0.05).max() < 1e-3
    assert np.all(phi[t >= 9.0, 2] == 0.0) and np.all(phi[t >= 9.0, 3] == 0.0)
    healthy = _speed_ratio(r, 3, 2.0, 6.0)
    assert _speed_ratio(r, 3, 6.3, 8.9) < 0.05 * healthy
    assert _speed_ratio(r, 3, 10.0, 20.0) > 0.85 * healthy


def test_zoo_faults_are_checked_in_one_line():
    def refused(fault: dict) -> str:
        with pytest.raises(ScenarioError) as e:
            load_scenario("paper_case", {"faults": [fault]})
        return str(e.value)

    assert "faults[1].value: expected the remaining effectiveness below 1" in refused(
        {"robot": 1, "kind": "loss_of_effectiveness", "t": 5.0, "value": 1.0}
    )
    assert "faults[1].duty: expected a number <= 1" in refused(
        {"robot": 1, "kind": "intermittent", "t": 5.0, "period": 1.0, "duty": 2.0}
    )
    assert "faults[1].end: expected a time after t = 5 s" in refused(
        {"robot": 1, "kind": "stop", "t": 5.0, "end": 4.0}
    )
    # a fault of size 0 changes nothing, yet its robot counted as the faulty one (it ran)
    for kind in ("bias", "drift", "sensor_bias", "sensor_drift"):
        assert "faults[1].value: expected a nonzero [x, y] pair ([0, 0] is no fault)" in refused(
            {"robot": 2, "kind": kind, "t": 5.0, "value": [0.0, 0.0]}
        )


@pytest.mark.parametrize(
    ("fault", "line"),
    [
        # acted 10 ms, a whole control period
        (
            {"kind": "bias", "t": 20.0, "end": 20.005, "value": [0.5, 0.0]},
            "faults[1].end: the bias fault: it lasts 0.005 s, less than a control period",
        ),
        # between two instants: a fault and a fault_ended event at 20.01 s, and no action
        (
            {"kind": "stop", "t": 20.001, "end": 20.002},
            "faults[1].end: the stop fault: it lasts 0.001 s, less than a control period",
        ),
        # 1.5 ms on of every 5 ms acted at every instant: a stop
        (
            {"kind": "intermittent", "t": 20.0, "period": 0.005, "duty": 0.3},
            "faults[1].duty: the intermittent fault: its on windows (0.0015 s of every 0.005 s)",
        ),
        (
            {"kind": "intermittent", "t": 20.0, "period": 1.0, "duty": 0.995},
            "faults[1].duty: the intermittent fault: its off windows (0.005 s of every 1 s)",
        ),
        (
            {"kind": "sensor_bias", "t": 25.995, "value": [0.2, 0.0]},
            "faults[1].t: the sensor_bias fault: the run ends at 26 s before a control instant",
        ),
    ],
)
def test_a_fault_the_control_instants_cannot_carry_is_refused(fault, line):
    """The faults switch at the control instants (every 0.01 s here): a fault shorter than a
    period, windows shorter than one, or a start after the last instant ran without a word,
    acting for a whole period, at every instant, or not at all."""
    with pytest.raises(ScenarioError) as e:
        load_scenario("paper_case", {"duration": 26.0, "faults": [{"robot": 1, **fault}]})
    assert str(e.value).count("\n") == 0 and line in str(e.value), str(e.value)
    kept = {**fault, "t": 20.0, "end": 20.01} if fault["kind"] != "intermittent" else fault
    if fault["kind"] != "intermittent":  # one period is enough
        load_scenario("paper_case", {"duration": 26.0, "faults": [{"robot": 1, **kept}]})


def test_a_loss_of_effectiveness_on_position_servos_is_refused():
    s = load_scenario(
        "paper_case",
        {
            "team.robot_model": str(DATA / "holobase.robot.toml"),
            "faults": [{"robot": 1, "kind": "loss_of_effectiveness", "t": 5.0, "value": 0.5}],
        },
    )
    with pytest.raises(InputError, match="loss_of_effectiveness is modelled for velocity servos"):
        simulate(s)


def test_every_fault_kind_survives_the_scenario_written_out_and_read_back():
    faults = [
        {"robot": 1, "kind": "bias", "t": 5.0, "value": [0.1, 0.0], "end": 9.0},
        {"robot": 2, "kind": "stop", "t": 6.0, "end": 8.0},
        {"robot": 3, "kind": "loss_of_effectiveness", "t": 5.0, "value": 0.3},
        {"robot": 4, "kind": "intermittent", "t": 5.0, "period": 2.0, "duty": 0.25, "end": 20.0},
        {"robot": 1, "kind": "sensor_bias", "t": 7.0, "value": [0.1, 0.2]},
        {"robot": 2, "kind": "sensor_drift", "t": 7.0, "value": [0.01, 0.0], "end": 30.0},
        {"robot": 3, "kind": "drift", "t": 8.0, "value": [0.01, 0.02]},
        {"robot": 4, "kind": "stuck", "t": 9.0, "end": 12.0},
    ]
    s = load_scenario("paper_case", {"faults": faults})
    again = type(s).from_dict(s.to_dict())
    assert [(f.kind, f.t, f.end, f.period, f.duty, list(f.value)) for f in again.faults] == [
        (f.kind, f.t, f.end, f.period, f.duty, list(f.value)) for f in s.faults
    ]
    assert s.with_overrides(duration=25.0).faults  # a shorter run keeps the earlier ones


def test_an_actuator_drift_grows_and_a_stuck_robot_keeps_its_command():
    from dftc_mujoco import Simulation

    r = _run([{"robot": 2, "kind": "drift", "t": 6.0, "value": [0.02, 0.0], "end": 11.0}])
    t, phi = r.log["t"], r.log["phi"][:, 1]
    w = (t > 6.0) & (t < 11.0)
    assert np.allclose(phi[w, 0], 0.02 * (t[w] - 6.0), atol=1e-9)
    assert np.all(phi[t >= 11.0] == 0.0)
    s = load_scenario(
        "paper_case", {"duration": 12.0, "faults": [{"robot": 3, "kind": "stuck", "t": 8.0}]}
    )
    with Simulation(s) as sim:
        ids = sim.adapter.actuation.ids
        sim.step(801)  # through t = 8.0 s
        held = sim.data.ctrl[ids[2]].copy()
        others = sim.data.ctrl[ids[0]].copy()
        sim.step(150)
        assert np.array_equal(sim.data.ctrl[ids[2]], held)  # robot 3 keeps its command
        assert not np.array_equal(sim.data.ctrl[ids[0]], others)  # robot 1 does not


def test_faults_left_alone_between_their_switches_act_as_if_re_evaluated_every_period():
    # apply() runs every period while a bias moves; it skips the stops' bookkeeping until
    # the next start or end, and the due-time search while the bias keeps moving: the
    # physics must be what re-evaluating everything every period gives, bit for bit
    from dftc_mujoco import Simulation

    faults = [
        {
            "robot": 1,
            "kind": "bias",
            "t": 2.0,
            "value": [0.1, -0.05],
            "time_constant": 0.5,
            "end": 10.0,
        },
        {"robot": 2, "kind": "stop", "t": 3.0, "end": 5.0},
        {"robot": 3, "kind": "intermittent", "t": 4.0, "period": 1.0, "duty": 0.5, "end": 8.0},
        {"robot": 4, "kind": "loss_of_effectiveness", "t": 6.0, "value": 0.5, "end": 9.0},
        {"robot": 2, "kind": "stuck", "t": 6.5, "end": 8.5},
        {"robot": 1, "kind": "stop", "t": 9.0, "end": 9.5},
    ]
    s = load_scenario("paper_case", {"duration": 11.0, "faults": faults})

    def run(every_period: bool):
        params, qpos = [], []

        def hook(t, plant):
            m = plant.model
            params.append(
                np.concatenate([m.actuator_gainprm[:, 0], m.actuator_biasprm[:, :3].ravel()])
            )
            qpos.append(plant.data.qpos.copy())
            if every_period:  # forget what apply() knows: it re-evaluates everything
                sim.faults._switch_due = sim.faults._moving_until = -np.inf

        with Simulation(s, hook=hook) as sim:
            sim.run(progress=False)
        return np.array(params), np.array(qpos)

    (p_skip, q_skip), (p_all, q_all) = run(False), run(True)
    assert len(p_skip) == 1100
    assert np.array_equal(p_skip, p_all) and np.array_equal(q_skip, q_all)
    # and the faults did act: parameters moved at each switch and while the bias moved
    changed = np.flatnonzero(np.any(np.diff(p_skip, axis=0) != 0, axis=1)) + 1
    assert {300, 500, 600, 650, 900, 950} <= set(changed.tolist())
    assert len(changed) > 400  # the bias moves every period from 2 s (at least until 10 s)


def test_a_fault_after_the_end_is_one_line():
    """The reader says a fault after the end once: the control instants' check stays quiet
    about it (it said the same fault "would never act" on a second line)."""
    with pytest.raises(ScenarioError) as e:
        load_scenario(
            "paper_case", {"duration": 30.0, "faults": [{"robot": 1, "kind": "stop", "t": 41.8}]}
        )
    assert str(e.value).endswith(
        "faults[1].t: fault at 41.8 s is after the end of the run (duration = 30 s)"
    )
    assert str(e.value).count("\n") == 0
