"""The team as an environment (dftc_mujoco/envs): each ecosystem's own checker and rules
(truncation, termination, seeding, rendering, registration), the observation, the fault
labels, and a policy that misbehaves flagged and excluded by the team."""

from __future__ import annotations

import subprocess
import sys
import unittest
from pathlib import Path

import numpy as np
import pytest

gymnasium = pytest.importorskip(
    "gymnasium", reason="the rl extra is not installed (pip install -e '.[rl]')"
)
pytest.importorskip("pettingzoo", reason="the rl extra is not installed")
dm_env = pytest.importorskip("dm_env", reason="the rl extra is not installed")
dm_test_utils = pytest.importorskip("dm_env.test_utils", reason="the rl extra is not installed")

from dftc_mujoco import load_scenario  # noqa: E402
from dftc_mujoco.envs import IDS, make_dm_env, make_gym, make_parallel  # noqa: E402
from dftc_mujoco.envs.seat import FIELDS  # noqa: E402
from tests.conftest import needs_gl  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def _short(duration: float = 0.5, **more):
    return load_scenario("paper_case", {"duration": duration, "faults": [], **more})


def _episode(env, seed, policy=None, steps=None):
    """Observations of an episode (all of it, or ``steps``), with ``policy(obs, info)``
    (default: the team's own command)."""
    obs, info = env.reset(seed=seed)
    seq, k, term, trunc = [obs], 0, False, False
    while not (term or trunc) and (steps is None or k < steps):
        act = policy(obs, info) if policy else info["dftc_command"]
        obs, _, term, trunc, info = env.step(act)
        seq.append(obs)
        k += 1
    return np.array(seq), term, trunc, info


@needs_gl
def test_the_gymnasium_env_passes_gymnasiums_checker_with_its_renderer():
    from gymnasium.utils.env_checker import check_env

    over = {"duration": 0.5, "faults": []}
    env = gymnasium.make("dftc/PaperCase-v0", render_mode="rgb_array", overrides=over)
    try:
        check_env(env.unwrapped)  # the render modes too, through the id's spec
        env.reset(seed=0)
        frame = env.render()
        assert frame.shape == (360, 480, 3) and frame.dtype == np.uint8
        assert frame.reshape(-1, 3).std(axis=0).max() > 5  # a picture, not a blank
    finally:
        env.close()


def test_the_parallel_env_passes_pettingzoos_api_and_seed_tests():
    from pettingzoo.test import parallel_api_test, parallel_seed_test

    env = make_parallel(_short(), robots=[1, 3])
    try:
        parallel_api_test(env, num_cycles=80)
        assert env.possible_agents == ["robot_1", "robot_3"]
    finally:
        env.close()
    parallel_seed_test(lambda: make_parallel(_short(0.2), robots=[1, 3]), num_cycles=15)


class TestDmEnv(dm_test_utils.EnvironmentTestMixin, unittest.TestCase):
    """dm_env's own test mixin (reset, step, specs, episode ends)."""

    def make_object_under_test(self):
        return make_dm_env(_short(0.3), robot=1, seed=3)

    def make_action_sequence(self):
        for _ in range(40):  # past the end of the 0.3 s episode (30 periods)
            yield np.zeros(2)


def test_the_time_limit_is_a_truncation_everywhere():
    """The scenario's duration ends an episode as truncated (terminated stays False: the
    value of the state goes on); dm_env's last step keeps discount 1."""
    seq, term, trunc, _ = _episode(make_gym(_short(0.3), robot=2), seed=1)
    assert (term, trunc) == (False, True) and len(seq) == 32  # periods at t = 0 .. 0.30 s
    env = make_dm_env(_short(0.3), robot=2, seed=1)
    step = env.reset()
    while not step.last():
        step = env.step(np.zeros(2))
    assert step.discount == 1.0 and step.step_type == dm_env.StepType.LAST
    par = make_parallel(_short(0.3), robots=[1, 2])
    par.reset(seed=1)
    while par.agents:
        _, _, terms, truncs, _ = par.step({a: np.zeros(2) for a in par.agents})
    assert not any(terms.values()) and all(truncs.values())


