"""The onboard blocks: locality, convergence, eq. 18's properties, both paths identical."""

import copy

import numpy as np
import pytest
from numba import njit

from dftc_mujoco import check_locality
from dftc_mujoco.blocks import paper
from dftc_mujoco.core.graph import Graph
from dftc_mujoco.core.mission import polygon_offsets
from dftc_mujoco.onboard import observer
from dftc_mujoco.onboard.execution.locality import deliver, demo_team, integrate
from tests.conftest import ring_with_chords

PAPER_EDGES = ((0, 1), (1, 2), (2, 3), (3, 0), (3, 1))


def _graph(n: int) -> Graph:
    if n == 4:
        return Graph(4, PAPER_EDGES)
    return Graph(n, tuple((a - 1, b - 1) for a, b in ring_with_chords(n)))


def _team(n: int, obstacles: bool = False, blocks=None, **changes):
    return demo_team(n, blocks, _graph(n), obstacles, seed=n, **changes)


def _integrate(team, x, steps, velocity=(0.1, 0.0), t0=0.0, fault=None):
    return integrate(team, x, steps, velocity, t0, fault)


@pytest.fixture(params=["compiled", "general"])
def path(request, monkeypatch):
    """Run a test on the compiled period and on the blocks' Python methods."""
    monkeypatch.setenv("DFTC_PERIOD", request.param)
    return request.param


@pytest.mark.parametrize("n", [4, 12, 20])
def test_update_of_robot_i_ignores_non_neighbours(n, path):
    """Robot i's command, residual, thresholds, flags and next state use only its own
    data and its in-neighbours' messages: changing anything else leaves them bit-identical,
    and changing an in-neighbour's message changes them."""
    team, _ = _team(n)
    assert team.path == path
    assert check_locality(n=n, graph=_graph(n), require_reaction=True) == []


class _Peeking(paper.Controller):
    """A controller that (wrongly) averages every robot's estimate of the team."""

    def collective_input(self, x_hat, x_d, xd_dot):
        shared = np.broadcast_to(x_hat.mean(axis=0), x_hat.shape)  # rows of other robots!
        return super().collective_input(shared, x_d, xd_dot)


def test_locality_check_catches_a_block_that_reads_other_robots():
    problems = check_locality({"controller": _Peeking()}, n=6)
    assert problems and "without a link" in problems[0]


def test_messages_sum_matches_laplacian():
    g = _graph(12)
    msg = observer.Messages(g.edges, g.n)
    y = np.random.default_rng(0).normal(size=(g.n, g.n, 2))
    expected = -np.einsum("ij,jkd->ikd", g.laplacian(), y)
    assert np.allclose(msg.neighbour_sum(y), expected)


@njit
def _residual_rows(y_hat, int_u_own, x_m, src, first_edge, in_degree, links, networked):
    out = np.empty((y_hat.shape[0], y_hat.shape[0] * y_hat.shape[2]))
    for i in range(y_hat.shape[0]):
        observer.residual_row(
            y_hat, int_u_own, x_m, src, first_edge, in_degree, links, networked, i, out[i],
            out[i], np.nan,
        )  # fmt: skip
    return out


