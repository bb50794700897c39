"""Teammate avoidance by the supervisor: teammates are obstacles of the null-space
behaviour of eqs. 17-18, so crossing robots keep apart and their residuals stay unaffected."""

from __future__ import annotations

import numpy as np
import pytest

from dftc_mujoco import load_scenario, simulate
from dftc_mujoco.errors import ScenarioError
from dftc_mujoco.onboard.supervisor import grid_work, supervise
from tests.test_premises import shuffled

INF = np.inf  # no range: the drive's limit plays no part


def test_two_robots_heading_at_each_other_are_held_at_the_safe_distance():
    """Eq. 18 with the teammate as obstacle: the radial part of the input is replaced by
    θ(d − ‖xᵢ − x_j‖), the tangential part is kept."""
    x = np.array([[0.0, 0.0], [0.25, 0.0]])
    u_g = np.array([[1.0, 0.2], [-1.0, 0.0]])
    active = np.full(2, -1, dtype=np.intp)
    u, du = np.empty((2, 2)), np.empty((2, 2))
    theta, safe = 3.0, 0.22
    none, nothing, work = np.zeros((0, 2)), np.zeros(0), grid_work(2)
    supervise(x, u_g, none, nothing, nothing, theta, 0.01, active, u, du, x, safe, 0.32, work, INF)
    assert list(active) == [1, 0]  # each avoids the other (obstacle index O + j, O = 0)
    away = theta * (safe - 0.25)  # radial speed allowed: −0.09 m/s towards the teammate
    assert u[0] == pytest.approx([-away, 0.2])
    assert u[1] == pytest.approx([away, 0.0])
    np.testing.assert_allclose(du, u - u_g)
    supervise(x, u_g, none, nothing, nothing, theta, 0.01, active, u, du, x, 0.0, 0.0, work, INF)
    assert list(active) == [-1, -1] and np.array_equal(u, u_g)  # off: the paper's behaviour


def test_robots_crossing_the_circle_to_their_slots_do_not_collide_or_flag():
    """12 robots start on their formation circle in a shuffled order, with contacts on: their
    paths cross. Without teammate avoidance they collide (before the fault estimator held
    its state on contact, healthy robots were flagged too); with it (the default) no contact
    happens and nobody is flagged or excluded."""
    over = shuffled(12, 30.0, **{"physics.robot_contacts": True})
    off = simulate(load_scenario("paper_case", {**over, "supervisor.avoid_teammates": False}))
    contacts = [e for e in off.events.of_kind("premise_violated") if e["premise"] == "contact"]
    assert contacts
    on = simulate(load_scenario("paper_case", over))
    contacts = [e for e in on.events.of_kind("premise_violated") if e["premise"] == "contact"]
    assert contacts == []
    assert on.summary["healthy_flags"] == 0 and on.events.of_kind("exclusion") == []
    avoided = {e["obstacle"] for e in on.events.of_kind("reactive_on")}
    assert any(a.startswith("robot") for a in avoided)
    assert on.summary["errors"]["final_formation"] < 0.01


def test_a_bad_teammate_distance_is_one_line_naming_the_key():
    with pytest.raises(ScenarioError, match=r"supervisor\.teammate_distance") as err:
        load_scenario("paper_case", {"supervisor.teammate_distance": "far"})
    assert 'expected a distance in m or "auto"' in str(err.value)


@pytest.mark.parametrize("model", ["disk", "diffdrive"])
def test_no_contact_between_teammates_in_paper_case(model):
    """paper_case (robot contacts on) with teammate avoidance: no hull ever touches another
    robot or a cylinder, before or after robot 1 is excluded; its outcome is the paper's."""
    r = simulate(load_scenario("paper_case", {"team.robot_model": model}))
    out = r.summary
    assert out["premises"]["contact"]["held"], out["premises"]["contact"]
    assert not [e for e in r.events.of_kind("premise_violated") if e["premise"] == "contact"]
    assert [e["robot"] for e in out["exclusions"]] == [1]
    assert not [e for e in out["events"] if e["kind"] == "exclusion_postponed"]


