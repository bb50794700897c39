"""The physics step beside a shared pass (physics_step.py, onboard/sharing.py): a team that
shares its pass over the N × N state between threads advances MuJoCo in one of them, and
the run's records are the very ones of a run that takes turns."""

from __future__ import annotations

import numpy as np
import pytest

from dftc_mujoco import loop
from dftc_mujoco.onboard import resident, sharing
from dftc_mujoco.onboard import team as team_mod
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


def _run(shared: bool, monkeypatch, hook=None, engine="resident", scenario=None):
    monkeypatch.setattr(team_mod, "PARALLEL_FROM", 4)
    monkeypatch.setattr(team_mod, "PARALLEL_ALLOWED", shared)
    monkeypatch.setattr(sharing, "RESIDENT_ALLOWED", engine == "resident")
    with loop.Simulation(scenario or _ring(26.0), hook=hook) as sim:
        assert sim.team.shares == shared
        watched = []  # the periods whose premises' monitor ran beside the pass
        sim.hook = lambda t, plant: (watched.append(sim._physics.watched), hook and hook(t, plant))
        result = sim.run(progress=False)
        assert any(watched) == shared  # a shared team's monitor runs beside its pass
        spent = sim.team._sharing.timings[0] if shared else 0.0
        if shared:  # who ran the helpers' rows (resident helpers: x86-64 Linux)
            ran = engine if engine == "pool" or resident.available() else "pool"
            assert sim.team._sharing.engine == ran
    return result, spent


def _same(a, b):
    assert sorted(a.log) == sorted(b.log)
    for name in a.log:
        assert np.array_equal(a.log[name], b.log[name], equal_nan=True), name
    assert a.events.items == b.events.items
    wall = ("wall_time", "real_time_factor", "build_time")
    sa = {k: v for k, v in a.summary.items() if k not in wall}
    sb = {k: v for k, v in b.summary.items() if k not in wall}
    assert sa == sb


@pytest.mark.parametrize("engine", ["resident", "pool"])
def test_the_physics_beside_a_shared_pass_gives_the_very_same_run(engine, monkeypatch):
    """Through a detection and an exclusion (a re-planned formation, a resized team):
    every log array, event and summary entry is bit for bit that of the run in one thread,
    whoever ran the helpers' rows, and the physics step was the work run beside the pass."""
    shared, spent = _run(True, monkeypatch, engine=engine)
    alone, _ = _run(False, monkeypatch)
    kinds = {e["kind"] for e in shared.events.items}
    assert {"fault", "detection", "exclusion"} <= kinds
    assert spent > 0.0  # the time spent on the beside work: MuJoCo's step
    _same(shared, alone)


def test_physics_trouble_beside_the_pass_stops_the_run_where_it_would_have(monkeypatch):
    """MuJoCo's error raised in the helper thread ends the run at the period it would have
    ended in one thread, with the same message, log and events."""

    def break_physics(t, plant):
        if t >= 2.0:
            plant.data.qvel[0] = np.nan

    shared, _ = _run(True, monkeypatch, hook=break_physics)
    alone, _ = _run(False, monkeypatch, hook=break_physics)
    assert not shared.ok and "MuJoCo warning BADQVEL" in str(shared.error)
    assert str(shared.error) == str(alone.error)
    assert 1.9 < shared.log["t"][-1] < 2.1
    _same(shared, alone)


@pytest.mark.parametrize("periods", [1, 7])
def test_stepping_a_shared_team_period_by_period_shows_the_same_snapshots(periods, monkeypatch):
    """step(k) with the physics beside the pass: the snapshots are those of one thread."""
    snaps = {}
    for shared in (True, False):
        monkeypatch.setattr(team_mod, "PARALLEL_FROM", 4)
        monkeypatch.setattr(team_mod, "PARALLEL_ALLOWED", shared)
        with loop.Simulation(_ring(6.0)) as sim:
            snaps[shared] = [sim.step(periods) for _ in range(140 // periods)]
    for a, b in zip(snaps[True], snaps[False], strict=True):
        assert a.t == b.t and a.events == b.events
        for name in ("x", "x_m", "x_hat", "u", "u_bar", "phi_hat", "residual", "flag"):
            assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), name


def test_a_robot_carried_off_the_floor_ends_the_mission_at_the_next_log_row(monkeypatch):
    """A robot put 60 m out (beyond the floor's ±50 m) at 2 s ends the mission at the log
    row that sees it, naming it, with its records kept; both ways alike."""

    def carry_off(t, plant):
        if t >= 2.0:
            m, body = plant.model, plant.scene.body[2]
            plant.data.qpos[m.jnt_qposadr[m.body_jntadr[body]]] = 60.0

    shared, _ = _run(True, monkeypatch, hook=carry_off)
    alone, _ = _run(False, monkeypatch, hook=carry_off)
    ended = [e for e in shared.events.items if e["kind"] == "mission_ended"]
    assert len(ended) == 1 and ended[0]["robots"] == [3], ended
    assert "robot 3 left the arena" in ended[0]["reason"]
    assert 2.0 < shared.log["t"][-1] <= 2.1 and shared.log["x"][-1, 2, 0] > 50.0
    assert np.all(np.abs(shared.log["x"][:-1]) < 50.0)  # the row before: all on the floor
    _same(shared, alone)


def test_a_robot_lifted_beside_the_pass_stops_the_run_where_it_would_have(monkeypatch):
    """The premises' monitor runs beside a shared pass: a robot lifted off the floor stops
    the run at the period, with the message, log and events of the run in one thread."""

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
    shared, _ = _run(True, monkeypatch, hook=lift, scenario=make(d))
    alone, _ = _run(False, monkeypatch, hook=lift, scenario=make(d))
    assert not shared.ok and "robot 3 left the plane at t = 2.01 s" in str(shared.error)
    assert str(shared.error) == str(alone.error)
    _same(shared, alone)
