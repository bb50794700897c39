"""The input a robot applies (``onboard/applied.py``): its drive's range and, for a slow
drive, its first-order lag. The lag model is checked against the exact
response, the calibration against a slow base of this project's own, and the closed loop on
MuJoCo physics: a slow robot's stop is isolated with no healthy robot flagged."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from dftc_mujoco import calibrate as cal_mod
from dftc_mujoco import load_scenario, simulate
from dftc_mujoco.closed_loop import assembly, loop
from dftc_mujoco.errors import ScenarioError
from dftc_mujoco.onboard.applied import lag_arrays, lag_coefficients, lag_input
from dftc_mujoco.onboard.execution import team as team_mod
from dftc_mujoco.onboard.thresholds import estimator_gain
from dftc_mujoco.sim import robots

SLOWBASE = Path(__file__).parent / "data" / "robots" / "slowbase.robot.toml"
H = 0.01
FREE = np.zeros(1, bool)  # the estimator's contact hold, off


def test_the_lag_model_integrates_what_a_first_order_lag_delivers():
    """h Σ of the modelled velocities equals the position of ẋ = v, τv̇ = u − v (commands held
    over each period), integrated by an ODE solver, and v̂ its velocity."""
    tau, periods = 0.7, 300
    rng = np.random.default_rng(3)
    commands = rng.uniform(-1, 1, (periods, 1, 2))
    a, b = lag_arrays(tau, 1, H)  # (1,): one robot
    assert (a[0], b[0]) == lag_coefficients(tau, H)
    v_hat, command = np.zeros((1, 2)), np.zeros((1, 2))
    position = np.zeros(2)
    state = np.zeros(4)  # exact: [x, v]
    for k in range(periods):
        u = commands[k].copy()
        lag_input(u, v_hat, command, a, b)
        assert np.array_equal(command, commands[k])  # the drive is told the command
        position += H * u[0]

        def f(_t, s, c=commands[k, 0]):
            return np.r_[s[2:], (c - s[2:]) / tau]

        state = solve_ivp(f, (0, H), state, rtol=1e-11, atol=1e-13).y[:, -1]
        assert np.allclose(v_hat[0], state[2:], atol=1e-8)
    assert np.allclose(position, state[:2], atol=1e-8)
    assert lag_coefficients(0.0, H) == (0.0, 0.0)  # no lag: the command is the velocity
    # beside a lagging robot, one without a lag moves at its command (a = 1, b = 0)
    a, b = lag_arrays(np.array([tau, 0.0]), 2, H)
    u, v_hat, command = np.array([[1.0, -1.0], [0.5, 0.25]]), np.zeros((2, 2)), np.zeros((2, 2))
    lag_input(u, v_hat, command, a, b)
    assert np.array_equal(u[1], [0.5, 0.25]) and np.array_equal(v_hat[1], [0.5, 0.25])
    assert 0.0 < u[0, 0] < 1.0  # the lagging one is still speeding up


def test_calibrate_fits_the_lag_of_a_slow_base_and_none_on_the_disk():
    """The test base (m / kv = 2.5 s) is fitted to 1 %, and against that model its mismatch
    falls below 1 % of the mismatch against the command; the disk (10 ms) keeps ẋ = u."""
    slow = cal_mod.measure(str(SLOWBASE))
    assert slow.lag == pytest.approx(2.5, rel=0.01)
    assert slow.rms_lag < 0.01 * slow.rms_command
    assert slow.smooth_max < 0.005  # ξ̄ against the model: the paper's 5 mm/s
    disk = cal_mod.measure("disk")
    assert disk.lag == 0.0 and disk.lag_fit < cal_mod.LAG_MIN


def estimator_loop(lag: float, eta: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """φ̂ (T,) along x of the paper's fault estimator (the compiled one the team runs)
    closed through a drive with a first-order lag ``lag`` that the robot models: the plant
    moves by the lag's response to −φ̂ plus ξ, and the robot measures x + η (T,) each."""
    from dftc_mujoco.onboard.fault_estimator import estimate_faults

    K, g_inv = 3.0 * np.eye(2), np.eye(2) / 0.01
    a, b = lag_coefficients(lag, H)
    x, w = 0.0, 0.0  # position and the lag's response to −φ̂
    z, int_e = np.zeros((1, 2)), np.zeros((1, 2))
    phi, applied, u_bar = np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 2))
    out = np.empty(len(eta))
    for k in range(len(eta)):
        x_m = np.array([[x + eta[k], 0.0]])
        estimate_faults(
            x_m, np.zeros((1, 2)), z, int_e, phi, applied, K, g_inv, H, np.inf, 1.0, FREE, u_bar
        )
        out[k] = phi[0, 0]
        c = -phi[0, 0]
        mean = c + b * (w - c) if a > 0 else c  # what the lagged drive delivers
        w = c + (1 - a) * (w - c) if a > 0 else c
        x += H * (mean + xi[k])
    return out


