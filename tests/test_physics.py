"""Physics in the loop: real MuJoCo stepping, physical outcomes asserted."""

import json
import signal
import subprocess
import sys
import time
from types import SimpleNamespace

import numpy as np
import pytest

from dftc_mujoco import run, scenario
from dftc_mujoco.closed_loop import loop
from dftc_mujoco.core.record import LOG_FIELDS, STATIC_FIELDS
from dftc_mujoco.sim import faults as sim_faults
from dftc_mujoco.sim import robots, scene
from dftc_mujoco.sim.plant import NoiseStream, Plant
from tests.conftest import make, ring_team, scenario_dict


def _fault_free(**changes):
    d = scenario_dict()
    d["faults"] = []
    d.update(changes)
    return make(d)


@pytest.mark.parametrize("at_bound", [False, True])
def test_the_noise_stream_is_the_disk_formula_whatever_its_chunk(at_bound):
    """η and ξ of each period, drawn ahead in chunks and computed in compiled loops, are the
    whole-array numpy formula of the disk, bit for bit, and the same for any chunk size."""
    n, periods, eta_bar, xi_bar, alpha = 37, 40, 0.001, 0.02, 0.9

    def plant(seed):  # what NoiseStream reads of a plant
        noise = scenario.Noise(eta_bar=eta_bar, xi_bar=xi_bar, at_bound=at_bound)
        state = np.full((n, 2), 0.004)
        return SimpleNamespace(
            rng=np.random.default_rng(seed), n=n, noise=noise, at_bound=at_bound,
            xi_bar=xi_bar, _alpha=alpha, _xi_state=state,
        )  # fmt: skip

    def disk(r, radius, rim):  # the formula, on whole arrays
        ang, mag = 2.0 * np.pi * r[0], radius if rim else radius * np.sqrt(r[1])
        return np.stack([mag * np.cos(ang), mag * np.sin(ang)], axis=-1)

    rng, state = np.random.default_rng(5), np.full((n, 2), 0.004)
    want = []
    for _ in range(periods):
        r = rng.random((2, 2, n))
        state = alpha * state + (1.0 - alpha) * disk(r[1], xi_bar, False)
        norm = np.maximum(np.sqrt(state[:, 0] ** 2 + state[:, 1] ** 2), 1e-12)[:, None]
        want.append((disk(r[0], eta_bar, at_bound), xi_bar * state / norm if at_bound else state))
    for chunk in (1, 7, 512):
        stream = NoiseStream(plant(5), chunk)  # type: ignore[arg-type]
        for k, (eta, xi) in enumerate(want):
            got = stream.next()
            same = np.array_equal(got[0], eta) and np.array_equal(got[1], xi)
            assert same, (chunk, k)


def test_fault_free_run_converges_without_obstacles():
    d = scenario_dict()
    d["faults"], d["obstacles"], d["duration"] = [], [], 20.0
    r = loop.simulate(make(d))
    t, err = r.log["t"], r.log["sigma_err"]
    after = t >= 5.0
    assert err[after].max() < 0.01  # centroid and formation within 1 cm after the transient
    est = np.abs(r.log["x_hat"] - r.log["x"][:, None]).max(axis=(1, 2, 3))
    assert est[after].max() < 0.01  # every robot's estimate of every robot
    assert r.summary["errors"]["centroid_rms"] < 0.005
    assert r.summary["detections"] == [] and r.summary["status"] == "ok"


def test_avoidance_keeps_the_safe_distance_and_then_reconverges(fault_free_run):
    r = fault_free_run
    s = r.summary
    assert len(s["reactive"]) >= 2  # two cylinders on the path
    assert all(e["t_on"] < 41.8 for e in s["reactive"])
    assert s["min_safe_distance_margin"] >= -0.01  # never closer than d − 1 cm
    # check it independently from the logged true positions
    obs = np.array([o.position for o in r.scenario.obstacles])
    d = np.array([o.safe_distance for o in r.scenario.obstacles])
    dist = np.linalg.norm(r.log["x"][:, :, None, :] - obs[None, None], axis=3)
    assert (dist - d).min() >= -0.01
    assert s["min_obstacle_clearance"] > 0.1  # surface gap: no robot touches a cylinder
    # after the last avoidance episode the formation is back within 1 cm
    last_off = max(e["t_off"] for e in s["reactive"] if e["t_off"] is not None)
    after = r.log["t"] >= last_off + 1.0
    assert after.any() and r.log["sigma_err"][after].max() < 0.01
    est = np.abs(r.log["x_hat"] - r.log["x"][:, None]).max(axis=(1, 2, 3))
    assert est[r.log["t"] >= 5.0].max() < 0.05  # estimation error stays bounded