def test_a_robot_closing_in_at_the_input_range_switches_without_a_jump():
    """Eq. 18 equals u_g,i at the switch only if the teammate is sensed from d + ‖u‖/θ on
    (docs/notes.md, 12). A disk closing in on a standing teammate at its whole input range: with the
    activation distance the run derives (``assembly.seamless_margin``) its command changes per
    period by no more than eq. 18's own deceleration θ‖u‖Δt (2.4 cm/s); with the former
    fixed 0.1 m margin it jumped by about 0.5 m/s."""
    from dftc_mujoco.closed_loop import assembly
    from dftc_mujoco.sim import robots

    s = load_scenario("paper_case")
    disk = robots.load(robots.resolve("disk", "test"))
    cfg = assembly.team_config(s, disk, 0.8)
    speed = np.sqrt(2.0) * cfg.input_limit  # the fastest a robot can close in
    none = np.zeros((0, 2))

    def largest_jump(activation: float) -> float:
        active = np.full(2, -1, dtype=np.intp)
        u, du = np.empty((2, 2)), np.empty((2, 2))
        x = np.array([[-1.5, 0.0], [0.0, 0.0]])
        u_g = np.array([[speed, 0.0], [0.0, 0.0]])
        previous, jump = speed, 0.0
        for _ in range(400):
            supervise(
                x,
                u_g,
                none,
                np.zeros(0),
                np.zeros(0),
                cfg.theta,
                0.01,
                active,
                u,
                du,
                x,
                cfg.teammate_safe,
                activation,
                grid_work(2),
                INF,
            )
            jump = max(jump, abs(u[0, 0] - previous))
            previous = u[0, 0]
            x[0] += u[0] * cfg.dt
        assert np.linalg.norm(x[1] - x[0]) > cfg.teammate_safe - 1e-3  # held apart either way
        return jump

    assert cfg.teammate_activation - cfg.teammate_safe == pytest.approx(speed / cfg.theta)
    assert cfg.excluded_activation - cfg.excluded_safe >= speed / cfg.theta - 1e-12
    smooth = cfg.theta * speed * cfg.dt  # eq. 18's own deceleration per period
    assert largest_jump(cfg.teammate_activation) < smooth + 0.005
    assert largest_jump(cfg.teammate_safe + assembly.TEAMMATE_MARGIN) > 0.3


def test_a_queue_of_robots_does_not_ring_into_a_healthy_exclusion():
    """Run 1735 of the no-false-exclusion battery (16 disks, drive rule, 0.6 m/s, start on a
    6 m circle, robot 8 stops at 16.9 s). Robots re-forming behind each other sensed their
    teammates only 0.1 m beyond the safe distance: each switch was a 0.5 m/s jump, the queue
    ran a 10 Hz limit cycle, robot 1's compensation rang into saturation and robot 1, healthy,
    was excluded at 31.06 s. With the activation distance from the input range only robot 8
    is excluded."""
    from pathlib import Path

    from dftc_mujoco import scenario
    from dftc_mujoco.campaign import spec as spec_mod

    sp = spec_mod.load(Path(__file__).parent / "data" / "battery_v2.toml")
    d = spec_mod.scenario_dict(sp, spec_mod.draw(sp, 1735))
    assert d["team"]["robots"] == 16 and d["faults"][0]["robot"] == 8
    d["duration"] = 32.0
    summary = simulate(scenario.from_dict(d)).summary
    assert [e["robot"] for e in summary["exclusions"]] == [8]


def _nearest_by_scan(x, u_g, mates, theta, release, active, safe, act):
    """The teammate each robot avoids, by a scan of every pair in index order (what the
    supervisor did for every team size before it used a grid)."""
    m, out = len(x), np.full(len(x), -1)
    for i in range(m):
        best, best_m = -1, 1e300
        for j in range(m):
            e = x[i] - mates[j]
            d2 = e @ e
            if j == i or d2 >= act * act:
                continue
            dist = np.sqrt(d2)
            h = e / max(dist, 1e-9)
            radial, barrier = h @ u_g[i], theta * (safe - dist)
            rel = release if active[i] == j else 0.0
            if radial < barrier + rel and dist - safe < best_m:
                best, best_m = j, dist - safe
        out[i] = best
    return out


