"""Robot models: the contract, the three models on physics, calibration, swapping in a new one."""

import json

import mujoco
import numpy as np
import pytest
import trimesh

from dftc_mujoco import calibrate, run, scenario
from dftc_mujoco.closed_loop import assembly, loop
from dftc_mujoco.errors import ScenarioError
from dftc_mujoco.runtime.paths import MODELS
from dftc_mujoco.sim import faults as sim_faults
from dftc_mujoco.sim import robots, scene
from dftc_mujoco.sim.plant import Plant
from tests.conftest import make, scenario_dict

BOX_ROBOT = """<mujoco model="boxbot">
  <custom>
    <text name="dftc_adapter" data="holonomic"/>
  </custom>
  <worldbody>
    <body name="base" pos="0 0 0.04">
      <joint name="x" type="slide" axis="1 0 0"/>
      <joint name="y" type="slide" axis="0 1 0"/>
      <geom name="hull" type="box" size="0.07 0.05 0.04" mass="1.5" rgba="0.2 0.45 0.85 1"/>
      <site name="center"/>
    </body>
  </worldbody>
  <actuator>
    <velocity name="vx" joint="x" kv="150" ctrlrange="-1 1" ctrllimited="true"/>
    <velocity name="vy" joint="y" kv="150" ctrlrange="-1 1" ctrllimited="true"/>
  </actuator>
</mujoco>
"""


def test_registry_lists_models_and_explains_unknown_names():
    names = ["diffdrive", "disk", "hexbot", "mecanum", "omni", "swerve"]
    assert robots.available() == names
    with pytest.raises(
        ScenarioError,
        match=r"unknown robot model 'tank' \(available: " + ", ".join(names),
    ):
        robots.get("tank")


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            lambda t: t.replace('<site name="center"/>', "").replace(
                "</worldbody>", '<site name="center"/></worldbody>'
            ),
            "site 'center' must be on body 'base'",
        ),
        (lambda t: t.replace('<site name="center"/>', ""), "no site named 'center'"),
        (
            lambda t: t.replace('data="holonomic"', 'data="legged"'),
            "dftc_adapter: expected one of holonomic, diffdrive",
        ),
        (lambda t: t.replace('name="vy"', 'name="vz"'), "missing: vy"),
        (lambda t: t.replace("<worldbody>", "<worldbody"), "MuJoCo cannot read bad.xml: XML"),
    ],
)
def test_contract_violations_are_one_clear_line(tmp_path, change, message):
    path = tmp_path / "bad.xml"
    path.write_text(change(BOX_ROBOT))
    with pytest.raises(ScenarioError, match=message) as info:
        robots.get(str(path))
    assert str(path) in str(info.value)


def test_mesh_robot_mass_inertia_and_footprint_come_from_the_mesh():
    hexbot = robots.get("hexbot")
    mesh = trimesh.load(MODELS / "robots" / "meshes" / "hexbot.stl", force="mesh")
    mesh.density = 1000.0
    assert hexbot.mass == pytest.approx(mesh.mass)
    assert np.allclose(hexbot.inertia, np.diag(mesh.moment_inertia))
    assert hexbot.footprint_radius == pytest.approx(
        np.hypot(mesh.vertices[:, 0], mesh.vertices[:, 1]).max()
    )
    sc = scene.compose(hexbot, np.zeros((2, 2)))
    body = sc.body[0]
    assert sc.model.body_mass[body] == pytest.approx(mesh.mass)
    assert np.allclose(sorted(sc.model.body_inertia[body]), sorted(hexbot.inertia))
    # obstacle avoidance keeps the mesh's footprint clear of a cylinder too close for it
    d = scenario_dict()
    d["obstacles"] = [
        {"position": [1, 1], "radius": 0.2, "safe_distance": 0.25, "activation_distance": 0.4}
    ]
    cfg = assembly.team_config(make(d), hexbot)
    assert cfg.obstacle_safe[0] == pytest.approx(0.2 + hexbot.footprint_radius + assembly.CLEARANCE)