def test_robot_stopped_by_a_cylinder_on_contact():
    """Contacts are on: a robot driven through a cylinder is stopped by it."""
    d = scenario_dict()
    d["faults"] = []
    d["obstacles"] = [
        {
            "position": [0.6, -0.25],
            "radius": 0.1,
            "safe_distance": 0.25,
            "activation_distance": 0.25,
        }
    ]
    s = make(d)
    model = robots.get("disk")
    sc = scene.build(s, model)
    plant = Plant(sc, s.noise, 0.01, np.random.default_rng(0))
    ctrl = np.zeros((4, 2))
    ctrl[0] = [0.3, 0.0]  # robot 1 starts at (-0.4, -0.2), cylinder surface at x = 0.5
    for _ in range(600):
        plant.step(ctrl, 5)
    x = plant.positions()[0]
    gap = np.linalg.norm(x - [0.6, -0.25]) - 0.1 - model.footprint_radius
    assert gap > -0.01  # not through the cylinder
    assert x[0] < 0.6


def _plant(changes=None):
    s = _fault_free(**(changes or {}))
    model = robots.get("disk")
    sc = scene.build(s, model)
    plant = Plant(sc, s.noise, s.physics.control_period, np.random.default_rng(0))
    adapter = model.adapter(sc, plant.data)
    return s, sc, adapter, plant


@pytest.mark.parametrize("kind", ["stop", "bias"])
def test_fault_acts_through_the_actuators(kind):
    _, sc, adapter, plant = _plant()
    fault = scenario.Fault(1, kind, 0.5, np.array([0.3, -0.35]), 0.05)
    inj = sim_faults.ActuatorFaults(sc.model, (fault,), adapter)
    command = np.tile([0.2, 0.1], (4, 1))
    sent = command.copy()
    x_at = {}
    for k in range(300):  # 3 s
        t = k * 0.01
        inj.apply(t)
        if k in (100, 300 - 1):
            x_at[k] = plant.positions()
        plant.step(command, 5)
    assert np.array_equal(command, sent)  # the controller's command is untouched
    v = plant.velocities()
    healthy = [0, 2, 3]
    assert np.abs(v[healthy] - command[healthy]).max() < 0.01
    if kind == "stop":
        assert np.linalg.norm(v[1]) < 0.006  # braked to rest (up to ξ̄), not coasting
        moved = np.linalg.norm(x_at[299] - x_at[100], axis=1)
        assert moved[1] < 0.012 and moved[0] > 0.4
    else:
        assert np.abs(v[1] - (command[1] + [0.3, -0.35])).max() < 0.01
    np.testing.assert_allclose(
        inj.phi(3.0, command)[1], [-0.2, -0.1] if kind == "stop" else [0.3, -0.35], atol=1e-6
    )
    inj.clear()
    assert np.array_equal(sc.model.actuator_gainprm[sc.actuator, 0], np.full((4, 2), 200.0))


