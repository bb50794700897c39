"""FDIR blocks: κ/λ of eq. 41, thresholds (eq. 40), decisions, exclusion."""

import numpy as np
import pytest
from scipy.linalg import expm

from dftc_mujoco.core.graph import Graph
from dftc_mujoco.onboard import decision
from dftc_mujoco.onboard.thresholds import decay, paper
from tests.test_onboard import _integrate, _team

PAPER = Graph(4, ((0, 1), (1, 2), (2, 3), (3, 0), (3, 1)))
SMALL = {
    "paper": PAPER,
    "ring3": Graph(3, ((0, 1), (1, 2), (2, 0))),
    "complete3": Graph(3, tuple((i, j) for i in range(3) for j in range(3) if i != j)),
    "line3_undirected": Graph(3, ((0, 1), (1, 0), (1, 2), (2, 1))),
    "random5": Graph(5, ((0, 1), (1, 2), (2, 3), (3, 4), (4, 0), (2, 0), (4, 2))),
}


@pytest.mark.parametrize("name", sorted(SMALL))
def test_kappa_lambda_against_brute_force_sup(name):
    g = SMALL[name]
    for k in range(g.n):
        m = decay.observer_matrix(g, 6.0, k)
        kappa, lam = decay.decay_bound(m)
        lam_min = np.linalg.eigvals(m).real.min()
        assert 0 < lam < lam_min
        t = np.linspace(0, 60 / lam_min, 6001)
        norms = np.array([np.linalg.norm(expm(-m * tt), 2) for tt in t])
        sampled = norms * np.exp(lam * t)
        assert sampled.max() <= kappa * (1 + 1e-9)  # eq. 41 holds on a fine grid
        assert kappa <= sampled.max() * 1.01  # and κ is the sup, not a loose bound
        # λ was chosen well: no λ on a finer grid gives a clearly smaller κ/λ
        for other in lam_min * np.linspace(0.05, 0.95, 19):
            k_other = (norms * np.exp(other * t)).max()
            assert kappa / lam <= k_other / other * 1.05


def test_paper_graph_values_match_notes():
    kappa, lam = decay.decay_bounds(PAPER, 6.0)
    assert np.all((kappa >= 1.0) & (kappa <= 1.3))  # docs/notes.md, 6: κ ≈ 1.0-1.2
    assert np.all((lam >= 0.5) & (lam <= 1.6))  # docs/notes.md, 6: λ ≈ 0.6-1.5


def test_not_strongly_connected_gives_infinite_thresholds():
    ring_without_1 = Graph(4, ((0, 1), (1, 2), (2, 3), (3, 0))).without(0)
    assert decay.decay_bound(decay.observer_matrix(ring_without_1, 6.0, 1)) == (np.inf, 0.0)
    th = paper.Thresholds.for_graph(ring_without_1, 6.0, 0.001, 0.005, np.ones(3))
    mu = th.mu(10.0)
    assert not np.isnan(mu).any()
    assert np.isinf(mu[:, 1]).all() and np.isinf(mu[:, 2]).all()


def test_threshold_formula_eq40():
    th = paper.Thresholds.for_graph(PAPER, 6.0, 0.001, 0.005, np.full(4, 0.8))
    d = PAPER.in_degree()
    mu0 = th.mu(0.0).copy()
    for i in range(4):
        for k in range(4):
            coef = np.sqrt(2) * d[i] + (i == k)
            assert mu0[i, k] == pytest.approx(coef * 0.8 * th.kappa[k] + 0.001 * (i == k))
    steady = th.kappa * (6.0 * 0.001 + 2.0 * 0.005) / th.lam
    mu_inf = th.mu(1e4)
    assert mu_inf[0, 2] == pytest.approx(np.sqrt(2) * 1 * steady[2])
    # restarted thresholds count time from t0
    late = paper.Thresholds.for_graph(PAPER, 6.0, 0.001, 0.005, np.full(4, 0.8), t0=30.0)
    assert np.allclose(late.mu(30.0), mu0)