def test_diffdrive_moves_only_through_wheel_contact():
    dd = robots.get("diffdrive")
    sc = scene.compose(dd, np.zeros((1, 2)))
    m = sc.model
    assert not any(m.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE for j in range(m.njnt))
    assert m.jnt_type[m.body_jntadr[sc.body[0]]] == mujoco.mjtJoint.mjJNT_FREE

    def drive(floor_friction):
        model = scene.compose(dd, np.zeros((1, 2))).model
        model.geom_friction[model.geom("floor").id] = floor_friction
        for g in range(model.ngeom):  # tyres use their own friction: make it the floor's
            if model.geom(g).name.endswith(("tyre_l", "tyre_r")):
                model.geom_friction[g] = floor_friction
                model.geom_priority[g] = 1
        data = Plant.initial_data(sc)
        start = data.site_xpos[sc.site[0], 0]
        adapter = dd.adapter(sc, data)
        for _ in range(200):
            data.ctrl[sc.actuator[0]] = adapter.command(np.array([[0.2, 0.0]]))[0]
            mujoco.mj_step(model, data, nstep=5)
        return data.site_xpos[sc.site[0], 0] - start

    assert drive([1.2, 0.01, 0.0005]) > 0.3  # 2 s at 0.2 m/s
    # next to no friction (none at all makes MuJoCo's contact solver unstable): no motion
    assert abs(drive([1e-4, 0.0, 0.0])) < 0.01  # the wheels spin in place


@pytest.mark.parametrize("offset", [0.22, 0.25, 0.28])
def test_a_diffdrive_that_glances_off_a_cylinder_stays_on_its_wheels(offset):
    """A tyre's corner reaches 9.7 cm from the centre, beyond the 9 cm hull: a diffdrive
    driven at 0.6 m/s past a cylinder that its left side meets used to run its tyre up the
    cylinder and tip (22° at 0.25 m, 56° at 0.28 m); half of the N >= 16 diffdrive runs of
    the untuned battery stopped so ("left the plane"). Its bumper covers the tyres: it stays
    level (the 2° of its casters at rest)."""
    from dftc_mujoco.scenario import Obstacle

    dd = robots.get("diffdrive")
    cylinder = Obstacle(np.array([0.45, offset]), 0.2, 0.5, 0.6)
    sc = scene.compose(dd, np.zeros((1, 2)), obstacles=(cylinder,))
    data = Plant.initial_data(sc)
    adapter = dd.adapter(sc, data)
    tilt = []
    for _ in range(200):  # 2 s at 0.6 m/s: past the cylinder, or pressed against it
        data.ctrl[sc.actuator[0]] = adapter.command(np.array([[0.6, 0.0]]))[0]
        mujoco.mj_step(sc.model, data, nstep=5)
        tilt.append(np.degrees(np.arccos(data.xmat[sc.body[0]][8])))
    assert max(tilt) < 3.0
    gap = np.hypot(*(data.xpos[sc.body[0], :2] - cylinder.position)) - 0.2
    assert gap > 0.09  # the bumper, not a tyre, met it


@pytest.mark.parametrize("kind", ["stop", "bias"])
def test_diffdrive_faults_act_on_the_wheels(kind):
    s = make(scenario_dict())
    dd = robots.get("diffdrive")
    sc = scene.compose(dd, np.asarray(s.team.initial_positions))
    data = Plant.initial_data(sc)
    adapter = dd.adapter(sc, data)
    inj = sim_faults.ActuatorFaults(
        sc.model, (scenario.Fault(1, kind, 1.0, np.array([0.1, -0.1]), 0.1),), adapter
    )
    vel = np.zeros(6)
    u = np.tile([0.15, 0.05], (4, 1))
    for k in range(400):
        inj.apply(k * 0.01)
        data.ctrl[sc.actuator.ravel()] = adapter.command(u).ravel()
        mujoco.mj_step(sc.model, data, nstep=5)
    v = []
    for site in sc.site:
        mujoco.mj_objectVelocity(sc.model, data, mujoco.mjtObj.mjOBJ_SITE, int(site), vel, 0)
        v.append(vel[3:5].copy())
    v = np.array(v)
    assert np.abs(v[[0, 2, 3]] - u[[0, 2, 3]]).max() < 0.01  # healthy ones follow u
    if kind == "stop":
        assert np.linalg.norm(v[1]) < 0.005  # wheels locked by the brakes
        assert np.allclose(sc.model.actuator_gainprm[sc.actuator[1], 0], 0.0)
    else:
        assert np.abs(v[1] - (u[1] + [0.1, -0.1])).max() < 0.01  # offset at the control point


