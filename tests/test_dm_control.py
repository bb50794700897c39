"""The scene in dm_control: ``Physics.from_xml_string(sim.scene_xml())`` loads the scene of
each built-in robot and, driven by the commands the simulator applied, steps to the very
positions the simulator's own MuJoCo model reached."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

dm_mujoco = pytest.importorskip(
    "dm_control.mujoco", reason="dm_control is not installed (the rl extra: pip install -e '.[rl]')"
)

from dftc_mujoco import Simulation, load_scenario  # noqa: E402
from dftc_mujoco.sim.mjcf import START_KEY  # noqa: E402

PERIODS = 60  # 0.6 s of paper_case: 300 MuJoCo steps of 2 ms


@pytest.mark.parametrize("robot", ["disk", "hexbot", "diffdrive"])
def test_physics_steps_the_scene_as_the_simulator_does(robot):
    applied = []  # after each control period: the commands it applied and where it left

    def hook(t, plant):
        applied.append((plant.data.ctrl.copy(), plant.data.qpos.copy()))

    with Simulation(load_scenario("paper_case", {"team.robot_model": robot}), hook=hook) as sim:
        xml = sim.scene_xml()
        substeps = sim.scenario.physics.substeps
        start = sim.scene.qpos_init.copy()
        assert isinstance(sim.scene.spec, mujoco.MjSpec)
        sim.step(PERIODS)
    physics = dm_mujoco.Physics.from_xml_string(xml)  # meshes too: the hexbot is an STL
    assert physics.model.id2name(0, "key") == START_KEY
    physics.reset(0)  # the keyframe: every robot where the run starts
    np.testing.assert_array_equal(physics.data.qpos, start)
    for ctrl, qpos in applied:
        physics.data.ctrl[:] = ctrl
        physics.step(substeps)
        np.testing.assert_array_equal(physics.data.qpos, qpos)  # bit for bit
    assert len(applied) == PERIODS
    assert np.abs(qpos - start).max() > 0.05  # the robots moved: a test of something


def test_the_text_loads_in_mujoco_as_the_same_model():
    """Every number of the compiled model is the simulator's (none rounded by the writer)."""
    with Simulation(load_scenario("paper_case", {"team.robot_model": "hexbot"})) as sim:
        ours = sim.model
        other = mujoco.MjModel.from_xml_string(sim.scene_xml())
        for name in ("body_mass", "body_inertia", "body_ipos", "body_pos", "geom_size", "opt"):
            a, b = getattr(ours, name), getattr(other, name)
            if name == "opt":
                assert a.timestep == b.timestep and a.integrator == b.integrator
            else:
                np.testing.assert_array_equal(a, b, err_msg=name)


def test_a_team_attached_in_many_groups_loads():
    """Past 32 robots the scene attaches them in groups, each bringing a default class of
    the same name: the text names each once, and it loads."""
    from dftc_mujoco.sim import robots, scene
    from dftc_mujoco.sim.mjcf import scene_xml

    positions = np.array([[0.5 * (i % 7), 0.5 * (i // 7)] for i in range(40)])
    made = scene.compose(robots.get("disk"), positions)
    physics = dm_mujoco.Physics.from_xml_string(scene_xml(made))
    assert physics.model.nbody == made.model.nbody == 41
    np.testing.assert_array_equal(physics.model.body_pos, made.model.body_pos)


def test_make_dm_env_is_a_dm_control_environment_over_the_simulation():
    """make_dm_env is dm_control's rl.control.Environment: its Physics is the simulation's
    own MjData (a step is one control period), its Task observes the driven robot in named
    fields and ends an excluded robot's episode with discount 0; the same seed replays an
    episode and the Physics renders the team."""
    from dm_control.rl import control

    from dftc_mujoco.envs import make_dm_env
    from dftc_mujoco.envs.dm import HoldSlotTask, TeamPhysics
    from dftc_mujoco.envs.seat import FIELDS

    def episode(env, policy, limit=10_000):
        step, seen = env.reset(), []
        while not step.last() and len(seen) < limit:
            seen.append(np.concatenate(list(step.observation.values())))
            step = env.step(policy(env))
        return step, np.array(seen)

    env = make_dm_env("paper_case", robot=2, seed=4, overrides={"duration": 0.5})
    assert isinstance(env, control.Environment)
    assert isinstance(env.physics, TeamPhysics) and isinstance(env.task, HoldSlotTask)
    assert env.physics.data.ptr is env.physics.seats.sim.data
    assert env.physics.timestep() == 0.01
    assert list(env.observation_spec()) == [name for name, *_ in FIELDS]
    last, a = episode(env, lambda e: np.zeros(2))
    assert last.discount == 1.0 and len(a) == 50  # truncated at the duration
    assert env.physics.seats.sim.t == pytest.approx(0.5)
    frame = env.physics.render(height=48, width=64)
    assert frame.shape == (48, 64, 3) and frame.std() > 0
    _, b = episode(make_dm_env("paper_case", robot=2, seed=4, overrides={"duration": 0.5}),
                   lambda e: np.zeros(2))  # fmt: skip
    np.testing.assert_array_equal(a, b)
    # a robot held still from 2 s is flagged and excluded by its teammates: discount 0
    s = load_scenario("paper_case", {"duration": 20.0, "faults": []})
    env = make_dm_env(s, robot=2, seed=1)

    def still(e):
        seats = e.physics.seats
        return np.zeros(2) if seats.sim.t >= 2.0 else seats.sim.team.u_bar[1]

    last, _ = episode(env, still)
    assert last.discount == 0.0 and env.physics.seats.sim.t < 20.0