def test_the_disks_bias_terms_are_the_drives_map_of_phi_bit_for_bit():
    """The disk's b0 is written from Python numbers (sim/faults.py, ``_direct``: slides along
    the plane's axes, velocity servos); it must equal the general map kv·gear·φ of
    :meth:`~.actuators.Actuation.bias_terms` bit for bit: two biases and a drift summed on
    robot 2 in the faults' order, a bias on robot 4, robot 2 stopped from 1.5 s (its b0 is
    then the stop's, not the bias's) and healthy again from 2.5 s."""
    _, sc, adapter, _ = _plant()
    faults = (
        scenario.Fault(1, "bias", 0.2, np.array([0.3, -0.35]), 0.45),
        scenario.Fault(3, "bias", 0.3, np.array([-0.1, 0.2]), 0.0),
        scenario.Fault(1, "drift", 0.4, np.array([0.05, 0.02]), 0.0),
        scenario.Fault(1, "bias", 0.6, np.array([-0.07, 0.11]), 0.2),
        scenario.Fault(1, "stop", 1.5, np.zeros(2), 0.0, end=2.5),
    )
    inj = sim_faults.ActuatorFaults(sc.model, faults, adapter)
    b0 = sc.model.actuator_biasprm[:, 0]
    ids = sc.actuator
    written, stopped = 0, 0
    for k in range(300):
        t = k * 0.01
        inj.apply(t)
        want = adapter.actuation.bias_terms(adapter.joint_velocity(inj.bias_phi(t)), True)
        for robot in (1, 3):
            if inj.stopped[robot]:
                stopped += 1
            else:
                assert np.array_equal(b0[ids[robot]], want[robot]), (t, robot)
                written += bool(want[robot].any())
        assert np.array_equal(b0[ids[[0, 2]]], np.zeros((2, 2)))
    # robot 2: 0.21-1.49 s and 2.5-2.99 s (at 0.2 s its profile is 0), robot 4: 0.3-2.99 s
    assert (written, stopped) == (129 + 50 + 270, 100)


def test_stop_fault_in_the_closed_loop():
    s = scenario.load("paper_case").with_overrides(duration=44.0)
    r = loop.simulate(s)
    t, x = r.log["t"], r.log["x"]
    after = t >= 42.0
    drift = np.linalg.norm(x[after, 0] - x[after][0, 0], axis=1).max()
    assert drift < 0.02  # robot 1 stays where it stopped (ξ̄ = 5 mm/s at most)
    assert np.linalg.norm(r.log["u"][after, 0], axis=1).min() > 0.0  # still commanded
    assert r.summary["faults"] == [
        {"robot": 2, "kind": "bias", "t": 19.0},
        {"robot": 1, "kind": "stop", "t": 41.8},
    ]
    phi = r.log["phi"]
    np.testing.assert_allclose(
        phi[t >= 25.0, 1], np.tile([0.3, -0.35], (int((t >= 25).sum()), 1)), atol=1e-6
    )


def test_same_seed_same_numbers_other_seed_other_numbers():
    s = scenario.load("paper_case").with_overrides(duration=6.0)
    a, b = loop.simulate(s), loop.simulate(s)
    c = loop.simulate(s.with_overrides(seed=2))
    for key in ("wall_time", "real_time_factor", "build_time"):
        a.summary.pop(key), b.summary.pop(key), c.summary.pop(key)
    assert json.dumps(a.summary) == json.dumps(b.summary)
    for name in a.log:
        assert np.array_equal(a.log[name], b.log[name], equal_nan=True), name
    assert not np.array_equal(a.log["x"], c.log["x"])


def test_twelve_robots_converge():
    d = scenario_dict()
    d["team"] = ring_team(12, 1.1, shift=0.05)
    d["obstacles"], d["faults"], d["duration"] = [], [], 25.0
    d["mission"]["formation"]["side"] = 0.6
    d["fdir"]["initial_error_bound"] = "auto"  # paper_case's 1 m is below this start
    r = loop.simulate(make(d))
    after = r.log["t"] >= 18.0  # slowest observer mode: λ ≈ 0.37 1/s on this graph
    assert r.summary["status"] == "ok"
    assert r.log["sigma_err"][after].max() < 0.01
    est = np.abs(r.log["x_hat"] - r.log["x"][:, None]).max(axis=(1, 2, 3))
    assert est[after].max() < 0.01


