"""A policy that learns to hold its slot under a bias its compensation does not know.

    python examples/train_hold_slot.py [--steps 60000] [--out renders/hold_slot]

needs the rl extra and Stable-Baselines3 (``pip install -e ".[rl,learn]"``; the ``learn``
extra installs stable-baselines3, which needs PyTorch: a CPU build is enough).

The task is ``dftc/HoldSlot-v0`` (:data:`dftc_mujoco.envs.HOLD_SLOT`): robot 3 of the paper's
team gets an actuator bias of 0.05-0.3 m/s in a random direction at 1-5 s, drawn anew each
episode, with fault detection and compensation off, so the team's own command leaves it off
its slot by about bias / k_c. The policy's action is a correction added to the team's
command; its reward is minus its distance from its slot (in slots' spacings) each period.
The script trains PPO, writes the learning curve (``curve.csv`` and ``curve.png``: the
return of each training episode) and compares, on the same ten evaluation episodes, the
learned policy with following the team's own command (a zero correction).
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import gymnasium
import numpy as np

import dftc_mujoco.envs  # noqa: F401 - registers dftc/HoldSlot-v0


def evaluate(env, act, seeds) -> float:
    """The mean return of ``act(obs)`` over the episodes ``seeds`` fix."""
    returns = []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(act(obs))
            total += reward
            done = terminated or truncated
        returns.append(total)
    return float(np.mean(returns))


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=60_000, help="training steps (periods)")
    p.add_argument("--out", type=Path, default=Path("renders/hold_slot"))
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    from stable_baselines3 import PPO
    from stable_baselines3.common.monitor import Monitor

    args.out.mkdir(parents=True, exist_ok=True)
    env = Monitor(gymnasium.make("dftc/HoldSlot-v0"))
    model = PPO("MlpPolicy", env, n_steps=2048, batch_size=256, seed=args.seed, verbose=0)
    model.learn(total_timesteps=args.steps)
    curve = list(zip(np.cumsum(env.get_episode_lengths()), env.get_episode_rewards(), strict=True))
    with open(args.out / "curve.csv", "w", newline="") as fh:
        csv.writer(fh).writerows([("steps", "return"), *curve])
    seeds = range(1000, 1010)  # the same ten episodes for both
    test = gymnasium.make("dftc/HoldSlot-v0")
    learned = evaluate(test, lambda o: model.predict(o, deterministic=True)[0], seeds)
    team = evaluate(test, lambda o: np.zeros(2, np.float32), seeds)
    print(f"training: {len(curve)} episodes, {args.steps} steps")
    print(f"mean return over 10 episodes: learned {learned:.1f}, the team's command {team:.1f}")
    _plot(curve, team, args.out / "curve.png")


def _plot(curve, team: float, path: Path) -> None:
    from dftc_mujoco.render.figures import new_figure

    fig, ax = new_figure(figsize=(6, 3.5))
    steps, returns = zip(*curve, strict=True) if curve else ((), ())
    ax.plot(steps, returns, ".-", label="PPO, each training episode")
    ax.axhline(team, color="k", ls="--", label="the team's own command")
    ax.set_xlabel("training steps (control periods)")
    ax.set_ylabel("episode return")
    ax.set_title("dftc/HoldSlot-v0")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)


if __name__ == "__main__":
    main()