@pytest.mark.parametrize("seed", range(6))
def test_the_grid_of_a_large_team_finds_the_teammates_a_scan_finds(seed):
    """From GRID_FROM robots on each robot looks for teammates in reach through a grid of
    cells: the same choice as a scan of every pair, ties (robots on a lattice, at equal
    distances) going to the lower index."""
    from dftc_mujoco.onboard.supervisor import GRID_FROM

    rng = np.random.default_rng(seed)
    m = GRID_FROM + 40 * seed
    spread = (0.15, 0.3, 0.5)[seed % 3] * np.sqrt(m)  # a dense, a sparse and a sparser team
    x = rng.uniform(-spread, spread, (m, 2))
    if seed % 2:
        x = np.round(x * 4) / 4  # a lattice of 0.25 m: exact ties
    mates = x.copy()
    u_g = rng.normal(0, 0.3, (m, 2))
    active = rng.integers(-1, m, m).astype(np.intp)
    expect = _nearest_by_scan(x, u_g, mates, 3.0, 0.01, active, 0.22, 0.6)
    u, du = np.empty((m, 2)), np.empty((m, 2))
    none = np.zeros((0, 2))
    # the team's own integers, the same left dirty by another period, and none (it allocates)
    dirty = np.full(len(grid_work(m)), 7, np.int64)
    for work in (grid_work(m), dirty, dirty, np.zeros(0, np.int64)):
        chosen = active.copy()
        supervise(
            x, u_g, none, np.zeros(0), np.zeros(0), 3.0, 0.01, chosen, u, du, mates, 0.22, 0.6,
            work, INF,
        )  # fmt: skip
        assert np.array_equal(chosen, expect)
    assert (expect >= 0).sum() > m // 10  # the case is not empty


def test_the_grid_of_a_large_team_allocates_nothing_in_the_teams_own_integers():
    """The supervisor sorts teammates into a grid every period: in the integers the team
    keeps (``grid_work``) it allocates nothing more than with the grid off (numba's own
    count of its allocations); the scratch arrays it allocated before, four a period, were
    the compiled period's only ones."""
    from numba.core.runtime import _nrt_python, rtsys

    from dftc_mujoco.onboard.supervisor import GRID_FROM

    m = 2 * GRID_FROM
    rng = np.random.default_rng(3)
    x = rng.uniform(-4.0, 4.0, (m, 2))
    u_g = rng.normal(0, 0.3, (m, 2))
    active = np.full(m, -1, dtype=np.intp)
    u, du, none, work = np.empty((m, 2)), np.empty((m, 2)), np.zeros((0, 2)), grid_work(m)

    def allocations(mate_safe: float, work: np.ndarray) -> int:
        args = (x, u_g, none, np.zeros(0), np.zeros(0), 3.0, 0.01, active, u, du, x)
        supervise(*args, mate_safe, 0.6, work, INF)  # compiled and typed before counting
        before = rtsys.get_allocation_stats().alloc
        supervise(*args, mate_safe, 0.6, work, INF)
        return rtsys.get_allocation_stats().alloc - before

    was = _nrt_python.memsys_stats_enabled()
    _nrt_python.memsys_enable_stats()
    try:
        off, on, own = allocations(0.0, work), allocations(0.22, work), allocations(0.22, work[:0])
    finally:
        if not was:
            _nrt_python.memsys_disable_stats()
    assert (active >= 0).any()  # teammates were in reach: the grid was read
    assert on == off and own == off + 1  # without the team's integers: one array of its own


