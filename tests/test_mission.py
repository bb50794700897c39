import numpy as np
import pytest

from dftc_mujoco import mission
from dftc_mujoco.scenario import CentroidPath


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
