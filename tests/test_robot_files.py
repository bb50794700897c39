"""Real robots unchanged: robot files, every actuator kind, keyframes, checks before the run.

The test robots in ``tests/data/robots`` are written for this project with the
conventions of published MJCF robots (<compiler angle="radian" meshdir>, <default>
classes, unnamed collision geoms in group 3, keyframes, gear, position servos, a
free-joint base carrying an arm); no third-party file is copied.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

from dftc_mujoco import calibrate, run, scenario
from dftc_mujoco.closed_loop import assembly, checks, loop
from dftc_mujoco.errors import ScenarioError
from dftc_mujoco.sim import faults as sim_faults
from dftc_mujoco.sim import robots, scene, tree
from dftc_mujoco.sim.plant import Plant

DATA = Path(__file__).parent / "data" / "robots"
HOLOBASE = DATA / "holobase.robot.toml"
MOBILEARM = DATA / "mobilearm.robot.toml"
# what a big robot needs in paper_case: room in the formation (the checks say how much)
# and start positions at the slots
BIG = {
    "mission.formation.side": 1.0,
    "team.initial_positions": {"layout": "formation", "jitter": 0.02},
}
# with the robots' measured mismatch (15-20 mm/s: position servos lag) eq. 40's thresholds
# are too wide to catch the stop in time; the block_row rule, with the calibrated drift
# offset, is the README's recipe for such robots
TIGHT = {**BIG, "onboard.thresholds": "block_row"}

MOTORBOX = """<mujoco model="motorbox">
  <worldbody>
    <body name="cart" pos="0 0 0.05">
      <joint name="slide_x" type="slide" axis="1 0 0" damping="0.5"/>
      <joint name="slide_y" type="slide" axis="0 1 0" damping="0.5"/>
      <geom type="box" size="0.08 0.08 0.04" mass="3"/>
    </body>
  </worldbody>
  <actuator>
    <motor name="fx" joint="slide_x" gear="2" ctrlrange="-40 40"/>
    <motor name="fy" joint="slide_y" gear="2" ctrlrange="-40 40"/>
  </actuator>
</mujoco>
"""

POSITION_BOX = """<mujoco model="posbox">
  <custom><text name="dftc_adapter" data="holonomic"/></custom>
  <worldbody>
    <body name="base" pos="0 0 0.04">
      <joint name="x" type="slide" axis="1 0 0"/>
      <joint name="y" type="slide" axis="0 1 0"/>
      <geom type="box" size="0.07 0.05 0.04" mass="1.5"/>
      <site name="center"/>
    </body>
  </worldbody>
  <actuator>
    <position name="vx" joint="x" kp="20000" kv="400"/>
    <position name="vy" joint="y" kp="20000" kv="400"/>
  </actuator>