def test_decision_window_and_release():
    dec = decision.Decision.standalone(2, window=0.2, dt=0.01)
    mu = np.ones((2, 2))
    high = np.array([[0.0, 2.0], [0.0, 0.0]])
    raised_at = []
    for k in range(60):
        r = high if 10 <= k < 25 else np.zeros((2, 2))  # 0.15 s above: too short
        if dec.update(r, mu).any():
            raised_at.append(k)
    assert raised_at == [] and not dec.flag.any()
    for k in range(40):
        if dec.update(high, mu)[0, 1]:
            raised_at.append(k)
    assert raised_at == [19]  # the 20th sample above: 0.2 s
    for _ in range(19):
        dec.update(np.zeros((2, 2)), mu)
    assert dec.flag[0, 1]  # still flagged 0.19 s after the residual dropped
    dec.update(np.zeros((2, 2)), mu)
    assert not dec.flag[0, 1]


def test_team_excludes_a_stopped_robot_and_forms_a_triangle():
    """Ideal integrator plant, no noise: the protocol and the re-planning on their own."""
    team, x = _team(4, dt_d_max=2.0)
    x = _integrate(team, x, 1000)  # 10 s healthy
    events = []

    def stop_robot_1(t, team):
        events.extend(team.events)
        team.events.clear()
        phi = np.zeros((4, 2))
        phi[0] = -team.u_bar[0]  # φ₁ = −ū₁: robot 1 does not move
        return phi

    x = _integrate(team, x, 2500, t0=10.0, fault=stop_robot_1)
    detections = [e for e in events if e["kind"] == "detection"]
    assert detections and all(e["robot"] == 1 for e in detections)  # events count from 1
    first = min(e["t"] for e in detections)
    (excl,) = [e for e in events if e["kind"] == "exclusion"]
    assert excl["robot"] == 1 and excl["t"] == pytest.approx(first + 2.0)  # eq. 43
    assert list(team.members) == [1, 2, 3]
    assert team.observer.y_hat.shape == (3, 3, 2) and team.decision.flag.shape == (3, 3)
    tri = x[1:]
    sides = np.linalg.norm(tri - np.roll(tri, -1, axis=0), axis=1)
    assert np.allclose(sides, 0.5, atol=0.005)


def test_exclusion_cancelled_when_nobody_flags_at_t_r():
    """docs/notes.md, 10: a fault that goes away before t_r must not cost the team a robot."""
    team, x = _team(4, dt_d_max=3.0)
    x = _integrate(team, x, 1000)
    events = []

    def burst(t, team):
        events.extend(team.events)
        team.events.clear()
        phi = np.zeros((4, 2))
        if t < 11.5:  # for 1.5 s robot 3 slips: its actuators ignore the compensation
            phi[2] = [0.6, 0.0] + team.phi_hat[2]
        return phi

    _integrate(team, x, 800, t0=10.0, fault=burst)
    kinds = [e["kind"] for e in events]
    assert {e["robot"] for e in events if e["kind"] == "detection"} == {3}
    assert "exclusion_cancelled" in kinds and "exclusion" not in kinds
    assert list(team.members) == [0, 1, 2, 3]


@pytest.mark.parametrize("name", sorted(SMALL))
def test_batched_kappa_lambda_agree_with_the_per_robot_ones(name):
    g = SMALL[name]
    kappa, lam = decay.decay_bounds(g, 6.0)
    for k in range(g.n):
        k1, l1 = decay.decay_bound(decay.observer_matrix(g, 6.0, k))
        assert lam[k] == pytest.approx(l1)
        assert k1 * (1 - 1e-3) <= kappa[k] <= k1 * 1.002  # both bound the sup, within 0.2 %


@pytest.mark.parametrize("n", [6, 16])
def test_rotation_invariant_graphs_compute_one_robot_and_agree_with_all(n):
    """Rings with chords look the same from every robot: κ_k, λ_k are computed for k = 0
    only, and equal the full batched computation; results are cached per graph but
    handed out as copies."""
    from dftc_mujoco.core.graph import ring_with_chords

    g = ring_with_chords(n, (2,))
    kappa, lam = decay.decay_bounds(g, 3.0)
    full_kappa, full_lam = decay._decay_bounds(g, 3.0)
    np.testing.assert_allclose(kappa, full_kappa, rtol=1e-10)
    np.testing.assert_allclose(lam, full_lam, rtol=1e-10)
    kappa[:] = -1.0  # the cache keeps its own values
    assert (decay.decay_bounds(g, 3.0)[0] > 0).all()


