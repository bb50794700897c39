"""Fault tolerance on MuJoCo physics: compensation, isolation, exclusion, re-planning."""

import json
import subprocess
import sys

import numpy as np
import pytest

from dftc_mujoco import run, scenario
from dftc_mujoco.closed_loop import loop
from tests.conftest import make, ring_team, scenario_dict

SLOW_SEEDS = [pytest.param(s, marks=pytest.mark.slow) for s in (4, 5, 6, 7, 8)]


def _detections(summary, robot=None):
    return [d for d in summary["detections"] if robot is None or d["robot"] == robot]


@pytest.mark.parametrize("seed", [1, 2, 3, *SLOW_SEEDS])
def test_paper_case_outcome(seed):
    s = scenario.load("paper_case").with_overrides(seed=seed)
    r = loop.simulate(s)
    out = r.summary
    assert out["status"] == "ok"
    # robot 1 flagged by all four robots within Δt_d,max of whichever flags first
    d1 = _detections(out, 1)
    assert sorted(d["by"] for d in d1) == [1, 2, 3, 4]
    first = min(d["t"] for d in d1)
    assert first > 41.8 and max(d["t"] for d in d1) - first <= s.fdir.dt_d_max
    # robots 2, 3, 4 never flagged by anyone
    assert _detections(out) == d1
    # robot 1 excluded exactly once, at t_r = min ⁱt_d + Δt_d,max (eq. 43)
    assert out["exclusions"] == [{"robot": 1, "t": pytest.approx(first + s.fdir.dt_d_max)}]
    # φ̂₂ mean error ≤ 0.02 m/s per component once settled
    (fe,) = out["fault_estimates"]
    assert fe["robot"] == 2 and max(fe["mean_error"]) <= 0.02
    # at 60 s: a triangle of side 0.5 ± 0.01 m, centroid within 0.02 m of the path
    log = r.log
    tri = log["x"][-1, 1:]
    sides = np.linalg.norm(tri - np.roll(tri, -1, axis=0), axis=1)
    assert np.all(np.abs(sides - 0.5) <= 0.01), sides
    assert log["sigma_err"][-1, 0] <= 0.02 and out["errors"]["final_centroid"] <= 0.02
    # nobody closer than d − 1 cm to a cylinder or to the stopped robot
    assert out["min_safe_distance_margin"] >= -0.01
    after = log["t"] >= out["exclusions"][0]["t"]
    gap = np.linalg.norm(log["x"][after, 1:] - log["x"][after, :1], axis=2)
    assert gap.min() >= s.fdir.excluded_safe_distance - 0.01
    # healthy residuals stay below their thresholds
    assert out["margin"] < 1
    assert out["warnings"] == []


def test_logs_after_exclusion():
    s = scenario.load("paper_case").with_overrides(duration=56.0)
    r = loop.simulate(s)
    log, t_r = r.log, r.summary["exclusions"][0]["t"]
    before, after = log["t"] < t_r, log["t"] > t_r
    assert log["active"][before].all() and not log["active"][after, 0].any()
    assert log["active"][after, 1:].all()
    # the excluded robot's rows and columns are gone from every collective quantity
    assert np.isnan(log["residual"][after, 0]).all()
    assert np.isnan(log["threshold"][after][:, :, 0]).all()
    assert np.isfinite(log["threshold"][after][:, 1:, 1:]).all()
    assert np.isnan(log["x_hat"][after, 1:, 0]).all()
    # thresholds were restarted for the 3-robot graph: different κ, λ, still finite and positive
    mu = log["threshold"]
    assert (mu[after][:, 1:, 1:] > 0).all()
    assert not np.allclose(mu[after][-1, 1:, 1:], mu[before][-1, 1:, 1:])
    assert np.isfinite(log["phi_hat"]).all()
    # the stopped robot's commands are zero once it is out of the team
    assert np.abs(log["u"][after, 0]).max() == 0.0


