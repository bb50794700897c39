"""The team as an environment for learned or hand-written policies (the ``rl`` extra).

Each robot that a policy drives is an agent: it observes what that robot knows (its own
measurement, its estimate of the team, its residuals, thresholds and flags, its
in-neighbours' messages: :mod:`.seat`) and its action is its planar velocity command, which
replaces the team's ū for that robot; every other robot, and the driven robot's own onboard
blocks, run the scenario's DFTC as before, so a policy that misbehaves is flagged like a
faulty robot. One step is one control period.

* :func:`make_gym` — a Gymnasium ``Env`` for one robot;
* :func:`make_parallel` — a PettingZoo ``ParallelEnv``, one agent per driven robot;
* :func:`make_dm_env` — a ``dm_env.Environment`` for one robot.

``pip install -e ".[rl]"`` installs gymnasium, pettingzoo and dm-env.
"""

from __future__ import annotations

from typing import Any

from ..errors import InputError


def _need(module: str) -> None:
    try:
        __import__(module)
    except ImportError:
        raise InputError(
            f"dftc_mujoco.envs needs {module}: pip install -e '.[rl]' (the rl extra)"
        ) from None


def make_gym(scenario: Any, robot: int = 1, **kwargs: Any) -> Any:
    """A Gymnasium environment in which a policy drives ``robot`` (numbered from 1) of
    ``scenario`` (a name, a path or a :class:`~dftc_mujoco.scenario.Scenario`)."""
    _need("gymnasium")
    from .gym import DFTCEnv

    return DFTCEnv(scenario, robot, **kwargs)


def make_parallel(scenario: Any, robots: list[int] | None = None, **kwargs: Any) -> Any:
    """A PettingZoo parallel environment whose agents drive ``robots`` (numbered from 1;
    None: every robot)."""
    _need("pettingzoo")
    from .petting import DFTCParallelEnv

    return DFTCParallelEnv(scenario, robots, **kwargs)


def make_dm_env(scenario: Any, robot: int = 1, **kwargs: Any) -> Any:
    """A ``dm_env.Environment`` in which a policy drives ``robot`` (numbered from 1)."""
    _need("dm_env")
    from .dm import DFTCDmEnv

    return DFTCDmEnv(scenario, robot, **kwargs)


__all__ = ["make_dm_env", "make_gym", "make_parallel"]
