"""The onboard blocks in pure numpy: locality, convergence, eq. 18's properties."""

import copy

import numpy as np
import pytest

from dftc_mujoco.graph import Graph
from dftc_mujoco.mission import polygon_offsets
from dftc_mujoco.onboard import observer
from dftc_mujoco.onboard.supervisor import Supervisor
from dftc_mujoco.onboard.team import Team, TeamConfig
from dftc_mujoco.scenario import Formation
from tests.conftest import ring_with_chords

PAPER_EDGES = ((0, 1), (1, 2), (2, 3), (3, 0), (3, 1))


def _graph(n: int) -> Graph:
    if n == 4:
        return Graph(4, PAPER_EDGES)
    return Graph(n, tuple((a - 1, b - 1) for a, b in ring_with_chords(n)))


def _team(n: int, obstacles: bool = False, **changes) -> tuple[Team, np.ndarray]:
    rng = np.random.default_rng(n)
    offsets = polygon_offsets(n, 0.5)
    pos = np.array([[0.0, 0.6]]) if obstacles else np.zeros((0, 2))
    settings = dict(
        graph=_graph(n),
        kc=4.0,
        ko=6.0,
        K=3.0 * np.eye(2),
        G=0.01 * np.eye(2),
        theta=3.0,
        dt=0.01,
        eta_bar=0.001,
        xi_bar=0.005,
        formation=Formation("polygon", 0.5),
        obstacle_position=pos,
        obstacle_safe=np.full(len(pos), 0.37),
        obstacle_activation=np.full(len(pos), 0.45),
    )
    settings.update(changes)
    x = offsets + rng.normal(scale=0.1, size=offsets.shape)
    return Team(TeamConfig(**settings), x, np.zeros(2)), x


def _integrate(
    team: Team, x: np.ndarray, steps: int, velocity=(0.1, 0.0), t0: float = 0.0, fault=None
):
    """Closed loop with an ideal integrator plant ẋ = ū + φ (eq. 1 with ξ = η = 0)."""
    v = np.array(velocity)
    for k in range(steps):
        t = t0 + k * team.config.dt
        out = team.step(t, x.copy(), v * t, v)
        phi = fault(t, out) if fault else 0.0
        x = x + team.config.dt * (out.u_bar + phi)
    return x


@pytest.mark.parametrize("compiled", [False, True])  # numpy path, numba kernel (if installed)
@pytest.mark.parametrize("n", [4, 12, 20])  # 20: the sparse-message path
def test_update_of_robot_i_ignores_non_neighbours(n, compiled):
    """Robot i's command, residual, thresholds, flags and next state use only its own
    data and its in-neighbours' messages: changing anything else leaves them bit-identical."""
    team, x = _team(n, compiled=compiled)
    from dftc_mujoco.onboard import kernel

    assert team.compiled == (compiled and kernel.AVAILABLE)
    x = _integrate(team, x, 50)
    graph = team.config.graph
    c, v = np.array([0.5, 0.0]), np.array([0.1, 0.0])

    def robot_view(tm, out, i):
        return (
            out.u_bar[i],
            out.phi_hat[i],
            out.residual[i],
            out.threshold[i],
            out.flag[i],
            tm.state.y_hat[i],
            tm.state.int_u_hat[i],
            tm.state.int_u_own[i],
        )

    for i in range(n):
        heard = set(graph.in_neighbours(i)) | {i}
        base = copy.deepcopy(team)
        ref = [a.copy() for a in robot_view(base, base.step(0.5, x.copy(), c, v), i)]
        for k in range(n):
            other = copy.deepcopy(team)
            other.state.y_hat[k] += 0.37  # robot k broadcasts a different ŷ
            x_m = x.copy()
            if k != i:
                x_m[k] += 0.21  # and measures something else
            got = robot_view(other, other.step(0.5, x_m, c, v), i)
            same = all(np.array_equal(a, b) for a, b in zip(ref, got, strict=True))
            if k in heard:
                assert not same, f"robot {i + 1} must react to robot {k + 1}'s message"
            else:
                assert same, f"robot {i + 1} used robot {k + 1}'s data without a link"


@pytest.mark.parametrize("n", [12, observer.SPARSE_FROM, 40])
def test_messages_sum_matches_laplacian(n):
    """Both paths (gather and sparse matrix) compute −(L ⊗ I) ŷ."""
    g = _graph(n)
    msg = observer.Messages(g.edges, g.n)
    assert (msg.adjacency is not None) == (n >= observer.SPARSE_FROM)
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
    any_reactive = False
    v = np.array([0.0, 0.1])
    for k in range(1200):
        out = team2.step(k * 0.01, x2.copy(), v * k * 0.01, v)
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