def test_physics_trouble_stops_the_run_and_keeps_the_log(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo appends warnings to ./MUJOCO_LOG.TXT
    s = _fault_free(duration=10.0)

    def break_physics(t, plant):
        if t >= 2.0:
            plant.data.qvel[0] = np.nan

    r = loop.simulate(s, hook=break_physics)
    assert not r.ok
    assert "MuJoCo warning BADQVEL" in str(r.error)
    assert r.summary["status"] == "failed" and "BADQVEL" in r.summary["error"]
    assert 1.9 < r.log["t"][-1] < 2.1 and np.isfinite(r.log["x"]).all()
    run.write_records(r, tmp_path)
    saved = json.loads((tmp_path / "summary.json").read_text())
    assert saved["status"] == "failed"
    assert np.load(tmp_path / "log.npz")["t"][-1] == r.log["t"][-1]
    assert not list(tmp_path.glob(".*tmp"))  # no half-written files left


def test_cli_writes_the_output_contract(tmp_path, capsys):
    code = run.main(
        ["paper_case", "--duration", "21", "--seed", "3", "--out", str(tmp_path), "--no-progress"]
    )
    out = capsys.readouterr().out
    assert code == 0
    assert "fault: bias on robot 2" in out and "real time" in out
    summary = json.loads((tmp_path / "summary.json").read_text())
    for key in (
        "scenario",
        "seed",
        "duration",
        "robots",
        "robot_model",
        "wall_time",
        "real_time_factor",
        "faults",
        "reactive",
        "detections",
        "exclusions",
        "errors",
        "min_obstacle_clearance",
    ):
        assert key in summary, key
    assert summary["seed"] == 3 and summary["duration"] == 21.0
    assert set(summary["errors"]) >= {
        "centroid_rms",
        "formation_rms",
        "final_centroid",
        "final_formation",
    }
    log = np.load(tmp_path / "log.npz")
    assert set(log.files) == set(LOG_FIELDS) | set(STATIC_FIELDS)
    assert log["obstacles"].shape == (2, 4)
    n_t = len(log["t"])
    assert n_t == 21 * 50 + 1  # default 50 Hz
    shapes = {
        "x": (n_t, 4, 2),
        "x_hat": (n_t, 4, 4, 2),
        "u": (n_t, 4, 2),
        "phi": (n_t, 4, 2),
        "phi_hat": (n_t, 4, 2),
        "residual": (n_t, 4, 4),
        "threshold": (n_t, 4, 4),
        "reactive": (n_t, 4),
        "active": (n_t, 4),
        "sigma_err": (n_t, 2),
        "x_d": (n_t, 4, 2),
        "c_d": (n_t, 2),
        "flagged": (n_t, 4),
        "pose": (n_t, 4, 3),
    }
    for name, shape in shapes.items():
        assert log[name].shape == shape, name
    assert log["reactive"].any() and log["active"].all()


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_stops_the_run_and_keeps_what_was_computed(tmp_path, sig, code):
    """Ctrl-C or SIGTERM during a run: it stops at the next control period, writes the
    records so far with status "interrupted" and exits 130 / 143, without a traceback
    (it used to die with a traceback and discard the whole simulation)."""
    proc = subprocess.Popen(
        [
            *(sys.executable, "-m", "dftc_mujoco.run", "paper_case", "--duration", "3000"),
            *("--no-video", "--no-progress", "--out", str(tmp_path)),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    proc.stdout.readline()  # the run's first line: the scenario is read
    time.sleep(6.0)  # the set-up (a second or two on an idle machine), then some simulation
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=900)  # a safety net: it stops at the next period
    assert proc.returncode == code, err
    assert "Traceback" not in err and "interrupted by" in err
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "interrupted"
    assert summary["end_reason"] == f"interrupted by {signal.Signals(sig).name}"
    assert 0 < summary["simulated_time"] < 3000
    with np.load(tmp_path / "log.npz") as log:
        # the physics stopped at simulated_time; the log's last row is at most one log
        # period (50 Hz) before it
        assert 0 <= summary["simulated_time"] - log["t"][-1] <= 0.02 + 1e-9
        assert np.isfinite(log["x"][-1]).all()


def test_simulated_time_is_the_control_clock_after_long_runs():
    """After 25 721 periods MuJoCo's accumulated ``data.time`` is 257.21000000050003, and the
    summary's simulated time read 257.210000001 against the log's 257.21: the interrupted-run
    test above failed on it (simulated − last row = 0.020000001 > one log period). The
    physics time is a whole number of MuJoCo steps, and the summary says so."""
    d = scenario_dict()
    d["faults"], d["obstacles"], d["duration"] = [], [], 300.0
    d["physics"]["log_rate"] = 1.0
    d["fdir"] = {**d.get("fdir", {}), "enabled": False}
    with loop.Simulation(make(d)) as sim:
        sim.step(25_721)
        summary = sim.result().summary
    assert summary["simulated_time"] == 257.21
