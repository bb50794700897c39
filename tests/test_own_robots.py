"""A user's own robot, unchanged: small models of the kinds public mobile bases are published
as (tests/data/robots): a differential drive on coupled tendons, a four-wheel skid steer
spawned above the floor, servos that throw their robot off the plane, servos that chatter
at the scene's step (or at the step that keeps them on the plane), a fixed-base arm given
a planar base. Each is driven through the simulator's own drive and physics."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import mujoco
import numpy as np
import pytest

from dftc_mujoco import calibrate, load_scenario, simulate
from dftc_mujoco.calibrate import command
from dftc_mujoco.calibrate.command import on_plane
from dftc_mujoco.calibrate.mismatch import (
    LAG_CANDIDATES,
    Calibration,
    _tracking_note,
    lag_choice,
    programme,
    report,
    wheel_share,
)
from dftc_mujoco.calibrate.physics import CHATTER_SHARE
from dftc_mujoco.calibrate.track import TRACK_RATIO_MAX
from dftc_mujoco.closed_loop.loop import Simulation
from dftc_mujoco.sim import robots, scene
from dftc_mujoco.sim.plant import Plant

DATA = Path(__file__).parent / "data" / "robots"
DT = 0.01


def _copy(tmp_path: Path, name: str) -> Path:
    """The robot file ``name`` and its folder of models in ``tmp_path`` (calibrate writes)."""
    shutil.copytree(DATA / name, tmp_path / name)
    shutil.copy(DATA / f"{name}.robot.toml", tmp_path)
    return tmp_path / f"{name}.robot.toml"


def _drive(path: Path | str, u: tuple[float, float], seconds: float, step: float = 0.002):
    """One robot of the file at ``path`` driven by the planar command ``u`` [m/s] for
    ``seconds``: (its controlled point's start, its end, the base's lowest height at the start
    and the largest tilt of its base [rad])."""
    robot = robots.get(str(path))
    sc = scene.compose(robot, np.zeros((1, 2)), timestep=step)
    data = Plant.initial_data(sc)
    drive = robot.adapter(sc, data, DT)
    ids = drive.controlled()[0]
    site, body = int(sc.site[0]), int(sc.body[0])
    mujoco.mj_forward(sc.model, data)
    start = data.site_xpos[site][:2].copy()
    tilt = 0.0
    for _ in range(round(seconds / DT)):
        data.ctrl[ids] = drive.command(np.array([u], float))[0]
        mujoco.mj_step(sc.model, data, nstep=round(DT / step))
        tilt = max(tilt, math.acos(min(1.0, float(data.xmat[body][8]))))
    return start, data.site_xpos[site][:2].copy(), sc, data, tilt


def test_a_diffdrive_on_coupled_tendons_follows_its_commands():
    """Two torque motors pull fixed tendons forward = ½ q_L + ½ q_R and turn = −½ q_L + ½ q_R
    (as MuJoCo Menagerie's Stretch is published): the drive reads the wheels under them and
    steers the controlled point where it is asked, forward and sideways."""
    robot = robots.get(str(DATA / "tendonbot.robot.toml"))
    assert robot.drive == "diffdrive"
    for u in ((0.1, 0.0), (0.0, 0.1)):
        start, end, *_ = _drive(DATA / "tendonbot.robot.toml", u, 4.0)
        moved = end - start
        assert moved @ np.array(u) / 0.1 > 0.25, moved  # most of the 0.4 m asked
        side = moved[0] * u[1] / 0.1 - moved[1] * u[0] / 0.1
        assert abs(side) < 0.1, moved  # in the direction asked


def test_a_skid_steer_spawned_above_the_floor_starts_on_it_and_calibrates_its_track(tmp_path):
    """A four-wheel skid steer (two wheels a side) whose MJCF puts it 0.17 m up: it starts on
    the floor; calibrate spins it in place and stores the track its slipping wheels give,
    wider than the wheels' own; paper_case at the scale the footprint check suggests then has
    robot 1's stop flagged by every teammate and robot 1 alone excluded."""
    path = _copy(tmp_path, "skidbot")
    _, _, sc, data, tilt = _drive(path, (0.0, 0.0), 0.5)
    cylinder = mujoco.mjtGeom.mjGEOM_CYLINDER
    wheels = [g for g in range(sc.model.ngeom) if sc.model.geom_type[g] == cylinder]
    lowest = min(data.geom_xpos[g][2] - sc.model.geom_size[g][0] for g in wheels)
    assert abs(lowest) < 0.005 and tilt < 0.05  # on the floor, level
    geometric = robots.get(str(path)).params["axle_width"]
    assert calibrate.main([str(path), "--write"]) == 0
    track = robots.get(str(path)).calibration["track"]
    assert track > geometric * 1.05, (track, geometric)
    s = load_scenario("paper_case", {"team.robot_model": str(path), "mission.scale": 1.8})
    r = simulate(s, progress=False)
    out = r.summary
    assert out["onboard"]["blocks"]["thresholds"] == "drive"  # "auto": its lag is calibrated
    flagged = {d["by"] for d in out["detections"] if d["robot"] == 1}
    assert flagged == {1, 2, 3, 4}
    assert {d["robot"] for d in out["detections"]} == {1}
    assert [e["robot"] for e in out["exclusions"]] == [1]


def test_a_fixed_base_arm_given_a_planar_base_moves_as_a_holonomic_base():
    """planar_base = true gives a model published without a base joint the simulator's own
    x, y and yaw joints: it is driven like any holonomic base and its arm keeps its pose."""
    path = DATA / "armbase.robot.toml"
    start, end, _, _, tilt = _drive(path, (0.1, -0.05), 3.0)
    np.testing.assert_allclose(end - start, [0.3, -0.15], atol=0.03)
    assert tilt < 1e-6  # the planar joints keep it level


def test_calibrate_refuses_a_robot_that_leaves_the_plane_while_measured(tmp_path, capsys):
    """Servos far too strong for their wheels (kv 400 with no force range) throw the robot off
    the floor at every physics step calibrate tries: nothing is written, and the one line
    says when, how much, at which steps, and what to check."""
    path = _copy(tmp_path, "stiffbot")
    before = path.read_bytes()
    assert calibrate.main([str(path), "--write"]) != 0
    err = capsys.readouterr().err
    line = err.strip().splitlines()[-1]
    assert "calibration refused, nothing written" in line and "the base rose" in line, err
    assert "at the shorter steps tried (1, 0.5, 0.25, 0.125, 0.1 ms)" in line, err
    assert path.read_bytes() == before


ARM_ON_WHEELS = """
<mujoco>
  <worldbody>
    <geom name="floor" type="plane" size="2 2 0.1"/>
    <body name="base" pos="0 0 0.049">
      <freejoint/>
      <geom type="box" size="0.1 0.1 0.02"/>
      <body name="wheel" pos="0.05 0 -0.02"><geom type="sphere" size="0.03"/></body>
      <body name="caster" pos="-0.05 0 -0.02"><geom type="sphere" size="0.03"/></body>
      <body name="arm" pos="0 0 0.2">
        <joint name="lift" type="slide" axis="0 0 1"/>
        <geom type="box" size="0.05 0.05 0.02"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_calibrate_names_a_part_that_was_off_the_floor_at_the_start_and_touches_it():
    """Calibrate's watch lets the parts that touched the floor at the start (wheels, casters)
    touch it, and names any other part of the robot that comes down onto it (an arm
    swinging down, a gripper dragging), with when."""
    from dftc_mujoco.calibrate.physics import Watch

    model = mujoco.MjModel.from_xml_string(ARM_ON_WHEELS)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    watch = Watch(model, data, model.body("base").id, model.geom("floor").id)
    assert data.ncon >= 2  # the wheel and the caster rest on the floor
    watch.check(1.0)
    assert watch.trouble is None
    data.qpos[model.joint("lift").qposadr[0]] = -0.24  # the arm comes down to the floor
    mujoco.mj_forward(model, data)
    watch.check(2.5)
    assert watch.trouble is not None
    assert watch.trouble.t == 2.5 and watch.trouble.what.startswith("arm touched the floor")


def test_a_skid_steer_too_long_to_turn_is_refused_in_one_line_that_says_why(tmp_path, capsys):
    """The same four-wheel base with its wheels 0.8 m apart front to back on a 0.26 m track
    (MuJoCo Menagerie's TIAGo++, whose model gives its "omni base" plain wheels, has
    0.49 m on 0.45 m): spun in place it hardly turns, its plain wheels scrubbing sideways, and every
    step of calibrate's search drags it off the plane. Calibrate says so at once, with the
    fix, and writes nothing; the base as published calibrates (its track slips to 2×)."""
    path = _copy(tmp_path, "skidbot")
    xml = path.parent / "skidbot" / "skidbot.xml"
    text = xml.read_text().replace('pos="0.1 ', 'pos="0.4 ').replace('pos="-0.1 ', 'pos="-0.4 ')
    xml.write_text(text.replace('size="0.16 0.1 0.03"', 'size="0.46 0.1 0.03"'))
    before = path.read_text()
    assert calibrate.main([str(path), "--write"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "calibration refused, nothing written" in err[0], err
    ratio = float(err[0].split("effective track is ")[1].split(" m, ")[1].split(" times")[0])
    assert ratio > TRACK_RATIO_MAX, err
    assert "0.8 m apart front to back" in err[0] and "Model the rollers" in err[0], err
    assert path.read_text() == before


def test_calibrate_measures_a_drive_that_chatters_at_the_scene_step_again_at_shorter_steps(
    capsys, monkeypatch
):
    """Wheel servos that chatter at the scene's 2 ms step without leaving the floor (as
    MuJoCo Menagerie's Stretch 3 does) take most of their command range as mismatch there;
    calibrate measures them again at shorter steps, says so, and keeps the step that calms
    them: ξ̄ is then a small share of the range (it was 31 %, which a run cannot work in).
    The search goes down to 1 ms here (a 0.5 ms measurement would double the test's time
    and show nothing more: at 1 ms the mismatch has halved)."""
    monkeypatch.setattr(command, "CHATTER_STEPS_DOWN_TO", 0.001)
    cal, measured = on_plane(str(DATA / "chatterbot.robot.toml"))
    said = capsys.readouterr().out
    assert "its servos chatter at that step" in said, said
    share = float(said.split("mm/s, ")[1].split("%")[0]) / 100  # at the scene's step
    assert share > CHATTER_SHARE, said
    assert measured["timestep"] < 0.002 and cal.timestep == measured["timestep"]
    assert cal.smooth_max < share * cal.command_limit / 2
    assert cal.smooth_max < CHATTER_SHARE * cal.command_limit


def test_a_drive_that_runs_away_at_the_scene_step_and_chatters_at_the_next_is_calmed_too(
    capsys, monkeypatch
):
    """Wheel servos that rock the base past the plane's limits at the scene's 2 ms step and,
    at 1 ms, keep it on the floor but chatter (a third of their range as mismatch): the
    step that kept the robot on the plane is checked for chatter as the scene's step is,
    and calibrate goes on to a step that calms the servos (down to 0.5 ms here, where the
    mismatch has halved: a 0.25 ms measurement would double the test's time)."""
    monkeypatch.setattr(command, "CHATTER_STEPS_DOWN_TO", 0.0005)
    cal, measured = on_plane(str(DATA / "jumpbot.robot.toml"))
    said = capsys.readouterr().out
    assert "it left the plane at 2 ms: measuring at 1 ms" in said, said
    assert "at 1 ms the drive's mismatch on smooth commands" in said, said
    assert "its servos chatter at that step" in said, said
    assert measured["timestep"] < 0.001 and cal.timestep == measured["timestep"]
    assert cal.smooth_max < CHATTER_SHARE * cal.command_limit


def test_calibrate_says_when_a_robot_moves_at_a_steady_share_of_its_commands(tmp_path):
    """A drive model that does not match the wheels (here a robot file that gives the
    tendon-driven base wheels twice their radius; in MuJoCo Menagerie's Robot Soccer Kit,
    omni rollers that friction loss keeps from rolling) moves the robot at a steady share
    of its commands, which no lag and no ξ̄ describes: calibrate measures the share and
    says what to check. The same base as published moves at its commands."""
    path = _copy(tmp_path, "tendonbot")
    right = calibrate.measure(str(path))
    assert 0.95 < right.tracking < 1.05 and not any("moves at" in n for n in right.notes)
    path.write_text(path.read_text() + "wheel_radius = 0.1\n")  # the true radius: 0.05 m
    wrong = calibrate.measure(str(path))
    assert 0.4 < wrong.tracking < 0.6, wrong.tracking
    (note,) = [n for n in wrong.notes if "of its command, steadily" in n]
    assert note in report(wrong)
    # its wheels turn as the drive asks: the shortfall is between the wheels and the base
    turned = float(note.split("while its wheels turn at ")[1].split("%")[0]) / 100
    assert 0.95 < turned < 1.05, note
    assert "the servos deliver" in note and "Check the wheels' radius" in note
    # stored, and every run with the robot says it before it starts
    assert "tracking" not in right.table() and wrong.table()["tracking"] == round(wrong.tracking, 3)
    path.write_text(path.read_text() + f"\n[calibration]\ntracking = {wrong.table()['tracking']}\n")
    s = load_scenario("paper_case", {"team.robot_model": str(path), "mission.scale": 1.4})
    with Simulation(s) as sim:
        said = [e["message"] for e in sim.events.items if e["kind"] == "warning"]
    (warned,) = [m for m in said if "of their commands (calibration.tracking)" in m]
    assert f"python -m dftc_mujoco.calibrate {path} says whether its wheels" in warned


def test_a_shortfall_of_the_wheels_themselves_is_put_on_the_servos():
    """Where the wheels turn slower than the drive asks (the AI Worker's, kv 1 servos on
    a 98 kg base in turns: 55 %), the note says the servos cannot carry the load; where
    they turn as asked, it looks between the wheels and the floor."""
    prog = programme(0.5)
    asked = np.tile(np.hypot(*prog.u.T)[:, None], (1, 2)) * [1.0, -1.0]
    weak = wheel_share(prog, asked, 0.55 * asked)
    assert weak == pytest.approx(0.55)
    assert "turn at only 55% of the speeds" in _tracking_note(0.47, weak)
    assert "servos cannot carry the load" in _tracking_note(0.47, weak)
    assert "the servos deliver" in _tracking_note(0.47, wheel_share(prog, asked, asked))


def test_a_swerve_whose_steering_is_limited_to_90_degrees_turns_within_its_range(tmp_path):
    """Steering joints limited to ±90.5° (as ROBOTIS's AI Worker publishes its swerve base):
    a module whose nearer angle lies past its range takes the other one and drives its wheel
    the other way, so the base follows its commands as the unlimited one does (before, the
    modules were sent past their range: the base moved at 78 % of its commands, its smooth
    mismatch 0.30 m/s at the 99th percentile). Where a module swings across its range's
    edge it turns half a circle, a transient the unlimited base does not have."""
    base = Path(__file__).parents[1] / "models" / "robots"
    shutil.copytree(base / "swervebase", tmp_path / "swervebase")
    xml = tmp_path / "swervebase" / "swervebase.xml"
    text = xml.read_text()
    limited = text.replace(
        '<joint type="hinge" axis="0 0 1" damping="0.02" armature="0.001"/>',
        '<joint type="hinge" axis="0 0 1" damping="0.02" armature="0.001" range="-90.5 90.5"/>',
    )
    assert limited != text
    xml.write_text(limited)
    path = tmp_path / "limited.robot.toml"
    lines = (base / "swerve.robot.toml").read_text().split("[calibration]")[0]
    path.write_text(lines)
    free = calibrate.measure("swerve")
    cal = calibrate.measure(str(path))
    assert abs(cal.tracking - free.tracking) < 0.02, (cal.tracking, free.tracking)
    assert cal.smooth_p99 < 0.1, cal.smooth_p99


def test_a_drive_narrower_than_the_compensations_headroom_is_said_before_the_run(tmp_path):
    """A drive whose command range (here the built-in disk's servos limited to ±0.04 m/s, as
    slow as MuJoCo Menagerie's Stretch 3) is no wider than the compensation's headroom has
    no command a healthy robot is sure to keep out of the anti-windup's band: the run says
    so before it starts, naming the premise it checks instead. The disk as built says
    nothing of the kind."""
    base = Path(__file__).parents[1] / "models" / "robots"
    xml = (base / "disk.xml").read_text()
    slow = xml.replace('ctrlrange="-1 1"', 'ctrlrange="-0.04 0.04"')
    assert slow != xml
    (tmp_path / "disk.xml").write_text(slow)
    (tmp_path / "slowdisk.robot.toml").write_text((base / "disk.robot.toml").read_text())

    def said(robot: str) -> list[str]:
        s = load_scenario("paper_case", {"team.robot_model": robot, "mission.centroid.speed": 0.01})
        with Simulation(s) as sim:
            return [e["message"] for e in sim.events.items if e["kind"] == "warning"]

    (narrow,) = [m for m in said(str(tmp_path / "slowdisk.robot.toml")) if "headroom" in m]
    assert "±0.04 m/s" in narrow and "premise 'saturation'" in narrow
    # the anti-windup's band alone (5 cm/s) is wider than ±0.04 m/s: no G helps, and it says so
    assert "no G up to 50 times the run's brings" in narrow, narrow
    assert not [m for m in said("disk") if "no wider than the compensation's headroom" in m]


def test_a_drive_narrower_than_the_headroom_is_told_the_gain_that_leaves_it_room(tmp_path):
    """At ±0.12 m/s the disk's range is taken by the headroom of the paper's G = 0.01 I
    (Φ̄ ≈ 0.2 m/s), but not by a larger G's: the warning names the G, and with it the run
    says nothing of the kind."""
    base = Path(__file__).parents[1] / "models" / "robots"
    xml = (base / "disk.xml").read_text()
    (tmp_path / "disk.xml").write_text(xml.replace('ctrlrange="-1 1"', 'ctrlrange="-0.12 0.12"'))
    (tmp_path / "slowdisk.robot.toml").write_text((base / "disk.robot.toml").read_text())
    robot = str(tmp_path / "slowdisk.robot.toml")

    def said(**more: object) -> list[str]:
        s = load_scenario(
            "paper_case", {"team.robot_model": robot, "mission.centroid.speed": 0.01, **more}
        )
        with Simulation(s) as sim:
            return [e["message"] for e in sim.events.items if "headroom (" in e["message"]]

    (narrow,) = said()
    given = narrow.split("--set gains.G=")[1].split(" ")[0]
    phi = float(narrow.split(f"gains.G={given} gives Φ̄ = ")[1].split(" m/s")[0])
    assert 0.01 < float(given) <= 0.5 and phi + 0.05 < 0.12, narrow
    assert said(**{"gains.G": float(given)}) == []


def test_calibrate_raises_g_until_the_compensation_leaves_the_drive_room():
    """Calibrate keeps the compensation's gain G only where a run's bound Φ̄ on a healthy
    robot's ‖φ̂‖ (with ξ̄ and the lag the run models) and the anti-windup's band leave the
    drive some of its range: a ±0.12 m/s drive gets the smallest larger G that does (Φ̄ at
    the paper's G = 0.01 I is about 0.2 m/s, more with a lag), a ±1 m/s drive keeps G, and
    a ±0.04 m/s drive, which the band alone fills, keeps it too (the run says why)."""
    from dftc_mujoco.calibrate.compensation import range_fit, range_fit_report
    from dftc_mujoco.closed_loop.assembly import compensation_headroom

    G, phi, first = range_fit(0.01, 0.12, "paper_case", {}, 0.005, (0.0, 0.0))
    assert G > 0.01 and compensation_headroom(phi) < 0.12 <= compensation_headroom(first)
    line = range_fit_report(0.01, G, phi, first, 0.12)
    assert line is not None and f"G = {G:g} I leaves it room" in line
    lagged, phi_lag, first_lag = range_fit(0.01, 0.12, "paper_case", {}, 0.06, (0.0, 0.165))
    assert first_lag > first and lagged >= G and compensation_headroom(phi_lag) < 0.12
    assert range_fit(0.01, 1.0, "paper_case", {}, 0.005, (0.0, 0.0))[0] == 0.01
    assert range_fit(0.01, 0.04, "paper_case", {}, 0.005, (0.0, 0.0))[0] == 0.01
    assert range_fit_report(0.01, 0.01, first, first, 0.04) is None


def test_a_calibrated_physics_step_is_the_step_of_every_run_with_the_robot(tmp_path):
    """[calibration] timestep (a drive that runs away at longer steps) makes the scene step at
    most that long, a whole number of steps a control period, and the run says so."""
    path = _copy(tmp_path, "tendonbot")
    text = path.read_text()
    path.write_text(text + "\n[calibration]\nxi_bar = 0.05\ntimestep = 0.0007\n")
    s = load_scenario("paper_case", {"team.robot_model": str(path), "mission.scale": 1.4})
    sim = Simulation(s)
    h = sim.model.opt.timestep
    assert h <= 0.0007 and abs(0.01 / h - round(0.01 / h)) < 1e-9, h
    said = [e["message"] for e in sim.events.items if e["kind"] == "warning"]
    assert any("calibration.timestep = 0.0007" in m for m in said), said


def test_a_lag_fit_at_the_edge_of_its_search_is_said_and_not_stored():
    """A drive no first-order lag in the search range describes (a weak servo that reaches a
    third of its command fits the longest lag tried) is reported as such, and no lag is
    stored; inside the range the same fit is."""
    edge = LAG_CANDIDATES[-1]
    assert lag_choice(edge, 0.01, 0.2) == (0.0, 0.0)
    assert lag_choice(0.5, 0.01, 0.2) == (0.5, 0.0)  # halves the mismatch: modelled
    assert lag_choice(0.02, 0.15, 0.2) == (0.0, 0.02)  # only lowers it: the drive rule's
    cal = Calibration(
        model="weak", smooth_max=0.2, smooth_p99=0.2, all_max=0.3, all_p99=0.3, samples=100,
        jump_samples=0, lag_fit=edge, rms_command=0.2, rms_lag=0.01,
    )  # fmt: skip
    said = report(cal)
    assert "the longest lag tried (the edge of the search" in said and "none is stored" in said
    assert "lag" not in cal.table() and "fast_lag" not in cal.table()


@pytest.mark.parametrize("scale", [2.5, 5.1])
def test_the_scale_the_footprint_check_suggests_runs(scale):
    """mission.scale scales every length the checks compare: the start bound, the sighting
    tolerance and the teammates' distance as well as the path (at 2.5 the start bound stayed
    1 m, and the disk's paper_case was refused)."""
    s = load_scenario("paper_case", {"mission.scale": scale, "fdir.initial_error_bound": 1.0})
    assert s.fdir.initial_error_bound == pytest.approx(scale)
    Simulation(s)  # builds: nothing refused