@pytest.mark.parametrize("name", ["disk", "hexbot", "diffdrive"])
def test_calibration_measures_the_mismatch_stored_with_the_model(name):
    cal = calibrate.measure(name)
    model = robots.get(name)
    assert cal.smooth_max <= cal.all_max and cal.smooth_p99 <= cal.smooth_max
    assert cal.all_max > 0.1  # command jumps are far from an integrator
    assert model.mismatch == pytest.approx(cal.smooth_max, rel=1e-3)
    assert model.xi_bar == pytest.approx(cal.recommended_xi_bar)
    assert cal.recommended_xi_bar >= max(calibrate.PAPER_XI_BAR, cal.smooth_max)
    if name in ("disk", "hexbot"):
        assert cal.smooth_max < 0.003  # kv / m ≈ 100 1/s: a 10 ms lag (docs/notes.md, 14)


def test_calibrate_cli_writes_into_a_copy(tmp_path, capsys):
    path = tmp_path / "boxbot.xml"
    path.write_text(BOX_ROBOT)
    assert calibrate.main([str(path), "--write"]) == 0
    out = capsys.readouterr().out
    assert "smooth commands" in out and "recommended xi_bar" in out
    model = robots.get(str(path))
    assert 0 < model.mismatch < 0.005 and model.xi_bar == 0.005
    assert calibrate.main(["tank"]) == 2


def _run_diffdrive(tmp_path, name: str, section: str, key: str, value) -> None:
    """A 6 s fault-free diffdrive run through the CLI with ``[section] key = value`` into
    ``tmp_path / name`` (the run must succeed; its console output stays in capsys)."""
    d = scenario_dict()
    d[section][key] = value
    d["duration"] = 6.0
    d["faults"] = []
    d["team"]["robot_model"] = "diffdrive"
    path = tmp_path / f"{name}.toml"
    path.write_text(_toml(d))
    assert run.main([str(path), "--out", str(tmp_path / name), "--no-video", "--no-progress"]) == 0


def test_a_low_xi_bar_for_the_model_is_warned_about(tmp_path, capsys):
    _run_diffdrive(tmp_path, "o", "noise", "xi_bar", 0.005)
    out = capsys.readouterr().out
    assert "WARNING: noise.xi_bar = 0.005 m/s is below the diffdrive model's measured" in out
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["xi_bar"] == 0.005 and summary["xi_bar_source"] == "scenario"
    assert any("below the diffdrive model" in w for w in summary["warnings"])


def test_a_G_below_the_models_compensation_G_is_warned_about(tmp_path, capsys):
    """The campaigns drew the diffdrive under paper_case's explicit G = 0.01 (below its
    calibrated 0.02): its compensation loop rang, healthy φ̂ reached 4.8 m/s and healthy
    robots were excluded, with no word said. Now "auto" takes the robot's value and an
    explicit one below it is warned about before the run."""
    _run_diffdrive(tmp_path, "o", "gains", "G", 0.01)
    out = capsys.readouterr().out
    assert "WARNING: gains.G = 0.01 I is below the diffdrive model's calibrated" in out
    _run_diffdrive(tmp_path, "a", "gains", "G", "auto")
    assert "gains.G" not in capsys.readouterr().out


def _toml(d, prefix=""):
    """A tiny TOML writer for the scenario dicts used here."""
    lines, tables = [], []
    for k, v in d.items():
        if isinstance(v, dict):
            tables.append((k, v))
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            tables.append((k, v))
        else:
            lines.append(f"{k} = {json.dumps(v)}")
    for k, v in tables:
        name = f"{prefix}{k}"
        if isinstance(v, list):
            for item in v:
                lines.append(f"\n[[{name}]]")
                lines.append(_toml(item, f"{name}."))
        else:
            lines.append(f"\n[{name}]")
            lines.append(_toml(v, f"{name}."))
    return "\n".join(lines)


