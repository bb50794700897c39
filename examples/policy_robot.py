"""A hand-written policy drives robot 2 of paper_case through the Gymnasium interface.

    python examples/policy_robot.py        (needs the rl extra: pip install -e ".[rl]")

Every other robot, and robot 2's own onboard blocks, run the paper's DFTC. Until 25 s the
policy follows what the team's blocks command robot 2 (``info["dftc_command"]``); from
25 s it keeps the robot where it is, a policy that misbehaves. The team's fault detection
sees a robot that does not move as its commands say and flags it like an actuator stop.
(A policy that only adds a constant offset within the drive's range is compensated by
the robot's fault estimator, as the paper's bias is: it is not flagged.)
"""

from __future__ import annotations

import numpy as np

from dftc_mujoco import load_scenario
from dftc_mujoco.core.events import Kind
from dftc_mujoco.envs import make_gym


def policy(t: float, info: dict) -> np.ndarray:
    """Follow the team's command; from 25 s on, stay still."""
    if t >= 25.0:
        return np.zeros(2, dtype=np.float32)
    return np.array(info["dftc_command"], dtype=np.float32)


def main() -> None:
    s = load_scenario("paper_case", {"duration": 35.0, "faults": []})
    env = make_gym(s, robot=2)
    _, info = env.reset(seed=1)
    total, terminated, truncated = 0.0, False, False
    while not (terminated or truncated):  # excluded by its teammates, or the time is up
        _, reward, terminated, truncated, info = env.step(policy(info["t"], info))
        total += reward
        for e in info["events"]:
            if e["kind"] == Kind.DETECTION:
                print(f"{e['t']:6.2f} s  robot {e['by']} flags robot {e['robot']}")
    env.close()
    print(f"return {total:.2f} over {info['t']:.2f} s")


if __name__ == "__main__":
    main()