@pytest.mark.parametrize("lag", [0.0, 0.05, 0.5, 2.5])
def test_phi_bar_with_the_lag_is_the_exact_worst_case_of_the_estimator_loop(lag):
    """Φ̄ from ``estimator_gain(lag=…)`` against the loop itself: the noise sequence that
    follows the signs of the loop's own impulse responses (measured by running it) drives
    ‖φ̂‖ to Φ̄ within 0.5 %, and 20 random sequences at the bounds stay below it."""
    eta_bar, xi_bar = 0.001, 0.005
    T = 4000 + int(4000 * lag)  # past the slowest tail of the impulse responses
    bound = estimator_gain(3 * np.eye(2), 0.01 * np.eye(2), H, eta_bar, xi_bar, lag=lag)
    unit = np.zeros(T)
    unit[0] = 1.0
    h_eta = estimator_loop(lag, unit, np.zeros(T))
    h_xi = estimator_loop(lag, np.zeros(T), unit)
    # φ̂(T−1) = Σ_k h(T−1−k) input(k): each input at its bound with the sign of its weight
    eta = eta_bar * np.sign(h_eta[::-1])
    xi = xi_bar * np.sign(h_xi[::-1])
    worst = abs(estimator_loop(lag, eta, xi)[-1])
    assert bound * 0.995 <= worst <= bound * (1 + 1e-9)
    rng = np.random.default_rng(1)
    for _ in range(20):
        seq = estimator_loop(lag, eta_bar * rng.choice([-1, 1], T), xi_bar * rng.choice([-1, 1], T))
        assert np.abs(seq).max() <= bound * (1 + 1e-9)


def test_phi_bar_without_a_lag_is_the_ideal_plants():
    assert estimator_gain(3 * np.eye(2), 0.01 * np.eye(2), H, 0.001, 0.005) == pytest.approx(
        0.205, abs=1e-3
    )
    assert estimator_gain(3 * np.eye(2), 0.01 * np.eye(2), H, 0.001, 0.005, lag=2.5) > 1.0


@pytest.mark.parametrize("steps", [1, 63, 64, 65, 831, 832, 100000])
@pytest.mark.parametrize("lag", [0.0, 0.2])
def test_phi_bar_is_the_sum_of_the_impulse_responses_norms_step_by_step(steps, lag):
    """Φ̄'s batched sums are the step-by-step sum of ‖C Ad^t B‖₂ up to the first state below
    1e-14 (or ``steps``), bit for bit, also where that step falls at a block's edge."""
    from dftc_mujoco.onboard.applied import lag_coefficients

    K, G, eta_bar, xi_bar = 3 * np.eye(2), 0.01 * np.eye(2), 0.001, 0.005
    gi, eye, zero = np.linalg.inv(G), np.eye(2), np.zeros((2, 2))
    a, b = lag_coefficients(lag, H)
    C, D = np.hstack([gi, gi @ K]), gi
    Ad = np.block([[eye - H * (1 - b) * gi - H * K, -H * (1 - b) * gi @ K], [H * eye, eye]])
    B_eta, B_xi = np.vstack([-H * (1 - b) * gi - H * K, H * eye]), np.vstack([H * eye, zero])
    if a > 0.0:
        Ad = np.block([[Ad, np.vstack([-H * b * eye, zero])], [a * gi, a * gi @ K, (1 - a) * eye]])
        C, B_eta, B_xi = np.hstack([C, zero]), np.vstack([B_eta, a * gi]), np.vstack([B_xi, zero])
    total_eta, total_xi = float(np.linalg.norm(D, 2)), 0.0
    xe, xx, taken = B_eta, B_xi, 0
    for _ in range(steps):
        total_eta += float(np.linalg.norm(C @ xe, 2))
        total_xi += float(np.linalg.norm(C @ xx, 2))
        taken += 1
        if max(np.abs(xe).max(), np.abs(xx).max()) < 1e-14:
            break
        xe, xx = Ad @ xe, Ad @ xx
    if lag == 0.0:  # the paper's gains: the state is below 1e-14 at its 831st step
        assert taken == min(steps, 831)
    expected = float(total_eta * eta_bar + total_xi * xi_bar)
    assert estimator_gain(K, G, H, eta_bar, xi_bar, steps=steps, lag=lag) == expected