@pytest.mark.parametrize(("model", "G"), [("hexbot", 0.01), ("diffdrive", 0.02)])
def test_paper_case_outcome_with_every_robot_model(model, G):
    """paper_case with each built-in model runs at the G its calibration recommends
    (``gains.G = "auto"``; the paper's 0.01 makes the diffdrive's compensation loop ring)."""
    assert robots.get(model).calibration["compensation_G"] == G
    s = scenario.load_scenario("paper_case", {"team.robot_model": model})
    assert s.gains.G is None and (assembly.effective_G(s, robots.get(model)) == G * np.eye(2)).all()
    r = loop.simulate(s)
    out = r.summary
    assert out["status"] == "ok" and out["warnings"] == []
    d1 = [d for d in out["detections"] if d["robot"] == 1]
    # the diffdrive moves within 10.5 mm/s of its command, twice the paper's ξ̄, and its
    # drive's lag is calibrated: the rule chosen for it is the drive rule (with eq. 40,
    # robots 1 and 2's thresholds widened by ξ̄, only robots 3 and 4 flagged the stop)
    assert out["onboard"]["blocks"]["thresholds"] == ("paper" if model == "hexbot" else "drive")
    assert sorted(d["by"] for d in d1) == [1, 2, 3, 4]
    assert out["detections"] == d1  # nobody else flagged
    assert [e["robot"] for e in out["exclusions"]] == [1]
    tri = r.log["x"][-1, 1:]
    sides = np.linalg.norm(tri - np.roll(tri, -1, axis=0), axis=1)
    assert np.all(np.abs(sides - 0.5) <= 0.02), sides
    assert out["min_obstacle_clearance"] > 0.0  # no hull ever touches a cylinder
    assert out["margin"] < 1


def test_a_fourth_model_from_an_mjcf_file(tmp_path):
    """The recipe of docs/guide/robots.md: write a robot file, calibrate it, run paper_case."""
    path = tmp_path / "boxbot.xml"
    path.write_text(BOX_ROBOT)
    assert calibrate.main([str(path), "--write"]) == 0
    out = tmp_path / "run"
    code = run.main(
        [
            "paper_case",
            "--robot",
            str(path),
            "--duration",
            "44",
            "--out",
            str(out),
            "--no-video",
            "--no-progress",
        ]
    )
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["robot_model"] == str(path)
    assert {d["robot"] for d in summary["detections"]} <= {1}
    assert summary["min_obstacle_clearance"] > 0.0


def test_a_path_faster_than_the_applied_range_is_flown_slower_and_said_so():
    """The battery's diffdrives at 0.6 m/s: within the 0.7 m/s command range but beyond the
    0.42 m/s the applied input keeps after the compensation's headroom (the drive rule's
    Φ̄, which "auto" chooses for the calibrated diffdrive), so every command
    stayed saturated and a healthy robot was excluded; then such runs were refused (a
    quarter of drivable set-ups). Now the path governor flies it at 95 % of the applied
    range, says so, and records both speeds: the commands stay inside the range (premise
    'saturation' held) and robot 1's stop is excluded. Beyond the command range a path is
    still refused."""
    s = scenario.load_scenario(
        "paper_case",
        {
            "team.robot_model": "diffdrive",
            "mission.centroid.speed": 0.6,
            "duration": 20.0,
            "faults": [{"robot": 1, "kind": "stop", "t": 8.0}],  # the team still on its way
        },
    )
    r = loop.simulate(s)
    flown = pytest.approx(0.95 * 0.42417, rel=1e-4)
    assert r.summary["mission_speed"] == {"asked": 0.6, "flown": flown}
    assert r.scenario.mission.centroid.speed == r.summary["mission_speed"]["flown"]
    (said,) = [w for w in r.summary["warnings"] if "mission.centroid.speed" in w]
    assert "diffdrive robots no room in their applied range of ±0.424 m/s" in said
    assert r.summary["premises"]["saturation"]["held"]
    assert [e["robot"] for e in r.summary["exclusions"]] == [1]
    assert r.summary["healthy_exclusions"] == 0
    beyond = scenario.load_scenario(
        "paper_case", {"team.robot_model": "diffdrive", "mission.centroid.speed": 0.8}
    )
    with pytest.raises(ScenarioError, match="beyond the diffdrive robots' command range") as no:
        loop.simulate(beyond)
    # the refusal names the fix, and the speed it suggests runs as given (not governed)
    fix = str(no.value).split("(mission.centroid.speed = ")[1].rstrip(")")
    assert float(fix) <= 0.95 * 0.42417
    kept = scenario.load_scenario(
        "paper_case",
        {"team.robot_model": "diffdrive", "mission.centroid.speed": float(fix), "duration": 1.0},
    )
    assert loop.simulate(kept).summary["mission_speed"]["flown"] == float(fix)


