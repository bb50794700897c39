"""The team as an environment for learned or hand-written policies (the ``rl`` extra).

Each robot that a policy drives is an agent: it observes what that robot knows (its slot and its
error to it, the team's command for it, its own fault estimate, its in-neighbours' estimated
positions, its residuals, flags and the team's membership: ``dftc_mujoco.envs.seat.FIELDS``) and its
action is its planar velocity command, which replaces the team's ū for that robot (or corrects it);
every other robot, and the driven robot's own onboard blocks, run the scenario's DFTC as before, so
a policy that misbehaves is flagged like a faulty robot. One step is one control period. Episodes
follow each ecosystem's rules (:mod:`.seat`): a seeded reset fixes the episode, an unseeded one
draws the next, the scenario's duration truncates, an exclusion terminates.

* :func:`make_gym` — a Gymnasium ``Env`` for one robot; the ids of :data:`IDS` are
  registered with Gymnasium when this package is imported (``gymnasium.make``,
  ``gymnasium.make_vec``);
* :func:`make_parallel` — a PettingZoo ``ParallelEnv``, one agent per driven robot;
* :func:`make_dm_env` — dm_control's ``rl.control.Environment`` (a ``dm_env.Environment``)
  for one robot.

``pip install -e ".[rl]"`` installs gymnasium, pettingzoo and dm-env.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..errors import InputError

#: the task of the training example: robot 3 of paper_case under a bias its compensation
#: does not know (fault detection off), each episode's bias drawn anew; the policy corrects
#: the team's command
HOLD_SLOT: dict[str, Any] = {
    "scenario": "paper_case",
    "overrides": {"duration": 20.0, "fdir.enabled": False, "obstacles": []},
    "robot": 3,
    "action": "correction",
    "vary": {
        "fault_kind": ["bias"],
        "faulty_robot": [3],
        "fault_time": [1.0, 5.0],
        "bias_magnitude": [0.05, 0.3],
    },
}
#: the Gymnasium ids this package registers, with their keyword arguments
IDS: dict[str, dict[str, Any]] = {
    "dftc/PaperCase-v0": {"scenario": "paper_case", "robot": 3},
    "dftc/HoldSlot-v0": HOLD_SLOT,
}


def _need(module: str) -> None:
    try:
        __import__(module)
    except ImportError:
        raise InputError(
            f"dftc_mujoco.envs needs {module}: pip install -e '.[rl]' (the rl extra)"
        ) from None


def _scenario(scenario: Any, overrides: Mapping[str, Any] | None) -> Any:
    """The scenario with ``overrides`` (dotted keys) applied, if any."""
    if not overrides:
        return scenario
    from ..scenario import Scenario, load_scenario

    if isinstance(scenario, Scenario):
        raise InputError("overrides: give a scenario name or path with them, not a Scenario")
    return load_scenario(scenario, dict(overrides))


def make_gym(
    scenario: Any = "paper_case",
    robot: int = 1,
    overrides: Mapping[str, Any] | None = None,
    **kwargs: Any,
) -> Any:
    """A Gymnasium environment in which a policy drives ``robot`` (numbered from 1) of
    ``scenario`` (a name, a path or a :class:`~dftc_mujoco.scenario.Scenario`; ``overrides``
    by dotted key). ``kwargs``: ``vary``, ``action``, ``render_mode``
    (``dftc_mujoco.envs.gym.DFTCEnv``)."""
    _need("gymnasium")
    from .gym import DFTCEnv

    return DFTCEnv(_scenario(scenario, overrides), robot, **kwargs)


def make_parallel(
    scenario: Any = "paper_case",
    robots: list[int] | None = None,
    overrides: Mapping[str, Any] | None = None,
    **kwargs: Any,
) -> Any:
    """A PettingZoo parallel environment whose agents drive ``robots`` (numbered from 1;
    None: every robot)."""
    _need("pettingzoo")
    from .petting import DFTCParallelEnv

    return DFTCParallelEnv(_scenario(scenario, overrides), robots, **kwargs)


def make_dm_env(
    scenario: Any = "paper_case",
    robot: int = 1,
    overrides: Mapping[str, Any] | None = None,
    **kwargs: Any,
) -> Any:
    """dm_control's ``rl.control.Environment`` (a ``dm_env.Environment``) in which a policy
    drives ``robot`` (numbered from 1): :mod:`dftc_mujoco.envs.dm`'s physics and task;
    ``seed``, ``vary`` and ``action`` as for :func:`make_gym`."""
    _need("dm_control")
    from .dm import environment

    return environment(_scenario(scenario, overrides), robot, **kwargs)


def register() -> list[str]:
    """Register :data:`IDS` with Gymnasium (done on import where Gymnasium is installed);
    returns the ids."""
    import gymnasium

    for name, kwargs in IDS.items():
        if name not in gymnasium.registry:
            gymnasium.register(name, entry_point="dftc_mujoco.envs:make_gym", kwargs=kwargs)
    return list(IDS)


try:  # Gymnasium's ids, where Gymnasium is installed (the rl extra)
    register()
except ImportError:
    pass

__all__ = ["IDS", "make_dm_env", "make_gym", "make_parallel", "register"]
