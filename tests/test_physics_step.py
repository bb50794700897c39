"""The physics step beside a shared pass (closed_loop/physics_step.py,
onboard/execution/sharing.py): a team that shares its pass over the N × N state between
threads advances MuJoCo while helper threads run the pass, and the run's records are the
very ones of a run in one thread."""

from __future__ import annotations

import numpy as np

from dftc_mujoco.closed_loop import loop
from dftc_mujoco.closed_loop.execution import Execution
from tests.conftest import make, ring_team, scenario_dict

N = 6


def _ring(duration: float):
    """Six robots on a ring (chords of 2), robot 1 stopping at 12 s (after the thresholds
    settled: detected, and excluded by 26 s), without obstacles."""
    d = scenario_dict()
    d["team"] = ring_team(N, 0.5, chord=2)
    d["obstacles"], d["duration"] = [], duration
    d["faults"] = [{"robot": 1, "kind": "stop", "t": 12.0}] if duration > 12.0 else []
    d["fdir"]["initial_error_bound"] = "auto"  # paper_case's 1 m is below this start
    return make(d)


def _execution(shared: bool) -> Execution:
    """Two threads from 4 robots on, or one."""
    return Execution(threads=2 if shared else 1, shared_from=4)


def _run(shared: bool, hook=None, scenario=None):
    with loop.Simulation(scenario or _ring(26.0), hook=hook, execution=_execution(shared)) as sim:
        assert sim.team.shares == shared
        result = sim.run(progress=False)
        sharing = sim.team._sharing
        if shared:  # every period's pass went through the helpers' engine
            assert sharing is not None and sharing.chunks > 0
    return result


def _same(a, b):
    assert sorted(a.log) == sorted(b.log)
    for name in a.log:
        assert np.array_equal(a.log[name], b.log[name], equal_nan=True), name
    assert a.events.items == b.events.items
    wall = ("wall_time", "real_time_factor", "build_time", "compile_time")
    sa = {k: v for k, v in a.summary.items() if k not in wall}
    sb = {k: v for k, v in b.summary.items() if k not in wall}
    assert sa == sb


def test_the_physics_beside_a_shared_pass_gives_the_very_same_run():
    """Through a detection and an exclusion (a re-planned formation, a resized team):
    every log array, event and summary entry is bit for bit that of the run in one thread,
    whoever ran which rows."""
    shared = _run(True)
    alone = _run(False)
    kinds = {e["kind"] for e in shared.events.items}
    assert {"fault", "detection", "exclusion"} <= kinds
    _same(shared, alone)


def test_physics_trouble_beside_the_pass_stops_the_run_where_it_would_have():
    """MuJoCo's error raised in the helper thread ends the run at the period it would have
    ended in one thread, with the same message, log and events."""

    def break_physics(t, plant):
        if t >= 2.0:
            plant.data.qvel[0] = np.nan

    shared = _run(True, hook=break_physics)
    alone = _run(False, hook=break_physics)
    assert not shared.ok and "MuJoCo warning BADQVEL" in str(shared.error)
    assert str(shared.error) == str(alone.error)
    assert 1.9 < shared.log["t"][-1] < 2.1
    _same(shared, alone)


def test_stepping_a_shared_team_period_by_period_shows_the_same_snapshots():
    """step(k) with the physics beside the pass: the snapshots are those of one thread."""
    snaps = {}
    periods = 7
    for shared in (True, False):
        with loop.Simulation(_ring(6.0), execution=_execution(shared)) as sim:
            snaps[shared] = [sim.step(periods) for _ in range(140 // periods)]
    for a, b in zip(snaps[True], snaps[False], strict=True):
        assert a.t == b.t and a.events == b.events
        for name in ("x", "x_m", "x_hat", "u", "u_bar", "phi_hat", "residual", "flag"):
            assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), name


def test_a_robot_carried_off_the_floor_ends_the_mission_at_the_next_log_row():
    """A robot put 60 m out (beyond the floor's ±50 m) at 2 s ends the mission at the log
    row that sees it, naming it, with its records kept; both ways alike."""

    def carry_off(t, plant):
        if t >= 2.0:
            m, body = plant.model, plant.scene.body[2]
            plant.data.qpos[m.jnt_qposadr[m.body_jntadr[body]]] = 60.0

    shared = _run(True, hook=carry_off)
    alone = _run(False, hook=carry_off)
    ended = [e for e in shared.events.items if e["kind"] == "mission_ended"]
    assert len(ended) == 1 and ended[0]["robots"] == [3], ended
    assert "robot 3 left the arena" in ended[0]["reason"]
    assert 2.0 < shared.log["t"][-1] <= 2.1 and shared.log["x"][-1, 2, 0] > 50.0
    assert np.all(np.abs(shared.log["x"][:-1]) < 50.0)  # the row before: all on the floor
    _same(shared, alone)


def test_a_robot_lifted_beside_the_pass_stops_the_run_where_it_would_have():
    """A robot lifted off the floor stops a run whose pass is shared at the period, with
    the message, log and events of the run in one thread."""

    def lift(t, plant):
        if 2.0 <= t < 2.01:
            m, body = plant.model, plant.scene.body[2]
            plant.data.qpos[m.jnt_qposadr[m.body_jntadr[body]] + 2] += 0.3

    d = scenario_dict()
    d["team"] = ring_team(N, 0.5, chord=2)
    d["team"]["robot_model"] = "diffdrive"
    d["obstacles"], d["duration"], d["faults"] = [], 6.0, []
    d["gains"]["G"] = 0.02
    d["fdir"]["initial_error_bound"] = "auto"
    shared = _run(True, hook=lift, scenario=make(d))
    alone = _run(False, hook=lift, scenario=make(d))
    assert not shared.ok and "robot 3 left the plane at t = 2.01 s" in str(shared.error)
    assert str(shared.error) == str(alone.error)
    _same(shared, alone)