</mujoco>
"""


def robot_file(tmp_path: Path, text: str, mjcf: str = "", name: str = "bot") -> Path:
    if mjcf:
        (tmp_path / f"{name}.xml").write_text(mjcf)
    path = tmp_path / f"{name}.robot.toml"
    path.write_text(text)
    return path


# --------------------------------------------------------------------------- the robot file


HOLO_FILE = f"""mjcf = "{DATA / "holobase" / "holobase.xml"}"
base = "base_link"
drive = "holonomic"
keyframe = "home"
[holonomic]
x = "joint_x"
y = "joint_y"
yaw = "joint_th"
"""


@pytest.mark.parametrize(
    ("change", "key", "message"),
    [
        (lambda t: 'colour = "red"\n' + t, "colour", "unknown key"),
        (lambda t: t.replace('base = "base_link"\n', ""), "base", "missing key"),
        (lambda t: t.replace('"base_link"', '"base_lnk"'), "base", "no body 'base_lnk'"),
        (lambda t: t.replace('x = "joint_x"', 'x = "jx"'), "holonomic.x", "no actuator 'jx'"),
        (lambda t: t.replace('"home"', '"park"'), "keyframe", "no keyframe 'park'"),
        (lambda t: t.replace('drive = "holonomic"', 'drive = "legs"'), "drive", "expected one of"),
        (lambda t: t + "[diffdrive]\nleft = 'a'\n", "diffdrive", "goes with drive = 'diffdrive'"),
        (lambda t: t.replace('x = "joint_x"', 'x = "joint_th"'), "holonomic.x", "slide joint"),
        (
            lambda t: t.replace('drive = "holonomic"', 'drive = "diffdrive"').replace(
                '[holonomic]\nx = "joint_x"\ny = "joint_y"\nyaw = "joint_th"',
                '[diffdrive]\nleft = "joint_x"\nright = "joint_y"',
            ),
            "drive",
            "needs a free joint",
        ),
        # a G of 0 ran as the paper's 0.01 without a word (gains.G = 0 itself is refused)
        (
            lambda t: t + "[calibration]\ncompensation_G = 0\n",
            "calibration.compensation_G",
            "expected a number > 0, got 0",
        ),
        # an empty name ran, its events reading "two  robots need ..."
        (lambda t: 'name = " "\n' + t, "name", "got an empty one"),
        # a folder was "no such file"
        (lambda t: t.replace(str(DATA / "holobase" / "holobase.xml"), str(DATA)), "mjcf", "folder"),
        # found by fuzzing: a file MuJoCo has no reader for printed MuJoCo's own WARNING first
        (
            lambda t: t.replace(
                str(DATA / "holobase" / "holobase.xml"), str(DATA / "make_meshes.py")
            ),
            "mjcf",
            "a .xml (MJCF) or .urdf file, got 'make_meshes.py'",
        ),
    ],
)
def test_robot_file_problems_are_one_line_naming_file_and_key(tmp_path, change, key, message):
    path = robot_file(tmp_path, change(HOLO_FILE))
    with pytest.raises(ScenarioError) as info:
        robots.get(str(path))
    text = str(info.value)
    assert text.startswith(f"{path}: {key}:") and message in text, text
    assert "\n" not in text


@pytest.mark.parametrize(
    ("change", "key", "known"),
    [
        (
            lambda t: "max_sped = 0.8\n" + t,
            "max_sped",
            "base, calibration, control_point, diffdrive, drive, holonomic, integrator, "
            "keyframe, max_speed, mesh_density, mjcf, motor, name, omni, planar_base, swerve",
        ),
        (lambda t: t + "yaww = 'joint_th'\n", "holonomic.yaww", "x, y, yaw"),
        (lambda t: t + "[motor]\ntau = 0.1\n", "motor.tau", "time_constant"),
    ],
)
def test_an_unknown_key_lists_every_key_the_robot_file_accepts(tmp_path, change, key, known):
    """A misspelt optional key is told what it could be: the list used to name only the
    keys the file already had (no keyframe, max_speed, motor or yaw)."""
    path = robot_file(tmp_path, change(HOLO_FILE.replace('yaw = "joint_th"\n', "")))
    with pytest.raises(ScenarioError) as info:
        robots.get(str(path))
    assert str(info.value) == f"{path}: {key}: unknown key (known keys here: {known})"


def test_a_robot_path_that_is_a_folder_or_nowhere_says_where_it_looked(tmp_path):
    """A folder given as the robot was "no such robot file", and a missing file named only the
    first of the folders looked in."""
    with pytest.raises(ScenarioError, match=r"^--robot: '.*' is a folder \(.*\), expected a robot"):
        robots.get(str(tmp_path), "--robot")
    with pytest.raises(ScenarioError) as info:
        robots.get("sub/bot.robot.toml", "team.robot_model", base=tmp_path)
    assert str(info.value) == (
        "team.robot_model: no such robot file 'sub/bot.robot.toml' "
        f"(looked in {Path.cwd() / 'sub'} and {tmp_path / 'sub'})"
    )


def test_a_bad_robot_file_on_the_command_line_is_one_line_exit_2(tmp_path):
    path = robot_file(tmp_path, HOLO_FILE.replace('"joint_y"', '"nope"'))
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "dftc_mujoco.run",
            "paper_case",
            "--robot",
            str(path),
            "--no-video",
            "--out",
            str(tmp_path / "o"),
        ],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f"error: {path}: holonomic.y: no actuator 'nope' in holobase.xml "
        "(actuators: joint_x, joint_y, joint_th)"
    ]
    assert not (tmp_path / "o").exists()


def test_a_third_party_mjcf_without_a_robot_file_says_what_to_write(tmp_path):
    path = tmp_path / "base.xml"
    path.write_text((DATA / "holobase" / "holobase.xml").read_text())
    with pytest.raises(ScenarioError, match=r"no body named 'base'.*write NAME\.robot\.toml"):
        robots.get(str(path))


# --------------------------------------------------------------------------- the model as it is


def test_compiler_defaults_assets_and_options_of_the_model_are_kept():
    holo = robots.get(str(HOLOBASE))
    # the bumper is turned by 1.5708 rad: along x it reaches 0.32 m (in degrees: 0.25 m)
    assert holo.footprint_radius == pytest.approx(0.32, abs=0.002)
    assert [i.kind for i in holo.driven_infos] == ["position", "position"]
    sc = scene.compose(holo, np.zeros((2, 2)))
    m = sc.model
    assert m.nmesh == 4 and sc.notes == ()  # meshes from meshdir; its <option> is the arena's
    base = sc.body[0]
    geoms = [g for g in range(m.ngeom) if m.geom_bodyid[g] == base]
    assert m.body_mass[base] == pytest.approx(25.0)  # <default><geom mass="0"/>, one of 25 kg
    assert sorted(set(m.geom_group[geoms])) == [2, 3]  # the classes' groups
    arm = robots.get(str(MOBILEARM))
    notes = scene.compose(arm, np.zeros((1, 2))).notes
    assert len(notes) == 1 and "cone=elliptic" in notes[0] and "arena's options apply" in notes[0]


def test_unnamed_collision_geoms_meet_cylinders_and_follow_robot_contacts():
    """Bug 1: collision bits by body membership, not by geom name."""
    holo = robots.get(str(HOLOBASE))
    cylinder = scenario.Obstacle(np.array([1.0, 0.0]), 0.1, 0.5, 0.6)

    def drive(positions, commands, contacts, obstacles=()):
        sc = scene.compose(holo, np.array(positions), obstacles, robot_contacts=contacts)
        data = Plant.initial_data(sc)
        d = holo.adapter(sc, data)
        for _ in range(200):  # 2 s
            data.ctrl[d.controlled().ravel()] = d.command(np.array(commands)).ravel()
            mujoco.mj_step(sc.model, data, nstep=5)
        return data.site_xpos[sc.site][:, :2]

    x = drive([[0.0, 0.0]], [[0.5, 0.0]], True, (cylinder,))  # 1 m in 2 s, unless stopped
    assert 0.6 < x[0, 0] < 1.0 - 0.1 - 0.2  # stopped at the cylinder by the shell's surface
    # two robots driven at each other: stopped by contact, or through each other without it
    start, push = [[-0.5, 0.0], [0.5, 0.0]], [[0.5, 0.0], [-0.5, 0.0]]
    apart = np.linalg.norm(np.diff(drive(start, push, True), axis=0))
    through = drive(start, push, False)
    assert apart > 2 * 0.2 and through[0, 0] > through[1, 0] + 0.5


def _contacts_between_robots(sc: scene.Scene, data: mujoco.MjData) -> int:
    """Contacts MuJoCo finds between geoms of two different robots."""
    owner = np.full(sc.model.nbody, -1)
    for i, b in enumerate(sc.body):
        owner[tree.subtree(sc.model, int(b))] = i
    pairs = [
        (owner[sc.model.geom_bodyid[c.geom1]], owner[sc.model.geom_bodyid[c.geom2]])
        for c in data.contact[: data.ncon]
    ]
    return sum(a >= 0 and b >= 0 and a != b for a, b in pairs)


def test_free_joint_robots_without_robot_contacts_meet_the_floor_but_not_each_other():
    """Robots on a free joint keep the floor under their wheels; with robot_contacts =
    false the floor's bit must not make their own geoms meet each other's."""
    arm = robots.get(str(MOBILEARM))
    for contacts, expect_between in ((True, True), (False, False)):
        sc = scene.compose(arm, np.array([[0.0, 0.0], [0.05, 0.0]]), robot_contacts=contacts)
        data = Plant.initial_data(sc)
        mujoco.mj_forward(sc.model, data)
        assert (_contacts_between_robots(sc, data) > 0) == expect_between, contacts
    for _ in range(100):  # 1 s standing through each other: both rest on the floor
        mujoco.mj_step(sc.model, data, nstep=5)
    z = data.xpos[sc.body, 2]
    assert abs(z[1] - z[0]) < 1e-3 and np.all(z > -0.01), z


def test_keyframe_pose_is_the_start_and_undriven_actuators_hold_it():
    arm = robots.get(str(MOBILEARM))
    s = scenario.load_scenario(
        "paper_case", {**BIG, "team.robot_model": str(MOBILEARM), "duration": 3.0, "gains.G": 0.05}
    )
    with loop.Simulation(s) as sim:
        m, data = sim.model, sim.data
        joints = [
            m.joint(f"robot{i}/{j}").qposadr[0] for i in (1, 4) for j in ("shoulder_pitch", "elbow")
        ]
        np.testing.assert_allclose(data.qpos[joints], [-1.2, 2.0, -1.2, 2.0])
        start = data.site_xpos[sim.scene.site][:, :2].copy()
        np.testing.assert_allclose(start, np.asarray(s.team.initial_positions), atol=1e-9)
        sim.run(progress=False)
        assert np.abs(data.qpos[joints] - [-1.2, 2.0, -1.2, 2.0]).max() < 0.05  # held by ctrl
        assert sim.result().summary["status"] == "ok"
    holo = scenario.load_scenario(
        "paper_case", {**BIG, "team.robot_model": str(HOLOBASE), "duration": 3.0}
    )
    with loop.Simulation(holo) as sim:
        sim.run(progress=False)
        yaw = sim.data.qpos[[sim.model.joint(f"robot{i}/joint_th").qposadr[0] for i in (1, 2)]]
        np.testing.assert_allclose(yaw, 0.3, atol=0.01)  # the yaw is held at its keyframe
    assert arm.init_qpos[-3:] == (0.0, -1.2, 2.0)


def test_bodies_outside_the_base_neither_widen_the_footprint_nor_shift_the_keyframe_ctrl(
    tmp_path,
):
    """A model with more than the robot at world level (here a dock on a slide, with the
    first actuator): only the base's subtree is attached, so only its geoms count for the
    footprint, and the arm's servos still hold their keyframe ctrl."""

    folder = tmp_path / "mobilearm"
    shutil.copytree(MOBILEARM.parent / "mobilearm", folder)
    xml = (folder / "mobilearm.xml").read_text()
    dock = (
        '<body name="dock" pos="3 0 0.3"><joint name="dock_slide" type="slide" axis="1 0 0"/>'
        '<geom type="box" size="0.5 0.5 0.3"/></body>\n  </worldbody>'
    )
    xml = xml.replace("</worldbody>", dock, 1)
    xml = xml.replace("<actuator>", '<actuator>\n    <position name="dock" joint="dock_slide"/>', 1)
    xml = xml.replace('-1.2 2.0" ctrl="0 0 0 -1.2 2.0"', '-1.2 2.0 0.4" ctrl="0.4 0 0 0 -1.2 2.0"')
    (folder / "dock.xml").write_text(xml)
    text = MOBILEARM.read_text().replace("mobilearm/mobilearm.xml", "mobilearm/dock.xml")
    (tmp_path / "dock.robot.toml").write_text(text)
    plain, docked = robots.get(str(MOBILEARM)), robots.get(str(tmp_path / "dock.robot.toml"))
    assert docked.footprint_radius == pytest.approx(plain.footprint_radius)
    sc = scene.compose(docked, np.array([[0.0, 0.0], [1.0, 0.0]]))
    data = Plant.initial_data(sc)
    for i in (1, 2):
        for name, value in (("shoulder_pitch", -1.2), ("elbow", 2.0)):
            assert data.ctrl[sc.model.actuator(f"robot{i}/{name}").id] == pytest.approx(value)


