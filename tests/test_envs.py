"""The team as an environment (dftc_mujoco/envs): each ecosystem's own checker, the
determinism of a seeded episode, and a policy that misbehaves flagged by the team."""

from __future__ import annotations

import subprocess
import sys
import unittest
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("gymnasium", reason="the rl extra is not installed (pip install -e '.[rl]')")
pytest.importorskip("pettingzoo", reason="the rl extra is not installed")
dm_test_utils = pytest.importorskip("dm_env.test_utils", reason="the rl extra is not installed")

from dftc_mujoco import load_scenario  # noqa: E402
from dftc_mujoco.envs import make_dm_env, make_gym, make_parallel  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def _short(duration: float = 0.5):
    return load_scenario("paper_case", {"duration": duration, "faults": []})


def test_the_gymnasium_env_passes_gymnasiums_checker():
    from gymnasium.utils.env_checker import check_env

    env = make_gym(_short(), robot=2)
    try:
        check_env(env, skip_render_check=True)
    finally:
        env.close()


def test_the_parallel_env_passes_pettingzoos_api_test():
    from pettingzoo.test import parallel_api_test

    env = make_parallel(_short(), robots=[1, 3])
    try:
        parallel_api_test(env, num_cycles=80)
        assert env.possible_agents == ["robot_1", "robot_3"]
    finally:
        env.close()


class TestDmEnv(dm_test_utils.EnvironmentTestMixin, unittest.TestCase):
    """dm_env's own test mixin (reset, step, specs, episode ends)."""

    def make_object_under_test(self):
        return make_dm_env(_short(0.3), robot=1)

    def make_action_sequence(self):
        for _ in range(40):  # past the end of the 0.3 s episode (30 periods)
            yield np.zeros(2)


def test_a_seeded_episode_repeats_and_the_view_is_the_robots_own():
    env = make_gym(_short(1.0), robot=3)
    try:
        runs = []
        for _ in range(2):
            obs, _ = env.reset(seed=5)
            seq = [obs]
            for k in range(60):
                obs, *_ = env.step(np.array([0.05 * np.sin(k / 9), 0.02], np.float32))
                seq.append(obs)
            runs.append(np.array(seq))
        assert np.array_equal(runs[0], runs[1])
        # its own measurement leads the vector; its in-neighbours (robot 2) follow as messages
        s = env.unwrapped.seats
        assert s.heard[2] == [1]
        assert np.allclose(runs[0][-1][:2], s.sim.snapshot().x_m[2], atol=1e-6)
    finally:
        env.close()


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


def test_a_robot_that_is_not_in_the_team_is_refused_in_one_line():
    from dftc_mujoco.errors import InputError

    with pytest.raises(InputError, match=r"robots to drive: expected numbers in 1\.\.4, got \[9\]"):
        make_gym(_short(), robot=9)