def _among_teammates(x, u_g, theta, safe, limit):
    """One call of the supervisor for robots at ``x`` (M, 2) with global inputs ``u_g``,
    teammates only (activation 0.5 m, safe distance ``safe``), within the range ±``limit``:
    (u, Δu, active)."""
    m = len(x)
    active = np.full(m, -1, dtype=np.intp)
    u, du = np.empty((m, 2)), np.empty((m, 2))
    none, nothing = np.zeros((0, 2)), np.zeros(0)
    supervise(
        x, u_g, none, nothing, nothing, theta, 0.01, active, u, du, x, safe, 0.5, grid_work(m),
        limit,
    )  # fmt: skip
    return u, du, active


def test_a_robot_between_two_teammates_escapes_sideways_within_its_range():
    """Robot 1 between robots 2 (above) and 3 (below), both nearer than the safe distance:
    its global input heads away from 2 and into 3, so only 3's task is due, and eq. 18 for
    3 alone would push it into 2. It takes the velocity nearest its input that meets both,
    sideways, and within the drive's range."""
    x = np.array([[0.0, 0.0], [0.06, 0.19], [0.05, -0.19]])
    u_g = np.array([[0.3, -0.5], [0.0, 0.0], [0.0, 0.0]])
    theta, safe, limit = 3.0, 0.24, 0.6
    u, du, _ = _among_teammates(x, u_g, theta, safe, limit)
    for j in (1, 2):  # eq. 17's task for each teammate: r̂ᵀu ≥ θ(d − ‖x₁ − x_j‖)
        gap = x[0] - x[j]
        dist = np.hypot(*gap)
        assert gap @ u[0] / dist >= theta * (safe - dist) - 1e-9, j
    assert np.abs(u[0]).max() <= limit and u[0, 0] < 0  # sideways, away from both
    np.testing.assert_allclose(du, u - u_g, atol=1e-15)


def test_an_avoiding_robot_keeps_to_its_range_and_judges_the_input_it_can_apply():
    """A global input far beyond the range, which clipped axis by axis (as the drive
    applies it) heads into a teammate nearer than the safe distance, and scaled into the
    range does not move away from it as fast as eq. 17 asks, though as given it would: the
    avoidance judges the input as the drive can apply it, and its answer is within range."""
    x = np.array([[0.0, 0.0], [0.16, -0.16]])
    u_g = np.array([[3.0, 3.3], [0.0, 0.0]])
    theta, safe, limit = 3.0, 0.24, 0.5
    u, _, active = _among_teammates(x, u_g, theta, safe, limit)
    gap = x[0] - x[1]
    dist = np.hypot(*gap)
    assert active[0] == 1 and np.abs(u[0]).max() <= limit + 1e-12
    assert gap @ u[0] / dist >= theta * (safe - dist) - 1e-9
    assert u[0] == pytest.approx([0.5 - np.sqrt(2) * theta * (safe - dist), 0.5])


def test_a_crowd_started_at_random_crosses_to_its_slots_without_a_contact():
    """40 hexbots started at random within 4 m cross the crowd to their slots at the edge
    of their range: no two hulls touch, and no premise is violated (they touched, up to
    7.7 mm deep, when a robot judged its unclipped input, clipped its avoidance axis by
    axis and heeded only the teammates its input approached)."""
    r = simulate(
        load_scenario(
            "paper_case",
            {
                "duration": 20.0,
                "seed": 434340769,
                "obstacles": [],
                "faults": [],
                "team.robots": 40,
                "team.robot_model": "hexbot",
                "team.initial_positions": {"layout": "random", "spread": 4.0, "spacing": 0.6},
                "team.graph": {"family": "random", "in_degree": 3},
                "mission.centroid.speed": 0.5,
                "mission.centroid.waypoints": [[0.0, 0.0], [6.6, 0.0], [10.2, 4.8], [18.0, 4.8]],
                "fdir.dt_d_max": "auto",
                "fdir.initial_error_bound": "auto",
            },
        )
    )
    premises = r.summary["premises"]
    assert premises["contact"]["held"], premises["contact"]
    assert all(p["held"] for p in premises.values()), premises