@pytest.mark.parametrize("seed", range(4))
def test_certified_kappa_lambda_bound_the_exponential_and_stay_close_to_the_exact_ones(seed):
    """The fast method (row and column sums of the uniformized B_k^n, no expm, no SVD):
    ‖exp(−M_k t)‖₂ ≤ κ e^{−λt} on a fine grid, 0 < λ ≤ λ_min, and κ/λ within 1.6x of the
    exact method's (√(‖·‖₁‖·‖_∞) ≥ ‖·‖₂ is the price)."""
    from dftc_mujoco.core.graph import random_strongly_connected

    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 12))
    g = random_strongly_connected(n, int(rng.integers(1, 4)), rng)
    ko = (3.0, 6.0)[seed % 2]
    kf, lf = decay._decay_bounds_fast(g, ko)
    ke, le = decay._decay_bounds(g, ko)
    for k in range(n):
        m = decay.observer_matrix(g, ko, k)
        lam_min = np.linalg.eigvals(m).real.min()
        assert 0 < lf[k] <= lam_min
        t = np.linspace(0, 40 / lam_min, 600)
        norms = np.array([np.linalg.norm(expm(-m * tt), 2) for tt in t])
        assert (norms * np.exp(lf[k] * t)).max() <= kf[k]
    ratio = (kf / lf) / (ke / le)
    assert 0.95 < ratio.min() and ratio.max() < 1.6


def test_decay_bounds_keep_the_exact_method_where_it_is_cheap():
    """The paper's graph (and rings up to N ~ 100) keep the exact κ, λ bit for bit; a
    random graph beyond N ~ 32 gets the certified ones, fast."""

    from dftc_mujoco.core.graph import random_strongly_connected

    decay._cached_decay_bounds.cache_clear()
    k4, l4 = decay.decay_bounds(PAPER, 6.0)
    ke, le = decay._decay_bounds(PAPER, 6.0)
    assert np.array_equal(k4, ke) and np.array_equal(l4, le)
    g = random_strongly_connected(40, 3, np.random.default_rng(0))
    kf, lf = decay._decay_bounds_fast(g, 3.0)
    k40, l40 = decay.decay_bounds(g, 3.0)
    assert np.array_equal(k40, kf) and np.array_equal(l40, lf)
    g100 = random_strongly_connected(100, 3, np.random.default_rng(1))
    kf100, lf100 = decay._decay_bounds_fast(g100, 3.0)  # (2.8 s where it was the exact one)
    k100, l100 = decay.decay_bounds(g100, 3.0)  # takes the fast path
    assert np.array_equal(k100, kf100) and np.array_equal(l100, lf100)
    # not strongly connected: the robots that reach everyone only
    ring_without_1 = Graph(4, ((0, 1), (1, 2), (2, 3), (3, 0))).without(0)
    kn, ln = decay._decay_bounds_fast(ring_without_1, 6.0)
    assert np.isfinite(kn[0]) and ln[0] > 0 and np.isinf(kn[1:]).all() and (ln[1:] == 0).all()