@pytest.mark.parametrize("name", ["hexbot", "diffdrive"])
def test_robots_attached_in_groups_make_the_same_model(name, monkeypatch):
    """The scene attaches robots into small specs of scene.GROUP first (attach_body costs in
    proportion to the spec it attaches into: 1.8 s for 1000 robots one by one, 0.16 s in
    groups): the compiled model is the same, array for array and name for name, whatever
    the group size (1: every robot through its own group; 7: groups and a remainder)."""
    robot = robots.get(name)
    pos = np.array([[(i % 5) * 2.0, (i // 5) * 2.0] for i in range(15)])
    models = []
    for group in (1, 7, 64):
        monkeypatch.setattr(scene, "GROUP", group)
        models.append(scene.compose(robot, pos).model)
    arrays = [
        a
        for a in dir(models[0])
        if not a.startswith("_") and isinstance(getattr(models[0], a), np.ndarray)
    ]
    assert len(arrays) > 100
    for m in models[1:]:
        assert m.names == models[0].names
        for a in arrays:
            if a == "mesh_pathadr":  # where a mesh's file path is stored, not the mesh
                continue
            assert np.array_equal(getattr(m, a), getattr(models[0], a), equal_nan=True), a
    assert mujoco.mj_name2id(models[0], mujoco.mjtObj.mjOBJ_BODY, f"robot15/{robot.base}") > 0


def test_the_team_s_start_state_and_roots_are_a_walk_robot_by_robot():
    """The scene finds every robot's start state (its keyframe on its own joints, a free
    base left where its MJCF puts it, its actuators' ctrl) and how to re-pose its base in
    array passes over the whole team: the numbers a walk robot by robot gives, for a
    mixed team of slides and a hinge, a free base, omni wheels and the disk."""
    from pathlib import Path

    from dftc_mujoco import load_scenario
    from dftc_mujoco.sim import fleet, tree

    data = Path(__file__).parent / "data" / "robots"
    team = [str(data / "holobase.robot.toml"), "diffdrive", "omni"]
    s = load_scenario("paper_case", {"team.robot_model": [*team, "disk"]})
    s, models = fleet.for_scenario(s)
    sc = scene.build(s, models)
    m = sc.model
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    qpos, ctrl = m.qpos0.copy(), np.zeros(m.nu)
    owner = tree.owners(m, sc.body)
    on = tree.actuator_bodies(m)
    root = np.full((4, 3), -1)
    sense = np.ones((4, 3))
    for i, (b, robot) in enumerate(zip(sc.body, models.models, strict=True)):
        mine = [j for j in range(m.njnt) if owner[m.jnt_bodyid[j]] == i]
        adr = np.concatenate([np.arange(m.jnt_qposadr[j], m.jnt_qposadr[j] + {0: 7, 1: 4}.get(
            int(m.jnt_type[j]), 1)) for j in mine])  # fmt: skip
        qpos[adr] = robot.init_qpos
        for j in mine:
            if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
                a = m.jnt_qposadr[j]
                qpos[a : a + 7] = m.qpos0[a : a + 7]
        ctrl[[a for a in range(m.nu) if on[a] >= 0 and owner[on[a]] == i]] = robot.init_ctrl
        for j in range(m.body_jntadr[b], m.body_jntadr[b] + m.body_jntnum[b]):
            hinge = m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE
            if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
                root[i] = [m.jnt_qposadr[j], scene.FREE_ROW, scene.FREE_ROW]
                break
            if hinge and abs(d.xaxis[j][2]) < 0.999:
                continue
            col = 2 if hinge else int(np.argmax(np.abs(d.xaxis[j][:2])))
            root[i, col], sense[i, col] = m.jnt_qposadr[j], np.sign(d.xaxis[j][col])
    yaw = [np.arctan2(d.xmat[b][3], d.xmat[b][0]) for b in sc.body]
    assert np.array_equal(sc.qpos_init, qpos) and np.array_equal(sc.ctrl_init, ctrl)
    assert np.array_equal(sc.root_qpos, root)
    assert (sc.root_qpos[:, 1] == scene.FREE_ROW).sum() == 2  # diffdrive, omnibase: free
    assert np.array_equal(sc.origin, np.hstack([d.xpos[sc.body], np.c_[yaw], sense]))
    assert np.array_equal(tree.qpos_addresses(m, np.arange(m.njnt)), np.arange(m.nq))
