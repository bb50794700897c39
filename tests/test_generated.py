"""Generated graphs, formations and layouts (scenario tables), and teams beyond four."""

import numpy as np
import pytest

from dftc_mujoco import scenario
from dftc_mujoco.closed_loop import loop
from dftc_mujoco.core import graph, mission
from dftc_mujoco.errors import ScenarioError
from dftc_mujoco.scenario import Formation
from tests.conftest import make, scenario_dict


@pytest.mark.parametrize("n", [5, 16, 100])
def test_graph_families_are_strongly_connected(n):
    rng = np.random.default_rng(n)
    ring = graph.ring_with_chords(n, (3,))
    assert ring.is_strongly_connected() and set(ring.in_degree()) == {2}
    rnd = graph.random_strongly_connected(n, 3, rng)
    assert rnd.is_strongly_connected() and set(rnd.in_degree()) == {min(3, n - 1)}
    pts = rng.uniform(0, 5, (n, 2))
    knn = graph.k_nearest(pts, 2)
    assert knn.is_strongly_connected()
    assert set(knn.edges) == {(i, j) for j, i in knn.edges}  # undirected


def test_random_graph_is_reproducible_from_the_seed():
    a = graph.random_strongly_connected(20, 3, np.random.default_rng([1, 11]))
    b = graph.random_strongly_connected(20, 3, np.random.default_rng([1, 11]))
    c = graph.random_strongly_connected(20, 3, np.random.default_rng([2, 11]))
    assert a == b and a != c


@pytest.mark.parametrize("shape", ["polygon", "grid", "line"])
@pytest.mark.parametrize("n", [3, 7, 16])
def test_formations_are_centred_with_the_spacing(shape, n):
    off = mission.formation_offsets(Formation(shape, 0.5), n)
    assert off.shape == (n, 2) and np.allclose(off.mean(axis=0), 0)
    dist = np.linalg.norm(off[:, None] - off[None], axis=2)
    np.fill_diagonal(dist, np.inf)
    assert dist.min() == pytest.approx(0.5)  # nearest neighbours are `side` apart
    # re-planning for one robot fewer keeps the shape and the spacing
    new = mission.replan(Formation(shape, 0.5), off[1:])
    d2 = np.linalg.norm(new[:, None] - new[None], axis=2)
    np.fill_diagonal(d2, np.inf)
    assert d2.min() == pytest.approx(0.5) and len(new) == n - 1


def test_scenario_tables_generate_team_and_layout():
    s = scenario.load("grid16")
    assert s.team.robots == 16 and s.team.graph_family == "random"
    assert set(s.team.graph.in_degree()) == {3}
    slots = np.asarray(s.mission.centroid.waypoints[0]) + mission.formation_offsets(
        s.mission.formation, 16
    )
    assert np.abs(np.asarray(s.team.initial_positions) - slots).max() <= 0.1 + 1e-12
    d = scenario_dict()
    d["team"]["graph"] = {"family": "ring_chords", "chords": [2]}
    assert make(d).team.graph == graph.ring_with_chords(4, (2,))
    d["team"]["graph"] = {"family": "ring_chords", "chords": [9]}
    with pytest.raises(ScenarioError, match=r"team\.graph\.chords: expected a list of integers"):
        make(d)
    d["team"]["graph"] = {"family": "smallworld"}
    with pytest.raises(ScenarioError, match=r"team\.graph\.family: expected one of"):
        make(d)


def test_sixteen_robot_grid_tracks_its_formation_on_physics():
    s = scenario.load("grid16").with_overrides(duration=19.0)  # before its fault
    r = loop.simulate(s)
    assert r.summary["status"] == "ok" and r.summary["detections"] == []
    after = r.log["t"] >= 15.0  # the slowest observer mode here is λ ≈ 0.2 1/s
    assert r.log["sigma_err"][after].max() < 0.02
    assert r.log["sigma_err"][-1].max() < 0.015


def test_large_teams_log_their_n_by_n_fields_within_a_memory_budget():
    """The N × N fields (estimates, residuals, thresholds) are logged every k-th row when
    they would not fit in the budget; everything derived from them still works."""
    from dftc_mujoco import load_scenario, simulate
    from dftc_mujoco.core.record import MATRIX_LOG_BUDGET, matrix_every, matrix_rows

    # paper_case fits: every row; N = 400 for 60 s at 50 Hz would take 7.7 GB: 1 row in 29
    assert matrix_every(4, 3002, 2, 0.01, "auto") == 1
    every = matrix_every(400, 3002, 2, 0.01, "auto")
    assert every == 29 and -(-3002 // every) * 400 * 400 * 16 <= MATRIX_LOG_BUDGET
    assert matrix_every(4, 3002, 2, 0.01, 5.0) == 10  # 5 Hz of a 50 Hz log
    s = load_scenario(
        "paper_case", {"physics.matrix_log_rate": 5.0, "duration": 47.0, "noise.at_bound": True}
    )
    r = simulate(s)
    log = r.log
    assert int(log["matrix_every"]) == 10 and len(log["residual"]) == len(log["t"][::10])
    assert log["x_hat"].shape == (len(log["residual"]), 4, 4, 2)
    rows = matrix_rows(log)
    # rows line up: robot 3's estimate of the healthy robots 2-4 is where they are
    assert np.allclose(log["x_hat"][-1][2, 1:], log["x"][rows[-1], 1:], atol=0.01)
    assert r.summary["margin"] < 1 and {d["robot"] for d in r.summary["detections"]} == {1}
    assert len(r.figures()) == 5