@pytest.mark.parametrize("n", [9, 60])
def test_one_columns_sums_are_its_column_in_a_batch_bit_for_bit(n):
    """κ, λ of a ring (one column) run entry by entry; a batch of columns runs row by row.
    The same robot's sums and maxima are the same numbers either way, so a circulant
    graph's κ, λ do not depend on the path."""
    from dftc_mujoco.core.graph import random_strongly_connected
    from dftc_mujoco.onboard.thresholds.kernels import Adjacency, advance_sums, column_of_row

    g = random_strongly_connected(n, 3, np.random.default_rng(n))
    adj = Adjacency.of(g)
    beta = 1.0 / (adj.deg.max() + 1.0)
    steps = 400

    def sums(ks: np.ndarray) -> tuple[np.ndarray, ...]:
        a, u = np.ones((n, len(ks))), np.ones((n, len(ks)))
        a2, u2 = np.empty_like(a), np.empty_like(u)
        amax, umax = np.empty((steps, len(ks))), np.empty((steps, len(ks)))
        args = (adj.src, adj.first, adj.dst, adj.out_first, adj.deg, column_of_row(ks, n))
        advance_sums(a, a2, u, u2, *args, beta, steps, amax, umax)
        return a, u, amax, umax

    batch = sums(np.array([2, 5, 7]))
    for col, k in enumerate((2, 5, 7)):
        one = sums(np.array([k]))
        for whole, alone in zip(batch, one, strict=True):
            assert np.array_equal(whole[:, col], alone[:, 0])
    assert (batch[2][-1] < batch[2][0]).all()  # ‖B_k^n‖_∞ did decay


def test_the_compiled_sweep_of_kappa_lambda_does_not_depend_on_its_blocks():
    """The certified κ, λ run their chunks compiled (``sweep_sums``) into blocks of rows
    handed back to Python: a block of one chunk and one of 64 chunks stop at the same step
    with the same sums, brackets, settled robots and maxima, and the sweep holds no GIL."""
    from dftc_mujoco.core.graph import random_strongly_connected
    from dftc_mujoco.onboard.thresholds.kernels import Adjacency, column_of_row, sweep_sums

    n = 40
    g = random_strongly_connected(n, 3, np.random.default_rng(7))
    adj = Adjacency.of(g)
    beta, ks = 1.0 / (adj.deg.max() + 1.0), np.arange(0, n, 3)
    args = (adj.src, adj.first, adj.dst, adj.out_first, adj.deg, column_of_row(ks, n), beta, 16)

    def sweep(rows: int) -> tuple:
        a, u = np.ones((n, len(ks))), np.ones((n, len(ks)))
        a2, u2 = np.empty_like(a), np.empty_like(u)
        s_a, s_u, settled = np.empty(len(ks)), np.empty(len(ks)), np.zeros(len(ks), bool)
        done, work, maxima = 0, 0.0, []
        while not settled.any():
            amax, umax = np.empty((rows, len(ks))), np.empty((rows, len(ks)))
            done, work, wrote = sweep_sums(
                a, a2, u, u2, *args, 0.02, done, 20_000, work, 4e9, amax, umax, s_a, s_u, settled
            )
            maxima += [amax[:wrote], umax[:wrote]]
        return (
            done,
            a,
            u,
            s_a,
            s_u,
            settled,
            np.concatenate(maxima[::2]),
            np.concatenate(maxima[1::2]),
        )

    small, large = sweep(16), sweep(1024)
    assert small[0] == large[0] > 16  # the same step, after several chunks
    for x, y in zip(small[1:], large[1:], strict=True):
        assert np.array_equal(x, y)
    assert small[5].any() and (small[3][small[5]] < 1).all()  # settled with a certificate
    assert sweep_sums.targetoptions["nogil"]


def test_kappa_lambda_begun_on_a_helper_thread_are_the_same_numbers_taken_once():
    """``prefetch_decay_bounds`` computes κ, λ on a helper thread; ``decay_bounds`` of the
    same graph takes them from it (once) and they equal the ones computed here."""
    from dftc_mujoco.core.graph import ring_with_chords

    g = ring_with_chords(150, (2, 5))  # beyond the exact path: the compiled sweep
    decay._cached_decay_bounds.cache_clear()
    decay.prefetch_decay_bounds(g, 3.0)
    key = decay._key(g, 3.0, 49)
    assert key in decay._PENDING
    kappa, lam = decay.decay_bounds(g, 3.0)
    assert key not in decay._PENDING
    here = decay._cached_decay_bounds.__wrapped__(*key)  # computed in this thread, uncached
    assert np.array_equal(kappa, here[0]) and np.array_equal(lam, here[1])
    assert np.isfinite(kappa).all() and (lam > 0).all()
