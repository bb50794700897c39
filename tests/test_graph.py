import numpy as np

from dftc_mujoco.core.graph import Graph

PAPER = Graph(4, ((0, 1), (1, 2), (2, 3), (3, 0), (3, 1)))


def test_adjacency_follows_paper_convention():
    a = PAPER.adjacency()
    assert a[1, 0] == 1 and a[0, 1] == 0  # 1 -> 2: robot 2 receives from robot 1
    assert list(PAPER.in_degree()) == [1, 2, 1, 1]
    assert PAPER.in_neighbours(1) == [0, 3]


def test_laplacian_rows_sum_to_zero_and_rank():
    lap = PAPER.laplacian()
    assert np.allclose(lap.sum(axis=1), 0)
    assert np.linalg.matrix_rank(lap) == 3  # N - 1 for a strongly connected graph (§3.1)


def test_strong_connectivity_with_and_without_robot_one():
    assert PAPER.is_strongly_connected()
    assert PAPER.without(0).is_strongly_connected()  # docs/notes.md, 9: ring + chord 4 -> 2
    ring = Graph(4, ((0, 1), (1, 2), (2, 3), (3, 0)))
    assert ring.is_strongly_connected()
    assert not ring.without(0).is_strongly_connected()  # docs/notes.md, 9: the ring breaks


def test_without_renumbers():
    g = PAPER.without(0)
    assert g.n == 3
    assert set(g.edges) == {(0, 1), (1, 2), (2, 0)}