def slow_case(**extra) -> dict:
    return {"team.robot_model": str(SLOWBASE), "onboard.thresholds": "l1", **extra}


def test_a_slow_robot_isolates_a_stop_and_flags_no_healthy_robot():
    """paper_case on the 2.5 s base (calibrated, its lag modelled), l1: robot 1's stop is
    flagged and robot 1 alone is excluded; after the re-plan the re-formed triangle moves at
    the robot's real lag and nobody else is flagged; every premise holds. Without the drive
    model (``fdir.drive_lag = 0``) the same run flags healthy robots (labelled)."""
    r = simulate(load_scenario("paper_case", slow_case()))
    assert r.ok
    gone = [e["robot"] for e in r.events.of_kind("exclusion")]
    assert gone == [1]
    assert r.summary["healthy_flags"] == 0
    assert all(p["held"] for p in r.summary["premises"].values())
    bare = simulate(load_scenario("paper_case", slow_case(**{"fdir.drive_lag": 0.0})))
    assert bare.summary["healthy_flags"] > 0
    assert bare.summary["healthy_flags_premises_held"] == 0  # each one is labelled
    # the lagging actuator is the violated premise the labels name
    assert not bare.summary["premises"]["mismatch"]["held"]
    onset = {f["robot"]: f["t"] for f in bare.summary["faults"]}  # robot 2's bias, robot 1's stop
    healthy = [d for d in bare.summary["detections"] if d["t"] < onset.get(d["robot"], 1e9)]
    assert healthy and all("mismatch" in d["premises"] for d in healthy)


@pytest.fixture(params=["compiled", "general"])
def path(request, monkeypatch):
    monkeypatch.setenv("DFTC_PERIOD", request.param)
    return request.param


def test_the_lag_model_runs_the_same_on_both_paths(path):
    """The compiled period and the blocks' Python methods agree with a drive lag."""
    r = simulate(load_scenario("paper_case", slow_case(duration=20.0)))
    assert r.summary["onboard"]["path"] == path
    want = np.load(Path(__file__).parent / "data" / "slowbase_20s.npz")
    for name in ("x", "u", "v_cmd", "phi_hat"):
        assert np.allclose(r.log[name][::20], want[name], atol=1e-9), name


@pytest.mark.parametrize(
    ("value", "message"),
    [('"fast"', 'expected a time constant in s or "robot"'), ("-1.0", "drive_lag")],
)
def test_a_bad_drive_lag_is_one_line_naming_the_key(value, message):
    import tomllib

    with pytest.raises(ScenarioError, match=message) as err:
        load_scenario("paper_case", {"fdir.drive_lag": tomllib.loads(f"v = {value}")["v"]})
    assert "fdir.drive_lag" in str(err.value)


def test_the_nominal_input_changes_at_most_a_max_h_per_period():
    """``limit_input`` with an acceleration: the change since the last command is held to
    a_max h in norm (direction kept), then each axis to the range; Δu follows."""
    from dftc_mujoco.onboard.applied import limit_input

    u = np.array([[1.0, 0.0], [0.05, 0.0], [-3.0, 4.0]])
    u_g = u.copy()
    du = np.zeros_like(u)
    previous = np.array([[0.0, 0.0], [0.0, 0.0], [9.0, 9.0], [0.0, 0.0]])
    rows = np.array([0, 1, 3])
    calm = np.full(3, -1, np.intp)  # no robot avoids anything
    hit = limit_input(u, u_g, du, 0.5, previous, rows, 0.1, calm, 0.1)  # a_max 10 m/s², h 0.01 s
    assert hit == 2
    assert np.allclose(u[0], [0.1, 0.0]) and np.allclose(u[1], [0.05, 0.0])  # within the step
    assert np.allclose(u[2], [-0.06, 0.08])  # 0.1 along (-3, 4)/5, from robot 3's command
    assert np.allclose(du, u - u_g)
    none = np.array([[2.0, 0.0]])
    limit_input(
        none, none.copy(), np.zeros((1, 2)), 0.5, np.zeros((1, 2)), rows[:1], np.inf, calm[:1],
        np.inf,
    )  # fmt: skip
    assert np.allclose(none, [[0.5, 0.0]])  # no acceleration limit: the range only