@pytest.mark.parametrize("networked", [False, True])
def test_the_residual_sums_its_messages_left_to_right_whatever_the_in_degree(networked):
    """Eq. 35 as the pass computes it, up to three messages in one loop: bit for bit the
    sum taken a message at a time, −|Nᵢ| ⁱŷ + ʲ¹ŷ + ʲ²ŷ + … left to right, then the own
    measurement's term, for in-degrees 0 to 6 (the current ŷ of each sender, or on a
    network the message each link delivered); and eq. 35 itself to rounding."""
    rng = np.random.default_rng(35)
    m, n = 9, 2
    src, first, degree = [], [0], []
    for i in range(m):  # robot i hears from i mod 7 teammates (0 to 6), in a shuffled order
        senders = rng.permutation([j for j in range(m) if j != i])[: i % 7]
        src += list(senders)
        first.append(len(src))
        degree.append(len(senders))
    src, first = np.array(src, np.int64), np.array(first, np.int64)
    in_degree = np.array(degree, float)
    y_hat = rng.normal(size=(m, m, n)) * 10.0 ** rng.integers(-3, 4, (m, m, 1))
    int_u_own, x_m = rng.normal(size=(m, n)), rng.normal(size=(m, n))
    links = rng.normal(size=(len(src), m * n)) if networked else np.zeros((0, m * n))
    got = _residual_rows(y_hat, int_u_own, x_m, src, first, in_degree, links, networked)
    flat, expected = y_hat.reshape(m, m * n), np.empty((m, m * n))
    for i in range(m):
        row = -in_degree[i] * flat[i]
        for e in range(first[i], first[i + 1]):
            row = row + (links[e] if networked else flat[src[e]])
        row[i * n : i * n + n] += x_m[i] - int_u_own[i] - y_hat[i, i]
        expected[i] = row
    assert np.array_equal(got, expected)
    sent = links if networked else flat[src]
    for i in range(m):  # Σ_{j∈Nᵢ}(ʲŷ − ⁱŷ) + Πᵢ(y_m,i − ⁱŷᵢ)
        eq35 = (sent[first[i] : first[i + 1]] - flat[i]).sum(axis=0)
        eq35[i * n : i * n + n] += x_m[i] - int_u_own[i] - y_hat[i, i]
        assert np.allclose(got[i], eq35, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("n", [4, 12])
def test_observer_and_formation_converge_on_an_ideal_plant(n):
    team, x = _team(n)
    x = _integrate(team, x, 1500)  # 15 s
    t_end = 15.0 - 0.01
    target = polygon_offsets(n, 0.5) + np.array([0.1 * t_end, 0.0])
    assert np.abs(x - target).max() < 0.01
    x_hat = team.observer.estimate()
    assert np.abs(x_hat - x[None]).max() < 0.01  # every robot knows the whole team


def test_reactive_input_does_not_disturb_the_estimates():
    """Remark 4.1: with Δuᵢ in the observer, reactive inputs are not mistaken for faults."""
    team2, x2 = _team(4, obstacles=True)
    any_reactive = False
    v = np.array([0.0, 0.1])
    for k in range(1200):
        team2.step(k * 0.01, x2.copy(), v * k * 0.01, v)
        any_reactive |= team2.reactive.any()
        x2 = x2 + 0.01 * team2.u_bar
    assert any_reactive
    ob = team2.observer
    y_err = np.abs(ob.y_hat - (x2 - ob.int_u_own)[None]).max()
    assert y_err < 1e-3  # ỹ* converges whatever the inputs (Theorem 1)


def _supervisor():
    sup = paper.Supervisor()
    cfg, _ = _team(4)
    sup.reset(cfg.config, np.zeros((1, 2)), np.zeros((1, 2)))
    return sup


def test_supervisor_eq18_and_continuity():
    sup = _supervisor()
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
    sup2 = _supervisor()
    _, du3 = sup2.step(np.array([[0.6, 0.0]]), np.array([[-0.2, 0.0]]), obs, safe, act)
    assert not sup2.reactive[0] and np.allclose(du3, 0)


def test_controller_eq15_through_its_public_method():
    ctrl = paper.Controller()
    team, _ = _team(4)
    ctrl.reset(team.config, np.zeros((4, 2)), np.zeros((4, 2)))
    rng = np.random.default_rng(1)
    x_hat, x_d, xd_dot = (
        rng.normal(size=(4, 4, 2)),
        rng.normal(size=(4, 2)),
        rng.normal(size=(4, 2)),
    )
    u_hat = ctrl.collective_input(x_hat, x_d, xd_dot)
    assert np.allclose(u_hat, xd_dot[None] + 4.0 * (x_d[None] - x_hat))  # ẋ_d + k_c(x_d − ⁱx̂)
    assert np.array_equal(ctrl.own_input(u_hat), u_hat[np.arange(4), np.arange(4)])  # eq. 16


def _run_side_by_side(a, b, x, v, seed):
    """Step teams ``a`` and ``b`` on the same measurements for 15 s, robot 2 pushed at
    1.5 m/s from 8 s (beyond the command range: anti-windup and a detection), asserting
    that every output and event is the same bit for bit at every period."""
    rng = np.random.default_rng(seed)
    xs = x.copy()
    for k in range(1500):
        t = k * 0.01
        x_m = xs + rng.uniform(-1e-3, 1e-3, xs.shape)
        a.step(t, x_m, v * t, v)
        b.step(t, x_m, v * t, v)
        out_a, out_b = a.outputs(), b.outputs()
        for name in out_a:
            same = np.array_equal(out_a[name], out_b[name], equal_nan=out_a[name].dtype.kind == "f")
            assert same, f"{name} at step {k}"
        assert a.events == b.events
        phi = np.zeros_like(xs)
        if t > 8.0:
            phi[1] = [1.5, 0.0]
        xs = xs + 0.01 * (np.clip(a.u_bar, -1.0, 1.0) + phi)  # actuators saturate at 1 m/s
    assert a.recovery.detected == b.recovery.detected and a.recovery.detected  # caught on both


def test_the_period_shared_between_threads_is_the_same_computation(monkeypatch):
    """From ``shared_from`` members (with more than one thread) the compiled period's pass
    over the N × N state is shared between threads: helpers take rows while the caller sends
    the commands (and the loop steps the physics), the caller taking the rows left when it
    finishes. The same numbers, bit for bit, as in one thread, through a detection, whoever
    took which rows; the commands are out when ``start`` returns."""
    split, x = _team(12, obstacles=False, command_limit=1.0, threads=2, shared_from=8)
    one, _ = _team(12, obstacles=False, command_limit=1.0)
    assert split.shares and not one.shares
    assert split._row.shape[0] == 2 and one._row.shape[0] == 1
    seen: list[np.ndarray] = []
    start = split.start

    def step(t, *given):  # the commands as they are before the pass has ended
        start(t, *given)
        seen.append(split.u_bar.copy())
        return split.finish(t)

    monkeypatch.setattr(split, "step", step)
    _run_side_by_side(split, one, x, np.array([0.1, 0.0]), seed=3)
    assert len(seen) == 1500 and np.array_equal(seen[-1], split.u_bar)
    assert split._sharing is not None and split._sharing.chunks > 0


def test_the_compiled_stages_of_a_shared_period_hold_no_lock_on_python():
    """In a shared period the calling thread computes the commands while the helper threads
    take their rows of the pass: both compiled calls must let go of Python's lock, or a
    helper cannot even begin its rows until the commands end (at N = 1000 it began 0.31 ms
    after it was handed them, the commands' time, instead of 0.04 ms)."""
    from dftc_mujoco.onboard.execution import period

    for stage in (period.commands_call, period.rows_call):
        assert stage.targetoptions.get("nogil") is True, stage.py_func.__name__


@pytest.mark.parametrize(("n", "obstacles"), [(4, True), (4, False), (12, False)])
def test_compiled_and_general_paths_are_the_same_computation(n, obstacles, monkeypatch):
    """The compiled period composes the blocks' own compiled functions: same numbers,
    bit for bit, through obstacles, saturation, anti-windup, a detection and an exclusion."""
    fast, x = _team(n, obstacles=obstacles, command_limit=1.0, phi_bar=0.2)
    monkeypatch.setenv("DFTC_PERIOD", "general")
    slow, _ = _team(n, obstacles=obstacles, command_limit=1.0, phi_bar=0.2)
    assert (fast.path, slow.path) == ("compiled", "general")
    v = np.array([0.0, 0.1]) if obstacles else np.array([0.1, 0.0])
    _run_side_by_side(fast, slow, x, v, seed=n)
    assert list(fast.members) == list(slow.members)
    assert np.array_equal(fast.estimator.int_e, slow.estimator.int_e)
    # each robot's own alarm (estimate_alarm.py): the same timers, and up on the faulty one
    assert fast.alarm.on and np.array_equal(fast.alarm.timer, slow.alarm.timer)
    assert np.array_equal(fast.alarm.seen, slow.alarm.seen)
    assert np.array_equal(fast.alarm.alarm, slow.alarm.alarm) and (fast.alarm.timer > 0).any()
    copy.deepcopy(fast)  # a team can be copied (the locality check relies on it)


@pytest.mark.parametrize("rounds", [1, 3])
def test_periods_that_keep_no_estimates_change_nothing_else(rounds):
    """The compiled period writes ⁱx̂ (the largest array a period writes) only where it is
    asked (:attr:`Team.estimates`: the loop asks at its log rows and the last period of
    step()), and ‖ⁱr_k‖ only there and while an exclusion is pending (its instant reads
    them; over a network, whose rounds' norms are read until the next round, always):
    every other output and event is the same bit for bit, through a detection and an
    exclusion, and the estimates and norms of a period that keeps them are the same too (the
    ideal network, and a round every 3 periods, whose log rows fall between rounds)."""
    net = {"networked": True, "round_periods": rounds} if rounds > 1 else {}
    every, x = _team(12, obstacles=False, command_limit=1.0, **net)
    some, _ = _team(12, obstacles=False, command_limit=1.0, **net)
    rng = np.random.default_rng(12)
    v, xs = np.array([0.1, 0.0]), x.copy()
    kept = norms = 0
    for k in range(2000):
        t = k * 0.01
        x_m = xs + rng.uniform(-1e-3, 1e-3, xs.shape)
        some.estimates = k % 7 == 0
        every.step(t, x_m, v * t, v)
        some.step(t, x_m, v * t, v)  # its exclusion instant raises if the norms were not kept
        deliver(every), deliver(some)
        assert some._norms_kept >= some.estimates
        a, b = every.outputs(), some.outputs()
        for name in a:
            if (name == "x_hat" and not some.estimates) or (
                name == "residual" and not some._norms_kept
            ):
                continue
            same = np.array_equal(a[name], b[name], equal_nan=a[name].dtype.kind == "f")
            assert same, f"{name} at step {k}"
        kept += some.estimates
        norms += some._norms_kept
        assert every.events == some.events
        phi = np.zeros_like(xs)
        if t > 8.0:
            phi[1] = [1.5, 0.0]
        xs = xs + 0.01 * (np.clip(every.u_bar, -1.0, 1.0) + phi)
    assert kept == 286 and every.recovery.detected  # robot 2 was detected on the way
    assert list(every.gone) == list(some.gone) == [1]  # and excluded at its t_r
    assert kept < norms < 2000 if rounds == 1 else norms == 2000


def test_a_simulation_shows_the_estimates_of_its_log_rows_and_of_each_step():
    """The loop asks for ⁱx̂ at its log rows and at the last period of step(): a snapshot
    after step(7) shows the estimates of its own period, the same numbers as stepping one
    period at a time (which writes them every period), and the log has them at every row."""
    from dftc_mujoco import load_scenario
    from dftc_mujoco.closed_loop.loop import Simulation

    s = load_scenario("paper_case", {"duration": 2.0})
    with Simulation(s) as sim:
        sevens = [sim.step(7).x_hat for _ in range(5)]
    with Simulation(s) as sim:
        ones = [sim.step(1).x_hat for _ in range(35)][6::7]
    assert all(np.array_equal(a, b) for a, b in zip(sevens, ones, strict=True))
    assert not np.array_equal(sevens[0], sevens[1])
    with Simulation(s) as sim:
        log = sim.run().log
    assert np.isfinite(log["x_hat"]).all() and len(log["x_hat"]) == len(log["t"])