def test_seeded_resets_repeat_and_unseeded_ones_continue_the_stream():
    """Gymnasium's convention: the same seed gives the same episode; reset() without one
    draws the next episode of the stream (it replayed the last seeded episode bit for bit,
    so every training episode was the same); the scenario's noise differs between them."""
    env = make_gym(_short(1.0), robot=3)
    try:
        a, *_ = _episode(env, seed=5, steps=40)
        b, *_ = _episode(env, seed=5, steps=40)
        c, *_ = _episode(env, seed=None, steps=40)
        d, *_ = _episode(env, seed=None, steps=40)
        assert np.array_equal(a, b)
        assert not np.array_equal(c, d) and not np.array_equal(b, c)
        again = make_gym(_short(1.0), robot=3)
        e, *_ = _episode(again, seed=5, steps=40)
        f, *_ = _episode(again, seed=None, steps=40)
        assert np.array_equal(a, e) and np.array_equal(c, f)  # the stream a seed begins
    finally:
        env.close()


def test_the_observation_is_the_robots_own_view_scaled_to_learn_from():
    """:data:`FIELDS` in order: the time, its slot and its error to it, the team's command,
    its fault estimate, its in-neighbours (robot 3 hears robot 2), its residual ratios,
    flags and the membership, every entry of the order of 1."""
    env = make_gym(_short(2.0), robot=3)
    try:
        seq, _, _, info = _episode(env, seed=2, steps=150)
        s = env.unwrapped.seats
        assert s.heard[2] == [1] and env.observation_space.shape == (1 + 2 * 4 + 2 + 3 * 4,)
        last = seq[-1]
        team = s.sim.team
        assert last[0] == pytest.approx(1.5 / 2.0, abs=1e-6)
        assert np.allclose(last[3:5], (s.sim.measurements[2] - team.x_d[2]) / s.spacing, atol=1e-6)
        assert np.allclose(last[5:7], info["dftc_command"] / s.limit, atol=1e-6)
        assert np.all(last[-4:] == 1.0)  # everyone in the team
        assert np.abs(seq).max() < 10.0
        # its residual ratios, with the thresholds read from eq. 40's factors as the
        # compiled period reads them, and the reward written with the observation
        assert team.threshold_factors is not None
        ratio = np.asarray(team.r_norm)[2] / np.asarray(team.mu)[2]
        assert np.allclose(last[11:15], np.minimum(ratio, 4.0) / 4.0, atol=1e-6)
        x, slot = s.sim.positions[2], team.x_d[2]
        assert s.reward(2) == pytest.approx(-np.hypot(*(x - slot)) / s.spacing)
        names = [f[0] for f in FIELDS]
        assert names[:3] == ["time", "slot", "slot_error"] and names[-1] == "active"
    finally:
        env.close()


def test_a_policy_that_stops_its_robot_is_excluded_and_its_agent_terminates():
    """A policy that keeps robot 2 still from 2 s: its teammates flag it, it is excluded,
    and its episode terminates (it earned 0 for ever after, and stayed in env.agents)."""
    s = load_scenario("paper_case", {"duration": 20.0, "faults": []})

    def still(obs, info):
        return np.zeros(2) if info["t"] >= 2.0 else info["dftc_command"]

    _, term, trunc, info = _episode(make_gym(s, robot=2), seed=1, policy=still)
    assert term and not trunc and info["t"] < 20.0
    par = make_parallel(s, robots=[2, 3])
    par.reset(seed=1)
    left = None
    while par.agents:
        acts = {a: np.zeros(2) if a == "robot_2" and par.seats.sim.t >= 2.0 else
                par.seats.sim.team.u_bar[int(a[-1]) - 1] for a in par.agents}  # fmt: skip
        _, _, terms, _, _ = par.step(acts)
        if terms.get("robot_2") and left is None:
            left = par.seats.sim.t
            assert par.agents == ["robot_3"]
    assert left is not None and left < 20.0


def test_each_step_labels_the_faults_in_force_and_episodes_draw_their_own():
    """``info["faulty"]`` and ``info["fault_kind"]`` say which robot is faulty now and how
    (a learned detector is trained and scored on them); ``vary`` draws each episode's fault
    (a campaign's [vary] table), so two episodes of the stream differ."""
    vary = {"fault_kind": ["stop", "bias"], "faulty_robot": [1, 4], "fault_time": [0.5, 1.0]}
    env = make_gym(_short(2.0), robot=2, vary=vary)
    try:
        drawn, labels = [], []
        for seed in (None, None, None, None):
            env.reset(seed=seed)
            (fault,) = env.unwrapped.seats.scenario.faults
            drawn.append((fault.robot, fault.kind, fault.t))
            info = None
            for _ in range(150):
                _, _, term, trunc, info = env.step(np.zeros(2))
                if term or trunc:
                    break
            labels.append((info["faulty"].copy(), list(info["fault_kind"])))
        assert len(set(drawn)) > 1
        for (robot, kind, t), (faulty, kinds) in zip(drawn, labels, strict=True):
            assert t <= 1.5 and faulty[robot] and kinds[robot] == kind
            assert faulty.sum() == 1
        with pytest.raises(Exception, match=r"vary\.robots: an episode cannot change the team"):
            make_gym(_short(), robot=2, vary={"robots": [4, 8]})
    finally:
        env.close()