def test_calibrate_finds_the_acceleration_a_drive_follows():
    """Jumping commands run the diffdrive's compensation loop away (healthy ‖φ̂‖ p99 ≫ Φ̄);
    held to 2 m/s² they do not. The disk's jump transients reach 2.2 Φ̄ unlimited, 1.6 Φ̄
    at 16 m/s². The robot files carry what calibrate found."""
    from dftc_mujoco import calibrate

    disk = calibrate.acceleration("disk", 0.01)
    assert [a for a, _ in disk] == [np.inf, 16.0] and disk[0][1].runs_away
    assert not disk[-1][1].runs_away
    diff = calibrate.acceleration("diffdrive", 0.02)
    assert diff[0][1].runs_away and diff[0][1].phi_p99 > 10 * diff[0][1].ideal
    assert diff[-1][0] == 2.0 and not diff[-1][1].runs_away
    assert robots.get("diffdrive").accel == 2.0 and robots.get("disk").accel == 16.0


def test_an_acceleration_limit_keeps_a_healthy_diffdrive_in_the_team():
    """Run 69 of the no-false-exclusion battery: 4 diffdrives from a 6 m circle at 0.3 m/s,
    robot 3 stops at 39.7 s. Unlimited (``drive_accel = 0``) robot 2's reversal at 11.2 s
    ran its compensation away (ū 4.8 m/s) and the healthy robot 2 was excluded; at the
    calibrated 2 m/s² only the stopped robot 3 is. Since teammates are sensed from
    safe + ‖u‖/θ on (switches without jumps) the unlimited run keeps robot 2 too, and since
    an avoiding robot keeps to its range its compensation swings less, but still more than
    twice as far (φ̂ 0.33 m/s against 0.13; ten times, 1.7 against 0.16, before)."""
    from dftc_mujoco import scenario
    from dftc_mujoco.campaign import spec as spec_mod

    sp = spec_mod.load(Path(__file__).parent / "data" / "battery_v1.toml")
    d = spec_mod.scenario_dict(sp, spec_mod.draw(sp, 69))
    assert d["team"]["robot_model"] == "diffdrive" and d["faults"][0]["robot"] == 3
    out = {}
    for accel in ("robot", 0.0):
        d.setdefault("fdir", {})["drive_accel"] = accel
        out[accel] = loop.simulate(scenario.from_dict(d))
    for r in out.values():
        assert [e["robot"] for e in r.summary["exclusions"]] == [3]
    swing = {k: np.nanmax(np.abs(r.log["phi_hat"][:, 1])) for k, r in out.items()}
    assert swing[0.0] > 2 * swing["robot"]


def test_a_jammed_slow_robot_reads_its_drive_state_from_its_own_motion():
    """A jam stops a slow robot while its drive model v̂ runs on. Four robots whose drive
    lags by 2.5 s (an exact first-order lag here, so the model is right whenever nothing
    touches them) go to their slots; robot 1 is jammed from 1 s to 3 s (held still, its
    bumper on). While its bumper is on (and 0.5 s after) it re-reads v̂ from its own measured
    velocity, so when it moves again its fault estimate stays below 0.15 m/s (0.07 measured,
    the compensation loop's own ringing). With the model run on through the jam φ̂ swung by
    0.8 m/s here, and by 4 m/s within 0.3 s of the hold's end in battery run 1078, where the
    healthy robot was excluded."""
    s = load_scenario("paper_case", slow_case(faults=[], obstacles=[]))
    cfg = assembly.team_config(s, robots.load(SLOWBASE), 0.8)
    assert cfg.lag > 2.0
    x = np.array(s.team.initial_positions, float)
    team = team_mod.Team(cfg, x.copy(), np.zeros(2))
    a, _ = lag_coefficients(cfg.lag, cfg.dt)
    v = np.zeros_like(x)
    after = 0.0
    for k in range(800):
        t = k * cfg.dt
        jam = 1.0 <= t < 3.0
        team.step(t, x.copy(), np.zeros(2), np.zeros(2), None, np.array([jam, 0, 0, 0], bool))
        v += a * (team.u_bar - v)  # the drive: a first-order lag of what it is told
        if jam:
            v[0] = 0.0
        x += cfg.dt * v
        if t >= 3.0:
            after = max(after, float(np.abs(team.estimator.phi_hat[0]).max()))
    assert after < 0.15