@pytest.mark.parametrize("seed", [1, 2, 3, *SLOW_SEEDS])
def test_fault_free_run_at_noise_bounds_has_no_detection(seed):
    d = scenario_dict()
    d["faults"], d["seed"] = [], seed
    d["noise"]["at_bound"] = True
    r = loop.simulate(make(d))
    assert r.summary["detections"] == [] and r.summary["exclusions"] == []
    assert r.summary["margin"] < 1


def test_bias_too_large_to_compensate_is_isolated_like_a_stop():
    d = scenario_dict()
    # robot 1's y actuator gains -1.6 m/s (away from the team): beyond the ±1 m/s range
    d["faults"] = [
        {"robot": 1, "kind": "bias", "t": 20.0, "value": [0.0, -1.6], "time_constant": 0.2}
    ]
    d["duration"] = 32.0
    r = loop.simulate(make(d))
    out = r.summary
    d1 = _detections(out, 1)
    assert {x["by"] for x in d1} == {1, 2, 3, 4}
    assert _detections(out) == d1
    assert [e["robot"] for e in out["exclusions"]] == [1]
    assert out["warnings"] == [  # said before the run: this bias is not recoverable
        "<test>: faults[1].value: a bias of 1.6 m/s on robot 1 cannot be compensated within "
        "the ±1 m/s command range while the team moves at 0.1 m/s: it acts as an "
        "unrecoverable fault"
    ]
    # the robot really could not be held: it drifted away at about 1.6 - 1 m/s
    x1 = r.log["x"][:, 0]
    assert x1[-1, 1] - x1[r.log["t"] == 20.0][0, 1] < -3.0
    # anti-windup: ∫e is frozen while saturated, so φ̂ settles (at G⁻¹e, the
    # proportional term of eq. 31) instead of winding up for ever
    phi_hat = np.abs(r.log["phi_hat"][:, 0, 1])
    late = r.log["t"] >= 28.0
    assert phi_hat[late].max() < 50.0
    assert abs(phi_hat[late][-1] - phi_hat[late][0]) < 0.1 * phi_hat[late][0]


def test_two_stop_faults_on_six_robots_are_handled_one_after_the_other():
    d = scenario_dict()
    d["team"] = ring_team(6, 0.5, chord=2)
    d["obstacles"] = []
    d["faults"] = [{"robot": 1, "kind": "stop", "t": 12.0}, {"robot": 4, "kind": "stop", "t": 30.0}]
    d["duration"] = 50.0
    d["fdir"]["initial_error_bound"] = "auto"  # paper_case's 1 m is below this start
    r = loop.simulate(make(d))
    out = r.summary
    assert [e["robot"] for e in out["exclusions"]] == [1, 4]
    assert {x["robot"] for x in out["detections"]} == {1, 4}
    t1, t4 = (e["t"] for e in out["exclusions"])
    assert 12.0 < t1 < 30.0 < t4
    assert out["warnings"] == []
    square = r.log["x"][-1, [1, 2, 4, 5]]
    dists = np.sort(np.linalg.norm(square[:, None] - square[None], axis=2)[np.triu_indices(4, 1)])
    assert np.allclose(dists[:4], 0.5, atol=0.01)  # four sides
    assert np.allclose(dists[4:], 0.5 * np.sqrt(2), atol=0.015)  # two diagonals


def test_excluded_robot_is_avoided_as_an_obstacle():
    d = scenario_dict()
    d["obstacles"] = []
    d["faults"] = [{"robot": 1, "kind": "stop", "t": 4.0}]
    d["fdir"]["dt_d_max"] = 2.0
    d["gains"]["theta"] = 6.0
    d["duration"] = 30.0
    # out along x, then back along y = -0.3 right over where robot 1 stopped
    d["mission"]["centroid"] = {
        "waypoints": [[0, 0], [1.0, 0], [1.0, -0.3], [-2.0, -0.3]],
        "speed": 0.1,
        "corner_radius": 0.15,
        "ramp_time": 2.0,
    }
    s = make(d)
    r = loop.simulate(s)
    out = r.summary
    assert [e["robot"] for e in out["exclusions"]] == [1]
    avoided = [e for e in r.events.of_kind("reactive_on") if e["obstacle"] == "robot 1"]
    assert avoided  # named where it was the nearest obstacle (robot 3 had robot 4 nearer)
    log, t_r = r.log, out["exclusions"][0]["t"]
    after = log["t"] >= t_r
    gap = np.linalg.norm(log["x"][after, 1:] - log["x"][after, :1], axis=2).min(axis=0)
    safe = s.fdir.excluded_safe_distance
    # all three survivors went round it, at its safe distance and no nearer
    assert np.all((safe - 0.01 <= gap) & (gap <= safe + 0.02)), gap


