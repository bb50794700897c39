from pathlib import Path

import numpy as np
import pytest

from dftc_mujoco import Simulation, load_scenario, simulate
from dftc_mujoco.core import mission
from dftc_mujoco.errors import ScenarioError
from dftc_mujoco.scenario import CentroidPath

DATA_ROBOTS = Path(__file__).parent / "data" / "robots"


@pytest.mark.parametrize("n", [2, 4, 12])
def test_task_map_matches_dense_jacobian(n):
    x = np.random.default_rng(n).normal(size=(n, 2))
    j = mission.task_matrix(n)
    assert j.shape == (2 * n, 2 * n)
    assert np.allclose(mission.task_map(x).ravel(), j @ x.ravel())  # eqs. 11-13
    assert np.allclose(mission.task_inverse(mission.task_map(x)), x)
    assert np.allclose(np.linalg.inv(j) @ x.ravel(), mission.task_inverse(x).ravel())


@pytest.mark.parametrize("n", [3, 4, 7, 12])
def test_polygon_has_the_requested_side_and_centroid(n):
    p = mission.polygon_offsets(n, 0.5)
    sides = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1)
    assert np.allclose(sides, 0.5)
    assert np.allclose(p.mean(axis=0), 0)


def test_centroid_path_is_smooth_and_at_speed():
    path = CentroidPath(np.array([[0, 0], [2, 0], [2, 2], [0, 2]]), 0.1, 0.4, 2.0)
    tab = mission.centroid_table(path, 80.0, 0.01)
    speed = np.linalg.norm(tab.velocity, axis=1)
    assert speed[0] == 0.0
    assert speed.max() == pytest.approx(0.1, abs=1e-9)
    assert np.abs(np.diff(tab.velocity, axis=0)).max() < 2e-3  # continuous velocity
    # position is the integral of velocity
    integrated = np.cumsum(tab.velocity[:-1] * 0.01, axis=0)
    assert np.abs(integrated[-1] - (tab.position[-1] - tab.position[0])).max() < 5e-3
    # the path ends at the last waypoint and stops there
    assert np.linalg.norm(tab.position[-1] - [0, 2]) < 0.01 and speed[-1] < 0.01


def test_mission_scale_scales_lengths_and_times_once():
    """One key instead of twelve overrides. Lengths and times k times (defaults
    included), speeds unchanged; the scenario read is the scaled one and writes itself
    without the key, so that it reads back the same."""
    base = load_scenario("paper_case")
    s = load_scenario("paper_case", overrides={"mission.scale": 2.0})
    assert s.duration == 2 * base.duration and s.mission.transient == 2 * base.mission.transient
    c, c0 = s.mission.centroid, base.mission.centroid
    np.testing.assert_allclose(c.waypoints, 2 * c0.waypoints)
    assert (c.speed, c.corner_radius, c.ramp_time) == (
        c0.speed,
        2 * c0.corner_radius,
        2 * c0.ramp_time,
    )
    assert s.mission.formation.side == 2 * base.mission.formation.side
    np.testing.assert_allclose(s.team.initial_positions, 2 * base.team.initial_positions)
    for o, o0 in zip(s.obstacles, base.obstacles, strict=True):
        np.testing.assert_allclose(o.position, 2 * o0.position)
        assert (o.radius, o.safe_distance, o.activation_distance) == pytest.approx(
            (2 * o0.radius, 2 * o0.safe_distance, 2 * o0.activation_distance)
        )
    assert [f.t for f in s.faults] == [2 * f.t for f in base.faults]
    assert s.fdir.replan_time == 2 * base.fdir.replan_time
    d, d0 = s.to_dict(), base.to_dict()
    assert d["gains"] == d0["gains"] and d["noise"] == d0["noise"]
    assert "scale" not in s.to_dict()["mission"]
    again = type(s).from_dict(s.to_dict())
    assert again.to_dict() == s.to_dict()
    assert load_scenario("paper_case", overrides={"mission.scale": 1}).to_dict() == base.to_dict()
    with pytest.raises(ScenarioError, match=r"mission\.scale: expected a number > 0"):
        load_scenario("paper_case", overrides={"mission.scale": 0})


def test_a_mission_scaled_for_a_bigger_robot_gives_the_paper_outcome():
    """The holonomic test base (footprint 0.32 m) does not fit paper_case's square; the
    check suggests mission.scale = 1.4, and at that scale robot 1's stop is flagged by its
    teammates and it alone is excluded."""
    robot = str(DATA_ROBOTS / "holobase.robot.toml")
    s = load_scenario("paper_case").with_overrides(robot_model=robot)
    with pytest.raises(ScenarioError, match=r"or mission\.scale = 1\.4 "):
        Simulation(s)
    s = load_scenario("paper_case", overrides={"mission.scale": 1.4, "team.robot_model": robot})
    r = simulate(s, progress=False)
    flags = {(e["by"], e["robot"]) for e in r.events.items if e["kind"] == "detection"}
    assert flags and all(k == 1 for _, k in flags) and len(flags) >= 2
    assert [e["robot"] for e in r.events.items if e["kind"] == "exclusion"] == [1]


def test_a_scaled_mission_still_too_small_suggests_a_scale_that_runs():
    """The suggested scale is the document's: at mission.scale = 1.2 the holonomic test base
    still needs 1.4 (it said 1.2, the scale already given, and at 2.1 a TIAGo was told 2),
    and the scale it suggests passes the check."""
    import re

    robot = str(DATA_ROBOTS / "holobase.robot.toml")
    small = load_scenario("paper_case", overrides={"mission.scale": 1.2, "team.robot_model": robot})
    with pytest.raises(ScenarioError, match=r"mission\.scale = ") as refused:
        Simulation(small)
    suggested = float(re.search(r"mission\.scale = ([0-9.]+) ", str(refused.value)).group(1))
    assert suggested == 1.4
    fits = load_scenario(
        "paper_case", overrides={"mission.scale": suggested, "team.robot_model": robot}
    )
    Simulation(fits).close()


@pytest.mark.parametrize("shape", ["grid", "polygon", "line"])
@pytest.mark.parametrize("n", [1, 2, 3, 7, 100, 1000])
def test_slot_spacing_is_the_smallest_distance_between_two_slots(shape, n):
    """The k-d tree's pairs give the very number the N × N distances give (measured as
    np.hypot measures them), ties of a grid included; one robot has no pair."""
    from dftc_mujoco.core.mission import Formation, formation_offsets, slot_spacing

    f = Formation(shape=shape, side=0.7071)
    spacing = slot_spacing(f, n)
    if n == 1:
        assert spacing == float("inf")
        return
    o = formation_offsets(f, n)
    d = np.hypot(*(o[:, None, :] - o[None]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    assert spacing == float(d.min())