@pytest.mark.parametrize("model", ["diffdrive", str(MOBILEARM)])
def test_a_diffdrive_reaches_its_command_range_in_every_heading_within_its_wheel_range(model):
    """The per-axis command range is what the wheels can give in every heading: at the
    corners (±m, ±m) the wheel speeds asked for stay within the servos' range, and reach
    it in the worst heading (the range is not understated either)."""
    robot = robots.get(model)
    sc = scene.compose(robot, np.zeros((1, 2)))
    drive = robot.adapter(sc, Plant.initial_data(sc))
    m = drive.command_limit
    wheel = min(i.velocity_limit for i in robot.driven_infos)
    corners = m * np.array([[1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0]])
    worst = max(
        float(np.abs(drive.joint_velocity(corners[[c]], np.array([h]))).max())
        for h in np.linspace(-np.pi, np.pi, 721)
        for c in range(4)
    )
    assert wheel * 0.999 < worst <= wheel * (1 + 1e-9), (worst, wheel)


def test_wheel_gear_and_axle_direction_are_read_from_the_model():
    """Bug 4 (diffdrive): the adapter honours gear="3" and a wheel whose axis points back."""
    arm = robots.get(str(MOBILEARM))
    assert arm.params["sign_right"] == -1.0 and arm.params["sign_left"] == 1.0
    assert arm.params["wheel_radius"] == pytest.approx(0.06)
    assert arm.params["axle_width"] == pytest.approx(0.31)
    assert arm.params["offset"] == pytest.approx(0.15)
    assert [i.gear for i in arm.driven_infos] == [3.0, 3.0]
    sc = scene.compose(arm, np.zeros((1, 2)))
    data = Plant.initial_data(sc)
    d = arm.adapter(sc, data)
    x0 = data.site_xpos[sc.site[0], :2].copy()
    for _ in range(300):  # 3 s at 0.2 m/s forward, then sideways
        u = np.array([[0.2, 0.0]]) if data.time < 2.0 else np.array([[0.0, 0.2]])
        data.ctrl[d.controlled()[0]] = d.command(u)[0]
        mujoco.mj_step(sc.model, data, nstep=5)
    moved = data.site_xpos[sc.site[0], :2] - x0
    np.testing.assert_allclose(moved, [0.4, 0.2], atol=0.03)


MOTOR_FILE = """mjcf = "bot.xml"
base = "cart"
drive = "holonomic"
[holonomic]
x = "fx"
y = "fy"
[motor]
time_constant = 0.04
"""


