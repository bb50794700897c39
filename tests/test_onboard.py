"""The onboard blocks in pure numpy: locality, convergence, eq. 18's properties."""

import copy

import numpy as np
import pytest

from dftc_mujoco.graph import Graph
from dftc_mujoco.mission import polygon_offsets
from dftc_mujoco.onboard import observer
from dftc_mujoco.onboard.supervisor import Supervisor
from dftc_mujoco.onboard.team import Team, TeamConfig
from tests.conftest import ring_with_chords

PAPER_EDGES = ((0, 1), (1, 2), (2, 3), (3, 0), (3, 1))


def _graph(n: int) -> Graph:
    if n == 4:
        return Graph(4, PAPER_EDGES)
    return Graph(n, tuple((a - 1, b - 1) for a, b in ring_with_chords(n)))


def _team(n: int, obstacles: bool = False) -> tuple[Team, np.ndarray]:
    rng = np.random.default_rng(n)
    offsets = polygon_offsets(n, 0.5)
    pos = np.array([[0.0, 0.6]]) if obstacles else np.zeros((0, 2))
    cfg = TeamConfig(
        _graph(n),
        kc=4.0,
        ko=6.0,
        theta=3.0,
        dt=0.01,
        obstacle_position=pos,
        obstacle_safe=np.full(len(pos), 0.37),
        obstacle_activation=np.full(len(pos), 0.45),
    )
    x = offsets + rng.normal(scale=0.1, size=offsets.shape)
    return Team(cfg, x, prior=offsets), x


def _integrate(team: Team, x: np.ndarray, steps: int, velocity=(0.1, 0.0)):
    """Closed loop with an ideal integrator plant ẋ = u (eq. 1 with φ = ξ = 0)."""
    offsets = polygon_offsets(team.n, 0.5)
    v = np.array(velocity)
    for k in range(steps):
        t = k * team.config.dt
        out = team.step(x.copy(), offsets + v * t, np.broadcast_to(v, x.shape))
        x = x + team.config.dt * out.u_bar
    return x


@pytest.mark.parametrize("n", [4, 12])
def test_update_of_robot_i_ignores_non_neighbours(n):
    team, x = _team(n)
    x = _integrate(team, x, 50)
    graph = team.config.graph
    x_d = polygon_offsets(n, 0.5) + np.array([0.5, 0.0])
    v = np.broadcast_to([0.1, 0.0], x.shape)
    for i in range(n):
        heard = set(graph.in_neighbours(i)) | {i}
        base = copy.deepcopy(team)
        out = base.step(x.copy(), x_d, v)
        ref = (
            out.u.copy(),
            out.residual[i].copy(),
            base.state.y_hat[i].copy(),
            base.state.int_u_hat[i].copy(),
        )
        for k in range(n):
            other = copy.deepcopy(team)
            other.state.y_hat[k] += 0.37  # robot k broadcasts a different ŷ
            x_m = x.copy()
            if k != i:
                x_m[k] += 0.21  # and measures something else
            o = other.step(x_m, x_d, v)
            got = (o.u, o.residual[i], other.state.y_hat[i], other.state.int_u_hat[i])
            same = all(
                np.array_equal(a[i] if j == 0 else a, b[i] if j == 0 else b)
                for j, (a, b) in enumerate(zip(ref, got, strict=True))
            )
            if k in heard:
                assert not same, f"robot {i + 1} must react to robot {k + 1}'s message"
            else:
                assert same, f"robot {i + 1} used robot {k + 1}'s data without a link"


def test_messages_sum_matches_laplacian():
    g = _graph(12)
    msg = observer.Messages(g.edges, g.n)
    y = np.random.default_rng(0).normal(size=(g.n, g.n, 2))
    expected = -np.einsum("ij,jkd->ikd", g.laplacian(), y)
    assert np.allclose(msg.neighbour_sum(y), expected)


@pytest.mark.parametrize("n", [4, 12])
def test_observer_and_formation_converge_on_an_ideal_plant(n):
    team, x = _team(n)
    x = _integrate(team, x, 1500)  # 15 s
    t_end = 15.0 - 0.01
    target = polygon_offsets(n, 0.5) + np.array([0.1 * t_end, 0.0])
    assert np.abs(x - target).max() < 0.01
    x_hat = team.state.estimate()
    assert np.abs(x_hat - x[None]).max() < 0.01  # every robot knows the whole team


def test_reactive_input_does_not_disturb_the_estimates():
    """Remark 4.1: with Δuᵢ in the observer, reactive inputs are not mistaken for faults."""
    team2, x2 = _team(4, obstacles=True)
    offsets = polygon_offsets(4, 0.5)
    any_reactive = False
    for k in range(1200):
        v = np.array([0.0, 0.1])
        out = team2.step(x2.copy(), offsets + v * k * 0.01, np.broadcast_to(v, x2.shape))
        any_reactive |= out.reactive.any()
        x2 = x2 + 0.01 * out.u_bar
    assert any_reactive
    y_err = np.abs(team2.state.y_hat - (x2 - team2.state.int_u_own)[None]).max()
    assert y_err < 1e-3  # ỹ* converges whatever the inputs (Theorem 1)


def test_supervisor_eq18_and_continuity():
    sup = Supervisor(1, theta=3.0)
    obs, safe, act = np.array([[0.0, 0.0]]), np.array([0.4]), np.array([0.5])
    x = np.array([[0.45, 0.0]])
    # global input heading into the obstacle: avoidance on
    u, du = sup.step(x, np.array([[-0.2, 0.1]]), obs, safe, act)
    assert sup.reactive[0]
    assert u[0, 0] == pytest.approx(3.0 * (0.4 - 0.45))  # radial part: θ (d − ‖x − x_o‖)
    assert u[0, 1] == pytest.approx(0.1)  # tangential part kept: null-space projection
    assert np.allclose(du, u - [[-0.2, 0.1]])
    # global input approaching exactly as fast as eq. 17 allows: the two coincide
    u_g = np.array([[3.0 * (0.4 - 0.45) + 0.001, 0.1]])
    u2, _ = sup.step(x, u_g, obs, safe, act)
    assert np.allclose(u2, [[3.0 * (0.4 - 0.45), 0.1]], atol=1e-3)
    # beyond the activation distance nothing happens
    sup2 = Supervisor(1, theta=3.0)
    _, du3 = sup2.step(np.array([[0.6, 0.0]]), np.array([[-0.2, 0.0]]), obs, safe, act)
    assert not sup2.reactive[0] and np.allclose(du3, 0)