def test_the_ids_are_registered_and_make_and_make_vec_work():
    assert {"dftc/PaperCase-v0", "dftc/HoldSlot-v0"} <= set(IDS) <= set(gymnasium.registry)
    env = gymnasium.make("dftc/PaperCase-v0", overrides={"duration": 0.2})
    obs, _ = env.reset(seed=0)
    assert obs.shape == env.observation_space.shape
    env.close()
    vec = gymnasium.make_vec(
        "dftc/PaperCase-v0", num_envs=2, vectorization_mode="sync", overrides={"duration": 0.2}
    )
    obs, _ = vec.reset(seed=0)
    assert obs.shape == (2, *env.observation_space.shape) and not np.array_equal(obs[0], obs[1])
    vec.close()


def test_a_nan_action_is_refused_and_an_infinite_one_saturates():
    """A policy's NaN drove its robot at 0 m/s in silence; ±inf is the drive's range."""
    env = make_gym(_short(), robot=2)
    try:
        env.reset(seed=0)
        with pytest.raises(ValueError, match=r"the action for robot 2 is \[nan, 0\.0\]: expected"):
            env.step(np.array([np.nan, 0.0]))
        env.step(np.array([np.inf, -np.inf]))
        told = env.unwrapped.seats.sim._physics.override[1]
        assert told.tolist() == [env.action_space.high[0], env.action_space.low[1]]
    finally:
        env.close()


def test_malformed_parallel_actions_are_refused():
    """PettingZoo: a missing agent's robot kept its previous command; an unknown agent's
    action was dropped; step(None) raised AttributeError."""
    env = make_parallel(_short(), robots=[1, 2])
    try:
        env.reset(seed=0)
        with pytest.raises(KeyError, match=r"missing \['robot_2'\]"):
            env.step({"robot_1": np.zeros(2)})
        with pytest.raises(KeyError, match=r"not live \['robot_9'\]"):
            env.step({"robot_1": np.zeros(2), "robot_2": np.zeros(2), "robot_9": np.zeros(2)})
        with pytest.raises(TypeError, match="expected a dict of agent -> action"):
            env.step(None)
    finally:
        env.close()


def test_a_robot_that_is_not_in_the_team_is_refused_in_one_line():
    from dftc_mujoco.errors import InputError

    with pytest.raises(InputError, match=r"robots to drive: expected numbers in 1\.\.4, got \[9\]"):
        make_gym(_short(), robot=9)


def test_a_policy_that_stops_its_robot_is_flagged_by_the_team(tmp_path):
    """examples/policy_robot.py: the policy follows the team's command, then keeps robot 2
    still from 25 s; its teammates flag it, and nobody flags anyone before."""
    out = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "policy_robot.py")],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert out.returncode == 0, out.stderr
    flags = [line.split() for line in out.stdout.splitlines() if "flags robot" in line]
    assert flags and all(float(f[0]) > 25.0 for f in flags)
    assert {f[3] for f in flags if f[6] == "2"} >= {"1", "3", "4"}


def test_the_training_example_learns_in_a_smoke_run(tmp_path):
    """examples/train_hold_slot.py with one PPO rollout (2048 steps): it trains, writes its
    learning curve and compares the learned policy with the team's own command on the same
    evaluation episodes (the full run, 60 000 steps, is on the environments page)."""
    pytest.importorskip(
        "stable_baselines3", reason="the learn extra is not installed (pip install -e '.[learn]')"
    )
    out = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "train_hold_slot.py"), "--steps", "2048",
         "--out", str(tmp_path)],
        cwd=tmp_path, capture_output=True, text=True, timeout=1800,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    rows = (tmp_path / "curve.csv").read_text().splitlines()
    assert rows[0] == "steps,return" and len(rows) >= 2
    assert (tmp_path / "curve.png").stat().st_size > 5_000
    assert "mean return over 10 episodes: learned" in out.stdout