@pytest.mark.parametrize("kind", ["velocity", "position", "motor"])
@pytest.mark.parametrize("fault", ["stop", "bias"])
def test_faults_act_through_every_actuator_kind(tmp_path, kind, fault):
    model = {
        "velocity": lambda: robots.get("disk"),
        "position": lambda: robots.get(str(HOLOBASE)),
        "motor": lambda: robots.get(str(robot_file(tmp_path, MOTOR_FILE, MOTORBOX))),
    }[kind]()
    assert {i.kind for i in model.driven_infos} == {kind}
    sc = scene.compose(model, np.array([[0.0, 0.0], [2.0, 0.0]]))
    data = Plant.initial_data(sc)
    d = model.adapter(sc, data)
    inj = sim_faults.ActuatorFaults(
        sc.model, (scenario.Fault(1, fault, 1.0, np.array([0.1, -0.1]), 0.0),), d
    )
    u = np.array([[0.2, 0.1], [0.2, 0.1]])
    x = []
    for k in range(400):  # 4 s
        inj.apply(k * 0.01)
        if k in (200, 399):
            x.append(data.site_xpos[sc.site][:, :2].copy())
        data.ctrl[d.controlled().ravel()] = d.command(u).ravel()
        mujoco.mj_step(sc.model, data, nstep=5)
    v = (x[1] - x[0]) / 1.99  # mean velocity over the last 2 s
    np.testing.assert_allclose(v[0], u[0], atol=0.01)  # the healthy robot
    if fault == "stop":
        assert np.linalg.norm(v[1]) < 0.005  # braked (or held) where it stopped
    else:
        np.testing.assert_allclose(v[1], u[1] + [0.1, -0.1], atol=0.01)
    inj.clear()


def test_position_servos_under_the_old_contract_are_driven_as_position_servos(tmp_path):
    """Bug 4: position servos named vx / vy passed as velocity ones and the run died."""
    path = tmp_path / "posbox.xml"
    path.write_text(POSITION_BOX)
    box = robots.get(str(path))
    assert [i.kind for i in box.driven_infos] == ["position", "position"]
    s = scenario.load_scenario("paper_case", {"team.robot_model": str(path), "duration": 48.0})
    r = loop.simulate(s)
    assert r.summary["status"] == "ok"
    assert {d["robot"] for d in r.summary["detections"]} == {1}  # only the stopped robot
    assert r.summary["min_obstacle_clearance"] > 0


# --------------------------------------------------------------------------- calibration


def test_calibrate_writes_the_robot_file_never_the_mjcf(tmp_path, capsys):
    mjcf = (DATA / "holobase" / "holobase.xml").read_text()
    (tmp_path / "assets").mkdir()
    for f in (DATA / "holobase" / "assets").iterdir():
        (tmp_path / "assets" / f.name).write_bytes(f.read_bytes())
    path = robot_file(
        tmp_path,
        HOLO_FILE.replace(str(DATA / "holobase" / "holobase.xml"), "bot.xml") + "\n# the end\n",
        mjcf,
    )
    before = (tmp_path / "bot.xml").read_bytes()
    path.chmod(0o644)
    assert calibrate.main([str(path), "--write"]) == 0
    assert path.stat().st_mode & 0o777 == 0o644  # the replaced file keeps its permissions
    out = capsys.readouterr().out
    assert "start-up:" in out and "response to a jump" in out and "compensation loop" in out
    assert (tmp_path / "bot.xml").read_bytes() == before
    holo = robots.get(str(path))
    assert 0.005 < holo.xi_bar < 0.05 and holo.calibration["mismatch"] > 0.005
    assert path.read_text().count("[calibration]") == 1 and "# the end" in path.read_text()
    assert calibrate.main([str(path), "--write"]) == 0  # again: replaced, not added
    assert path.read_text().count("[calibration]") == 1