def test_exclusion_that_breaks_the_graph_is_reported_and_the_run_goes_on():
    """Without re-wiring (``fdir.rewire = "none"``): the split is a warning, the robots that
    cannot be judged get infinite thresholds, and the run goes on."""
    d = scenario_dict()
    d["obstacles"] = []
    # paper graph without robot 2: robot 3 has no in-neighbour left
    d["faults"] = [{"robot": 2, "kind": "stop", "t": 5.0}]
    d["duration"] = 20.0
    d.setdefault("fdir", {})["rewire"] = "none"
    r = loop.simulate(make(d))
    out = r.summary
    assert out["status"] == "ok"
    assert [e["robot"] for e in out["exclusions"]] == [2]
    assert len(out["warnings"]) == 1 and "not strongly connected" in out["warnings"][0]
    after = r.log["t"] > out["exclusions"][0]["t"]
    mu = r.log["threshold"][after][:, [0, 2, 3]][:, :, [0, 2, 3]]  # robots 1, 3, 4
    # robot 3 roots the spanning tree 3 -> 4 -> 1: pinning it still gives a Hurwitz
    # matrix, so robot 3 can be judged; robots 1 and 4 can no longer be (λ = 0)
    assert np.isfinite(mu[:, :, 1]).all()
    assert np.isinf(mu[:, :, [0, 2]]).all()
    assert not np.isnan(mu).any()


def test_cli_lists_the_events_in_time_order(tmp_path, capsys):
    assert run.main(["paper_case", "--out", str(tmp_path), "--no-progress", "--no-video"]) == 0
    text = capsys.readouterr().out
    lines = [ln for ln in text.splitlines() if ln[:8].strip().replace(".", "").isdigit()]
    times = [float(ln.split()[0]) for ln in lines]
    assert times == sorted(times)
    body = "\n".join(lines)
    for needle in (
        "fault: bias on robot 2",
        "fault: stop on robot 1",
        "robot 3 flags robot 1",
        "robot 1 excluded from the team",
        "switches to obstacle avoidance (cylinder",
    ):
        assert needle in body, needle
    assert "flags robot 2" not in body


def test_a_team_reduced_to_one_robot_ends_the_mission_with_its_records(tmp_path):
    """Two robots, both stop: excluding the first leaves one robot, which is no team.
    The run ends there with an event and status "ended", keeping every record (it used
    to crash in the threshold set-up and leave nothing)."""
    two = tmp_path / "two.toml"
    faults = [{"robot": 1, "kind": "stop", "t": 10.0}, {"robot": 2, "kind": "stop", "t": 30.0}]
    s = scenario.load_scenario(
        "paper_case",
        {
            "team.robots": 2,
            "team.initial_positions": [[-0.3, 0.0], [0.3, 0.0]],
            "team.graph": [[1, 2], [2, 1]],
            "faults": faults,
            "obstacles": [],
            "duration": 40.0,
        },
    )
    two.write_text(s.to_toml())
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "dftc_mujoco.run",
            str(two),
            "--no-video",
            "--out",
            str(tmp_path / "o"),
        ],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert out.returncode == 0, out.stderr
    assert "Traceback" not in out.stderr
    assert "MISSION ENDED: the team was reduced to robot 2 alone" in out.stdout
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["status"] == "ended" and summary["exclusions"][0]["robot"] == 1
    assert summary["end_reason"] == "the team was reduced to robot 2 alone"
    with np.load(tmp_path / "o" / "log.npz") as log:
        assert log["t"][-1] == pytest.approx(summary["exclusions"][0]["t"])
        assert list(log["active"][-1]) == [False, True]
