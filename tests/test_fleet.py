"""Mixed teams: one model per robot in ``team.robot_model``, composed in one
scene with each robot's own drive and actuators; the onboard blocks take the team's
envelope (sim/fleet.py)."""

from pathlib import Path

import pytest

from dftc_mujoco import load_scenario, simulate
from dftc_mujoco.core.events import Kind
from dftc_mujoco.errors import ScenarioError
from dftc_mujoco.sim import fleet

DATA = Path(__file__).parent / "data" / "robots"
HOLO, SLOW = (str(DATA / f"{n}.robot.toml") for n in ("holobase", "slowbase"))
OMNI = "omni"  # built in (models/robots/omni.robot.toml)
#: holonomic slides, a differential drive, omni wheels and the disk
MIXED = [HOLO, "diffdrive", OMNI, "disk"]


def test_a_team_lists_one_model_per_robot():
    s = load_scenario("paper_case", overrides={"team.robot_model": MIXED})
    assert s.team.models == tuple(MIXED) and s.to_dict()["team"]["robot_model"] == MIXED
    same = load_scenario("paper_case", overrides={"team.robot_model": ["disk"] * 4})
    assert same.team.robot_model == "disk"  # one model after all
    for bad, said in (
        (["disk"] * 3, "expected one model per robot (team.robots = 4) or a single name, got 3"),
        (["disk", 3, "disk", "disk"], "expected a model name or a list of names"),
    ):
        with pytest.raises(ScenarioError, match=r"team\.robot_model: " + said.split("(")[0]):
            load_scenario("paper_case", overrides={"team.robot_model": bad})


def test_the_envelope_is_the_team_s_worst_bounds():
    team = fleet.load(tuple(MIXED), "team.robot_model", None)
    assert team.mixed and [m.name for m, _ in team.groups()] == [
        "holobase",
        "diffdrive",
        "omni",
        "disk",
    ]
    env, models = team.envelope, team.models
    assert env.xi_bar == max(m.xi_bar for m in models)
    assert env.footprint_radius == max(m.footprint_radius for m in models)
    assert env.drift_bound == max(m.drift_bound for m in models)
    assert env.accel == min(m.accel for m in models)
    assert env.response_time == max(m.response_time for m in models) == 0.52  # the diffdrive
    assert env.calibration["compensation_G"] == max(
        m.calibration.get("compensation_G", 0) for m in models
    )
    slow = fleet.load((SLOW, "disk", "disk", "disk"), "team.robot_model", None)
    assert slow.envelope.lag == max(m.lag for m in slow.models) == pytest.approx(2.503)


def test_robots_with_different_lags_each_model_their_own():
    """The 2.5 s base beside three disks (which answer at once) in paper_case with l1: each
    robot's drive model has its own lag (it was refused: one lag for the team), robot 1's
    stop is flagged by its three teammates and robot 1 alone is excluded, no healthy robot
    is flagged and every premise holds; the general path computes the same. (The slow
    robot's bias drifts it 5.2 cm from its slot before its compensation, through the 2.5 s
    lag, catches up: as in a team of four such bases.)"""
    import numpy as np

    from dftc_mujoco import Simulation
    from dftc_mujoco.closed_loop.execution import Execution

    over = {"team.robot_model": ["disk", SLOW, "disk", "disk"], "onboard.thresholds": "l1"}
    s = load_scenario("paper_case", overrides=over)
    with Simulation(s) as sim:
        assert np.allclose(sim.team.config.lag, [0.0, 2.503, 0.0, 0.0])
        assert sim.team.drive.lag_b[0] == 0.0 and sim.team.drive.lag_b[1] > 0.0
        r = sim.run(progress=False)
    assert r.ok
    stop = next(e["t"] for e in r.events.of_kind(Kind.FAULT) if e["robot"] == 1)
    by = {e["by"] for e in r.events.of_kind(Kind.DETECTION) if e["robot"] == 1 and e["t"] > stop}
    assert by >= {2, 3, 4}
    assert [e["robot"] for e in r.events.of_kind(Kind.EXCLUSION)] == [1]
    assert r.summary["healthy_flags"] == 0
    assert all(p["held"] for p in r.summary["premises"].values())
    short = load_scenario("paper_case", overrides={**over, "duration": 10.0})
    logs = []
    for period in ("compiled", "general"):
        with Simulation(short, execution=Execution(period)) as sim:
            logs.append(sim.run(progress=False).log)
    for name in ("x", "u", "v_cmd", "phi_hat"):
        assert np.allclose(logs[0][name], logs[1][name], atol=1e-9), name


def test_a_mixed_team_of_three_drives_gives_the_paper_outcome():
    """Holonomic slides (the holonomic test base), a differential drive, omni wheels and the
    disk in paper_case at mission.scale = 1.4 (the base's footprint asks for it) with l1:
    robot 1's stop is flagged by all four within a second and robot 1 alone is excluded;
    nobody else is flagged and every premise holds."""
    over = {"team.robot_model": MIXED, "mission.scale": 1.4, "onboard.thresholds": "l1"}
    r = simulate(load_scenario("paper_case", overrides=over), progress=False)
    stop = next(e["t"] for e in r.events.items if e["kind"] == "fault" and e["robot"] == 1)
    flags = [(e["by"], e["robot"], e["t"]) for e in r.events.items if e["kind"] == "detection"]
    assert sorted(b for b, _, _ in flags) == [1, 2, 3, 4] and all(k == 1 for _, k, _ in flags)
    assert all(stop < t < stop + 1.0 for _, _, t in flags)
    assert [e["robot"] for e in r.events.items if e["kind"] == "exclusion"] == [1]
    assert all(p["held"] for p in r.summary["premises"].values())
    assert r.summary["robot_model"][1] == "diffdrive" and r.summary["robot_model"][0].endswith(
        "holobase.robot.toml"
    )


def test_a_mixed_team_s_starts_are_checked_robot_by_robot():
    """Two disks 0.3 m apart overlap nobody (0.1 m footprints), though the holonomic base
    beside them has a 0.32 m one: only a pair that really overlaps is refused."""
    from dftc_mujoco.closed_loop.loop import Simulation

    starts = [[-0.9, -0.9], [0.2, 0.0], [0.5, 0.0], [0.35, 0.6]]
    over = {
        "team.robot_model": [HOLO, "disk", "disk", "disk"],
        "team.initial_positions": starts,
        "mission.formation.side": 0.7,
        "fdir.initial_error_bound": "auto",
    }
    Simulation(load_scenario("paper_case", overrides=over)).close()  # not refused
    starts[1] = [-0.6, -0.7]  # a disk 0.36 m from the base: 0.1 + 0.32 overlap
    with pytest.raises(
        ScenarioError,
        match=r"robots 1 and 2 start 0\.361 m apart: their hulls overlap "
        r"\(footprint radii 0\.321 m and 0\.100 m\)",
    ):
        Simulation(
            load_scenario("paper_case", overrides={**over, "team.initial_positions": starts})
        )