@pytest.mark.parametrize(
    "written", ["calibration = { xi_bar = 0.01 }", "calibration.xi_bar = 0.01"]
)
def test_calibrate_refuses_a_calibration_table_it_cannot_replace_before_measuring(
    tmp_path, written
):
    """An inline or dotted calibration cannot be replaced line-wise: one line naming the
    file and the key, exit 2, in well under the measuring time, the file untouched."""
    path = robot_file(tmp_path, f"{written}\n{HOLO_FILE}")
    before = path.read_bytes()
    proc = subprocess.run(
        [sys.executable, "-m", "dftc_mujoco.calibrate", str(path), "--write"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert f"{path}: calibration:" in proc.stderr and "[calibration] table" in proc.stderr
    assert not proc.stdout and path.read_bytes() == before  # nothing was measured


ROBOTS = Path(robots.__file__).resolve().parents[2] / "models" / "robots"
# a robot file a person wrote: comments everywhere, a hand-measured lag, a comment that
# belongs to the table after [calibration]
HAND_WRITTEN = f"""# my disk, for the lab's bench tests
mjcf = "{ROBOTS / "disk.xml"}"   # the built-in model
base = "base"
drive = "holonomic"

[holonomic]
x = "vx"  # the x servo
y = "vy"

[calibration]
lag = 0.08  # measured on the bench
xi_bar = 0.005

# the inner loop of the motors, tuned by hand
[motor]
time_constant = 0.05
"""
FAST_CALIBRATION = ["--runs", "1", "--set", "duration=5"]


def test_calibrate_write_replaces_calibration_keys_only_and_lists_what_it_replaces(
    tmp_path, capsys
):
    """--write keeps every line outside the values it replaces (the next table and its
    comment included) and says which hand-set values it replaces."""
    path = robot_file(tmp_path, HAND_WRITTEN)
    assert calibrate.main([str(path), "--write", *FAST_CALIBRATION]) == 0
    out = capsys.readouterr().out
    said = out[out.index("replacing values of") :].splitlines()
    assert said[1].strip().startswith("lag = 0.08 (# measured on the bench): removed"), out
    assert out.index("replacing values of") < out.index("written to")
    text = path.read_text()
    before = HAND_WRITTEN.partition("[calibration]\n")
    assert text.startswith(before[0] + "[calibration]\n")  # byte for byte up to the table
    assert text.endswith("\n# the inner loop of the motors, tuned by hand\n[motor]\n"
                         "time_constant = 0.05\n")  # fmt: skip
    assert "\nlag =" not in text and "measured on the bench" not in text  # listed, removed
    assert "\nfast_lag = " in text  # the drive rule's lag: what fits, below 50 ms
    model = robots.get(str(path))
    assert model.calibration["mismatch"] > 0 and "drift_bound" in model.calibration
    assert model.motor_time_constant == 0.05


def test_calibrate_keep_keeps_the_values_the_file_has(tmp_path, capsys):
    """--keep adds the keys the file lacks and leaves the others, their comments too."""
    from dftc_mujoco.calibrate import files

    path = robot_file(tmp_path, HAND_WRITTEN)
    new = {"lag": 0.05, "xi_bar": 0.0055, "mismatch": 0.002}
    assert files.write(path, new, keep=True) == []
    text = path.read_text()
    assert "lag = 0.08  # measured on the bench\nxi_bar = 0.005\nmismatch = 0.002\n" in text
    assert text.endswith("\n# the inner loop of the motors, tuned by hand\n[motor]\n"
                         "time_constant = 0.05\n")  # fmt: skip
    changes = files.write(path, new)  # without it: replaced, each change returned
    assert [c.line() for c in changes] == [
        "lag = 0.08 (# measured on the bench) -> 0.05",
        "xi_bar = 0.005 -> 0.0055",
    ]
    assert "lag = 0.05\n" in path.read_text()  # the old value's comment went with it
    assert calibrate.main(["disk", "--keep"]) == 2  # nothing to keep without --write
    assert "--keep" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("table", "after"),
    [
        ("[calibration]", ""),  # the file's last line, no newline
        ("[ 'calibration' ]  # mine\n", "\n# the motors\n[motor]\ntime_constant = 0.05\n"),
        ("[calibration]\nlag = 0.08\n\n", "# the motors\n[motor]\ntime_constant = 0.05\n"),
    ],
)
def test_a_new_calibration_key_goes_after_the_tables_last_key(tmp_path, table, after):
    """--write adds a key the file lacks inside its [calibration] table, after its last
    key: the blank line and the comment that lead to the next table stay with it."""
    import tomllib

    from dftc_mujoco.calibrate import files

    head = 'mjcf = "bot.xml"\nbase = "base"\n'
    path = robot_file(tmp_path, head + table + after)
    files.write(path, {"mismatch": 0.002}, keep=True)
    text = path.read_text()
    assert text.startswith(head) and text.endswith(after), text
    assert tomllib.loads(text)["calibration"]["mismatch"] == 0.002
    keys = text.index("mismatch = 0.002\n")
    assert text.index("calibration") < keys < len(text) - len(after)


INCLUDED_BOX = """<mujoco model="boxbot">
  <!-- the parts are shared with the lab's other models -->
  <include file="parts.xml"/>
  <custom>
    <text name="dftc_adapter" data="holonomic"/>
    <numeric name="dftc_xi_bar" data="0.02"/>
  </custom>
</mujoco>
"""
PARTS = """<mujoco>
  <worldbody>
    <body name="base" pos="0 0 0.04">
      <joint name="x" type="slide" axis="1 0 0"/>
      <joint name="y" type="slide" axis="0 1 0"/>
      <geom name="hull" type="box" size="0.07 0.05 0.04" mass="1.5"/>
      <site name="center"/>
    </body>
  </worldbody>
  <actuator>
    <velocity name="vx" joint="x" kv="150" ctrlrange="-1 1" ctrllimited="true"/>
    <velocity name="vy" joint="y" kv="150" ctrlrange="-1 1" ctrllimited="true"/>
  </actuator>
</mujoco>
"""


def test_calibrate_write_edits_an_mjcf_in_place_never_resaves_it(tmp_path, capsys):
    """On an MJCF with <include>, --write edits the values in place: the include stays an
    include and <velocity> actuators stay <velocity> (the model is never re-saved)."""
    path = tmp_path / "boxbot.xml"
    path.write_text(INCLUDED_BOX)
    (tmp_path / "parts.xml").write_text(PARTS)
    assert calibrate.main([str(path), "--write", *FAST_CALIBRATION]) == 0
    assert "  xi_bar = 0.02 -> 0.005\n" in capsys.readouterr().out  # listed first
    text = path.read_text()
    assert (tmp_path / "parts.xml").read_text() == PARTS
    assert '<include file="parts.xml"/>' in text and "<general" not in text
    assert (
        text.replace('data="0.005"', 'data="0.02"').replace(
            re.search(r'\n *<numeric name="dftc_mismatch" data="[^"]+"/>', text).group(0), ""
        )
        == INCLUDED_BOX
    )  # every other byte as it was
    model = robots.get(str(path))
    assert model.xi_bar == 0.005 and 0 < model.mismatch < 0.005


@pytest.mark.parametrize("runs", ["0", "-3"])
def test_calibrate_refuses_fewer_than_one_drift_run_before_measuring(capsys, runs):
    """--runs 0 and --runs -3 measured one run and said "1 fault-free runs"."""
    assert calibrate.main(["disk", "--runs", runs]) == 2
    out, err = capsys.readouterr()
    assert err == f"error: --runs: expected at least 1 fault-free run, got {runs}\n"
    assert not out  # nothing measured


def test_calibrate_applies_set_to_every_measurement(capsys):
    """--set reaches the compensation check and the detectability line, not only the
    drift runs: at G = 0.02 the diffdrive's loop is calm and paper_case with block_row
    detects far smaller faults than with eq. 40."""
    args = ["diffdrive", "--runs", "1", "--set", "gains.G=0.02"]
    assert calibrate.main([*args, "--set", 'onboard.thresholds="block_row"']) == 0
    out = capsys.readouterr().out
    assert "compensation loop (G = 0.02 I)" in out and "does not ring" in out
    assert "thresholds (block_row)" in out
    assert calibrate.main(["diffdrive", "--set", "gains.nope=1"]) == 2  # before measuring
    assert "gains.nope" in capsys.readouterr().err


def test_calibrate_writes_an_mjcf_saved_by_mjspec(tmp_path):
    """Bug 2: a regex missed the size attribute MjSpec writes and duplicated the entry."""
    spec = mujoco.MjSpec.from_string(POSITION_BOX)
    spec.add_numeric(name="dftc_xi_bar", data=[0.005])
    path = tmp_path / "saved.xml"
    path.write_text(spec.to_xml())
    assert 'size="1"' in path.read_text()
    assert calibrate.main([str(path), "--write"]) == 0
    again = mujoco.MjSpec.from_file(str(path))
    assert [n.name for n in again.numerics].count("dftc_xi_bar") == 1
    assert robots.get(str(path)).mismatch > 0


def test_calibrate_finds_a_ringing_compensation_loop_and_the_gain_that_calms_it():
    ring = calibrate.compensation("diffdrive")
    assert ring[0].rings and ring[0].phi_p99 > 5 * ring[0].ideal  # G = 0.01: it rings
    assert not ring[-1].rings and ring[-1].G > 0.01
    calm = calibrate.compensation("disk")
    assert len(calm) == 1 and not calm[0].rings


def test_calibration_separates_start_up_jumps_and_saturation():
    prog = calibrate.programme(limit=0.25)
    assert np.abs(prog.u).max() <= 0.8 * 0.25 + 1e-12  # within the command range
    mismatch = np.full(len(prog.u), 0.001)
    mismatch[:50] = 0.3  # a robot that drops onto its wheels for 0.5 s
    for j in prog.jumps:
        mismatch[j : j + 150] = 0.2  # and takes 1.5 s to follow a jump
    clamped = np.zeros(len(prog.u), bool)
    clamped[prog.startup + 100 : prog.startup + 110] = True
    cal = calibrate._analyse("x", prog, mismatch, clamped, 0.25)
    assert cal.startup_time == pytest.approx(0.5) and cal.startup_mismatch == 0.3
    assert cal.response_time == pytest.approx(1.5)
    assert cal.smooth_max == 0.001 and cal.recommended_xi_bar == 0.005
    assert any("clamped" in n for n in cal.notes)


# --------------------------------------------------------------------------- before the run


def test_a_big_footprint_raises_the_activation_distance_with_the_safe_distance():
    """Bug 3: d was raised for the footprint but the activation distance was not."""
    holo = robots.get(str(HOLOBASE))
    s = scenario.load("paper_case")
    cfg = assembly.team_config(s, holo)
    d = 0.12 + holo.footprint_radius + checks.CLEARANCE
    np.testing.assert_allclose(cfg.obstacle_safe, d)
    np.testing.assert_allclose(cfg.obstacle_activation - cfg.obstacle_safe, 0.45 - 0.37)


def _refusals(overrides, robot="disk"):
    s = scenario.load_scenario("paper_case", {"team.robot_model": robot, **overrides})
    with pytest.raises(ScenarioError) as info:
        loop.Simulation(s)
    return str(info.value).splitlines()


def test_impossible_set_ups_are_refused_before_simulating():
    lines = _refusals({}, str(HOLOBASE))  # paper_case as it is, with a 0.64 m robot
    assert any("mission.formation.side" in ln and "use side >= 0.66" in ln for ln in lines)
    assert any("team.initial_positions" in ln and "hulls overlap" in ln for ln in lines)
    inside = _refusals(
        {
            "team.initial_positions": [[1.2, 0.55], [0.1, -0.45], [0.35, 0.1], [-0.1, 0.4]],
            "fdir.initial_error_bound": "auto",  # 1 m is below this start: refused too
        }
    )
    assert inside == [
        f"{scenario.resolve('paper_case')}: team.initial_positions: robot 1 starts with its hull "
        "0.170 m inside cylinder 1 (its footprint radius is 0.100 m); move it or the cylinder"
    ]
    assert (
        "beyond the disk robots' command range" in _refusals({"mission.centroid.speed": 100.0})[0]
    )
    assert (
        "no actuator offset produces that"
        in _refusals({"faults": [{"robot": 1, "kind": "bias", "t": 5.0, "value": [1e6, 0.0]}]})[0]
    )
    ring = {"family": "ring_chords", "chords": [2]}
    lines = _refusals(  # a log that does not fit: one line, with the estimate
        {
            "team.robots": 1000,
            "team.initial_positions": {"layout": "formation"},
            "mission.formation": {"shape": "grid", "side": 0.5},
            "team.graph": ring,
            "duration": 1e9,
            "faults": [],
        }
    )
    assert len(lines) == 1 and "GB" in lines[0] and "reduce" in lines[0], lines
    with pytest.raises(ScenarioError, match=r"team\.robots: expected an integer <= 5000"):
        scenario.load_scenario("paper_case", {"team.robots": 100_000, "team.graph": ring})


def test_what_can_run_but_deserves_a_look_is_warned_about(tmp_path):
    uncalibrated = robot_file(tmp_path, HOLO_FILE)  # the test model, without [calibration]
    s = scenario.load_scenario(
        "paper_case",
        {
            **BIG,
            "team.robot_model": str(uncalibrated),
            "mission.formation.side": 0.7,
            "faults": [{"robot": 2, "kind": "bias", "t": 0.5, "value": [0.95, 0.0]}],
        },
    )
    with loop.Simulation(s) as sim:
        warnings = [e["message"] for e in sim.events.items if e["kind"] == "warning"]
    assert any("safe_distance: raised from 0.37 to 0.461" in w for w in warnings)
    assert any("may run into a teammate" in w for w in warnings)  # the squeeze at a cylinder
    assert any("cannot be compensated" in w for w in warnings)  # 0.95 + 0.1 > 1 m/s
    assert any("bot model is not calibrated" in w for w in warnings)


# --------------------------------------------------------------------------- the paper's outcome


def _outcome(r):
    out = r.summary
    d1 = [d for d in out["detections"] if d["robot"] == 1]
    assert sorted(d["by"] for d in d1) == [1, 2, 3, 4]  # flagged by every teammate
    assert out["detections"] == d1  # nobody else flagged
    assert [e["robot"] for e in out["exclusions"]] == [1]
    tri = r.log["x"][-1, 1:]
    sides = np.linalg.norm(tri - np.roll(tri, -1, axis=0), axis=1)
    assert np.all(np.abs(sides - 1.0) <= 0.02), sides  # a triangle formed
    assert out["min_obstacle_clearance"] > 0.0  # no hull inside a cylinder
    assert out["margin"] < 1


def test_a_published_style_holonomic_base_gives_the_paper_outcome(tmp_path):
    """The paper's outcome with the project's own model of a position-servo base."""
    out = tmp_path / "run"
    args = [
        "paper_case",
        "--robot",
        str(HOLOBASE),
        "--out",
        str(out),
        "--no-video",
        "--no-progress",
    ]
    for k, v in TIGHT.items():
        args += ["--set", f"{k}={json.dumps(v) if not isinstance(v, dict) else _inline(v)}"]
    assert run.main(args) == 0
    r = scenario.load_scenario(out / "scenario.toml")
    assert r.team.robot_model == str(HOLOBASE.resolve())
    from dftc_mujoco import open_run

    _outcome(open_run(out))


def test_a_mobile_manipulator_gives_the_paper_outcome_with_its_calibrated_gain():
    arm = robots.get(str(MOBILEARM))
    G = arm.calibration["compensation_G"]
    assert G == 0.05  # calibrate: the paper's G = 0.01 makes this robot's compensation ring
    s = scenario.load_scenario(
        "paper_case", {**TIGHT, "team.robot_model": str(MOBILEARM), "gains.G": G}
    )
    _outcome(loop.simulate(s))


def _inline(d):
    return "{" + ", ".join(f"{k} = {json.dumps(v)}" for k, v in d.items()) + "}"


def test_the_drift_split_keeps_slow_drift_and_bounds_jumps():
    h, xi = 0.01, 0.005
    t = np.arange(300) * h
    slow = np.stack([0.003 * t, 0.0 * t], axis=1)  # 3 mm/s: within ξ̄, all slow
    assert calibrate.split_drift(slow, h * xi).max() < 1e-12
    jump = slow + np.where(t[:, None] >= 1.0, [0.0, 0.005], 0.0)  # a lag turns a jump into 5 mm
    off = calibrate.split_drift(jump, h * xi)
    assert off.max() == pytest.approx(0.005, abs=1e-4) and off[-1] < 1e-12  # then caught up


def test_the_disk_drifts_by_a_few_millimetres_in_paper_case():
    d = calibrate.drift("disk", runs=1)
    assert d.period_max > 0.1  # per period the drift is far beyond h ξ̄ (compensation, start-up)
    # a bounded offset, the start-up's no larger since the start is ramped (1 m/s² during
    # the path's ramp: 4.4 mm with the disk's 16 m/s² acceleration from rest, 7.6 mm with
    # none)
    assert d.drift_bound < 0.003 and d.startup <= d.drift_bound + 1e-9
    jumped = calibrate.drift("disk", overrides={"fdir.start_ramp": False}, runs=1)
    assert 0.004 < jumped.startup


def test_a_diffdrive_whose_wheels_do_not_share_an_axle_is_refused(tmp_path):
    """Two wheels whose axes are 60° apart (an omni-wheel base) do not follow a differential
    drive's kinematics: refused in one line."""
    folder = tmp_path / "mobilearm"
    shutil.copytree(MOBILEARM.parent / "mobilearm", folder)
    xml = folder / "mobilearm.xml"
    text = xml.read_text()
    straight = 'name="left_wheel_joint" class="wheel" axis="0 1 0"'
    assert straight in text
    turned = 'name="left_wheel_joint" class="wheel" axis="0.866 0.5 0"'  # 60° off the axle
    xml.write_text(text.replace(straight, turned))
    robot_file = tmp_path / "mobilearm.robot.toml"
    robot_file.write_text(MOBILEARM.read_text())
    with pytest.raises(ScenarioError) as e:
        robots.get(str(robot_file))
    msg = str(e.value)
    assert "diffdrive.left" in msg and "60° from the line joining the two wheels" in msg
    assert "\n" not in msg
    xml.write_text(text)  # the original axles: accepted
    assert robots.get(str(robot_file)).drive == "diffdrive"


OMNIBASE = ROBOTS / "omni.robot.toml"


def _legs(robot: robots.RobotModel, seconds: float) -> tuple[dict[float, np.ndarray], float]:
    """Drive one robot alone at 0.2 m/s along x for 2 s, along y for 2 s, then diagonally
    (0.15, -0.15): where its control point is every period (from its start) and how far it
    turned at most [°]."""
    sc = scene.compose(robot, np.zeros((1, 2)))
    data = Plant.initial_data(sc)
    d = robot.adapter(sc, data)
    x0 = data.site_xpos[sc.site[0], :2].copy()
    marks, turned = {}, 0.0
    for _ in range(round(seconds / 0.01)):
        t = data.time
        u = [[0.2, 0.0]] if t < 2.0 else ([[0.0, 0.2]] if t < 4.0 else [[0.15, -0.15]])
        data.ctrl[d.controlled()[0]] = d.command(np.array(u))[0]
        mujoco.mj_step(sc.model, data, nstep=5)
        mat = data.xmat[sc.body[0]]
        turned = max(turned, abs(np.degrees(np.arctan2(mat[3], mat[0]))))
        marks[round(data.time, 2)] = data.site_xpos[sc.site[0], :2] - x0
    return marks, turned


def _paper_outcome(robot_file: Path, rule: str, within: float) -> None:
    """paper_case on the robot (its calibration in its file) with threshold rule ``rule``:
    robot 1's stop at 41.8 s flagged by all four within ``within`` s, robot 1 alone
    excluded, nobody else flagged, every premise held."""
    over = {"team.robot_model": str(robot_file), "onboard.thresholds": rule}
    r = loop.simulate(scenario.load_scenario("paper_case", overrides=over), progress=False)
    flags = [(e["by"], e["robot"], e["t"]) for e in r.events.items if e["kind"] == "detection"]
    assert sorted(b for b, k, _ in flags) == [1, 2, 3, 4] and all(k == 1 for _, k, _ in flags)
    assert all(41.8 < t < 41.8 + within for _, _, t in flags)
    assert [e["robot"] for e in r.events.items if e["kind"] == "exclusion"] == [1]
    assert all(p["held"] for p in r.summary["premises"].values())


def test_an_omni_base_is_read_from_its_wheels():
    """drive = "omni" classifies each wheel from the compiled model: its position
    from the base, the direction a positive turn rolls the base (axle × z), its radius (the
    rollers' envelope)."""
    r = robots.get(str(OMNIBASE))
    p = r.params
    assert r.drive == "omni" and r.root == "free" and p["wheels"] == 3
    for k in range(3):
        theta = np.pi / 2 + 2 * np.pi * k / 3
        np.testing.assert_allclose(
            [p[f"wheel{k}_x"], p[f"wheel{k}_y"]],
            0.09 * np.array([np.cos(theta), np.sin(theta)]),
            atol=1e-6,
        )
        # the axle is radial: the wheel rolls the base along the tangent
        np.testing.assert_allclose(
            [p[f"wheel{k}_dx"], p[f"wheel{k}_dy"]], [np.sin(theta), -np.cos(theta)], atol=1e-6
        )
        assert p[f"wheel{k}_r"] == pytest.approx(0.0356, abs=5e-4)


def test_an_omni_base_goes_where_it_is_told_and_keeps_its_heading():
    """Physics: 0.2 m/s along x for 2 s, then along y for 2 s; the base moves 0.4 m each way
    (within its start-up) without turning."""
    marks, turned = _legs(robots.get(str(OMNIBASE)), 4.0)
    np.testing.assert_allclose(marks[4.0], [0.4, 0.4], atol=0.03)
    assert turned < 1.0


def test_omni_wheels_that_cannot_move_the_base_everywhere_are_refused(tmp_path):
    """Three wheels whose axles are all parallel roll the base along one line only: refused
    in one line, as are fewer than three wheels."""
    folder = tmp_path / "omnibase"
    shutil.copytree(OMNIBASE.parent / "omnibase", folder)
    xml = folder / "omnibase.xml"
    text = xml.read_text()
    xml.write_text(re.sub(r'euler="0 0 [-0-9.]+"', 'euler="0 0 90"', text))
    robot_file = tmp_path / "omnibase.robot.toml"
    robot_file.write_text(OMNIBASE.read_text())
    with pytest.raises(ScenarioError) as e:
        robots.get(str(robot_file))
    assert "omni.wheels: these wheels cannot move the base in every planar direction" in str(
        e.value
    )
    xml.write_text(text)
    two = OMNIBASE.read_text().replace('["wheel0", "wheel1", "wheel2"]', '["wheel0", "wheel1"]')
    robot_file.write_text(two)
    with pytest.raises(ScenarioError, match=r"omni\.wheels: expected three or more wheels, got 2"):
        robots.get(str(robot_file))


def test_the_paper_case_on_omni_wheels():
    """paper_case on the omni base (its calibration in the robot file) with block_row:
    robot 1's stop is flagged by all four and robot 1 alone is excluded; nobody else is
    flagged and every premise holds."""
    _paper_outcome(OMNIBASE, "block_row", within=2.5)


MECANUM = ROBOTS / "mecanum.robot.toml"


def test_mecanum_wheels_are_read_with_their_rollers_and_drive_the_base_sideways():
    """drive = "omni" covers mecanum wheels: the axis of the roller at the floor (45° from
    the rim) is read from the model, and the map divides by ρ·d. Physics: 0.2 m/s along x,
    then along y, then diagonally; the base follows and keeps its heading."""
    r = robots.get(str(MECANUM))
    p = r.params
    for k in range(4):
        assert [p[f"wheel{k}_dx"], p[f"wheel{k}_dy"]] == pytest.approx([1.0, 0.0], abs=1e-6)
        assert abs(p[f"wheel{k}_rx"]) == pytest.approx(np.sqrt(0.5), abs=1e-3)
        assert abs(p[f"wheel{k}_ry"]) == pytest.approx(np.sqrt(0.5), abs=1e-3)
    assert p["wheel0_ry"] == pytest.approx(-p["wheel1_ry"])  # an X seen from above
    marks, turned = _legs(r, 6.0)
    np.testing.assert_allclose(marks[2.0], [0.4, 0.0], atol=0.02)
    np.testing.assert_allclose(marks[4.0] - marks[2.0], [0.0, 0.4], atol=0.03)
    np.testing.assert_allclose(marks[6.0] - marks[4.0], [0.3, -0.3], atol=0.03)
    assert turned < 2.0  # degrees, at the command switches


def test_plain_wheels_are_not_omni_wheels(tmp_path):
    """Rollers welded to their wheel (no hinge) cannot slide along the axle: refused."""
    folder = tmp_path / "omnibase"
    shutil.copytree(OMNIBASE.parent / "omnibase", folder)
    xml = folder / "omnibase.xml"
    xml.write_text(re.sub(r'<joint name="wheel\d_roller\d+"[^>]*/>', "", xml.read_text()))
    robot_file = tmp_path / "omnibase.robot.toml"
    robot_file.write_text(OMNIBASE.read_text())
    with pytest.raises(ScenarioError, match=r"omni\.wheels: wheel 'wheel0' has no free rollers"):
        robots.get(str(robot_file))


def test_the_paper_case_on_mecanum_wheels():
    """paper_case on the mecanum base (its calibration in the robot file) with l1: robot
    1's stop flagged by all four within a second, robot 1 alone excluded, premises held."""
    _paper_outcome(MECANUM, "l1", within=1.0)


SWERVE = ROBOTS / "swerve.robot.toml"


def test_swerve_modules_are_read_from_the_model_and_steer_where_they_are_told():
    """drive = "swerve": each module's steering axis, wheel direction and radius are read
    from the model; the base goes along x, then y, then diagonally, without turning."""
    r = robots.get(str(SWERVE))
    p = r.params
    assert r.drive == "swerve" and p["modules"] == 4
    corners = {(p[f"module{k}_x"], p[f"module{k}_y"]) for k in range(4)}
    assert corners == {(0.1, 0.1), (0.1, -0.1), (-0.1, 0.1), (-0.1, -0.1)}
    assert all(p[f"module{k}_r"] == pytest.approx(0.035, abs=1e-4) for k in range(4))
    marks, turned = _legs(r, 6.0)
    # each leg loses a little while the modules turn to their new direction
    np.testing.assert_allclose(marks[2.0], [0.4, 0.0], atol=0.03)
    np.testing.assert_allclose(marks[4.0] - marks[2.0], [0.0, 0.4], atol=0.03)
    np.testing.assert_allclose(marks[6.0] - marks[4.0], [0.3, -0.3], atol=0.03)
    assert turned < 1.0


def test_the_paper_case_on_swerve_modules():
    """paper_case on the swerve base (its calibration in the robot file) with l1: robot 1's
    stop flagged by all four within 1.5 s, robot 1 alone excluded, premises held."""
    _paper_outcome(SWERVE, "l1", within=1.5)


def test_a_swerve_file_names_pairs_and_steers_about_the_vertical(tmp_path):
    folder = tmp_path / "swervebase"
    shutil.copytree(SWERVE.parent / "swervebase", folder)
    robot_file = tmp_path / "swervebase.robot.toml"
    robot_file.write_text(SWERVE.read_text().replace('["steer3", "drive3"]', '["steer3"]'))
    with pytest.raises(
        ScenarioError, match=r"swerve\.modules: expected a list of \[steer, drive\]"
    ):
        robots.get(str(robot_file))
    xml = folder / "swervebase.xml"
    xml.write_text(
        xml.read_text().replace('axis="0 0 1" damping="0.02"', 'axis="1 0 0" damping="0.02"')
    )
    robot_file.write_text(SWERVE.read_text())
    with pytest.raises(
        ScenarioError,
        match=r"swerve\.modules: joint 'steer0' turns about .* a module steers about the vertical",
    ):
        robots.get(str(robot_file))
