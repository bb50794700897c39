"""Does a set of blocks use only what each robot may know? A reusable test.

Robot i may use its own measurement, inputs and state, and the messages ʲŷ of
its in-neighbours j. :func:`check_locality` runs a team of the given blocks on
an ideal-integrator plant, then, for every robot i and every other robot k,
changes robot k's broadcast message (``observer.y_hat[k]``) and measurement and
steps once more: if k is not an in-neighbour of i, robot i's outputs (inputs,
fault estimate, residuals, thresholds, flags) and every row i of every block's
state must stay bit-identical. With ``networked=True`` the team runs over a network
(observers in rounds, each robot reading the last message each of its links delivered):
robot k's messages are changed where they are, on its outgoing links, and robot i's view
includes the links into it. Use it on your own blocks::

    from dftc_mujoco import check_locality
    assert check_locality({"controller": MyController()}) == []
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

import numpy as np

from ...core.graph import Graph, ring_with_chords
from ...core.mission import Formation, polygon_offsets
from ..block import Block, TeamConfig
from .team import Team


def demo_team(
    n: int,
    blocks: Mapping[str, Block] | None = None,
    graph: Graph | None = None,
    obstacles: bool = False,
    seed: int = 0,
    **changes,
) -> tuple[Team, np.ndarray]:
    """A team of ``n`` robots with the paper's gains (polygon of side 0.5 m), and its positions."""
    rng = np.random.default_rng(seed)
    offsets = polygon_offsets(n, 0.5)
    pos = np.array([[0.0, 0.6]]) if obstacles else np.zeros((0, 2))
    settings: dict[str, Any] = dict(
        graph=graph or ring_with_chords(n, (3,) if n > 4 else (2,)),
        kc=4.0,
        ko=6.0,
        K=3.0 * np.eye(2),
        G=0.01 * np.eye(2),
        theta=3.0,
        dt=0.01,
        eta_bar=0.001,
        xi_bar=0.005,
        formation=Formation("polygon", 0.5),
        obstacle_position=pos,
        obstacle_safe=np.full(len(pos), 0.37),
        obstacle_activation=np.full(len(pos), 0.45),
    )
    settings.update(changes)
    x = offsets + rng.normal(scale=0.1, size=offsets.shape)
    blocks = {k: copy.deepcopy(b) for k, b in (blocks or {}).items()}
    return Team(TeamConfig(**settings), x, np.zeros(2), blocks), x


def integrate(
    team: Team, x: np.ndarray, steps: int, velocity=(0.1, 0.0), t0: float = 0.0, fault=None
) -> np.ndarray:
    """Closed loop with an ideal integrator plant ẋ = ū + φ (eq. 1 with ξ = η = 0)."""
    v = np.asarray(velocity, float)
    for k in range(steps):
        t = t0 + k * team.config.dt
        team.step(t, x.copy(), v * t, v)
        deliver(team)
        phi = fault(t, team) if fault else 0.0
        x = x + team.config.dt * (team.u_bar + phi)
    return x


def deliver(team: Team) -> None:
    """A perfect network: every link delivers, for the next period, what its sender sends."""
    if team.radios is not None:
        e = len(team.radios.link_map)
        team.receive(np.arange(e), np.full(e, team.rounds.content), np.zeros(e))


#: per-link arrays of the observer (rows are links, not robots): shown through the links
#: into each robot instead
_LINK_STATE = {"links", "link_round", "sent"}


def robot_view(team: Team, i: int) -> list[np.ndarray]:
    """Everything robot i computed or holds after a step (copies)."""
    view = [
        team.u[i],
        team.u_bar[i],
        team.phi_hat[i],
        team.r_norm[i],
        np.asarray(team.mu)[i],
        np.asarray(team.flag)[i],
        team.x_hat[i],
    ]
    m = len(team.members)
    for block in team.blocks.values():
        for name, value in vars(block).items():
            if name in _LINK_STATE:
                continue
            if isinstance(value, np.ndarray) and value.ndim and value.shape[0] == m:
                view.append(value[i])
    obs = team.observer
    if team.radios is not None:  # the messages robot i holds from its in-neighbours
        into = obs.link_dst() == i
        view += [obs.links[into], obs.link_round[into]]
    return [np.array(v, copy=True) for v in view]


def check_locality(
    blocks: Mapping[str, Block] | None = None,
    n: int = 8,
    graph: Graph | None = None,
    warmup: int = 50,
    require_reaction: bool = False,
    networked: bool = False,
) -> list[str]:
    """Locality violations of a block set (empty when every robot uses only what it may).

    ``blocks`` replaces the paper's blocks as in :class:`~dftc_mujoco.closed_loop.loop.Simulation`;
    the team has ``n`` robots on ``graph`` (default: a ring with chords). With
    ``require_reaction`` a robot that ignores an in-neighbour's message is
    reported too. ``networked``: over a network with rounds of 3 periods (the checked
    period is a round).
    """
    changes: dict[str, Any] = {"networked": True, "round_periods": 3} if networked else {}
    if networked:
        warmup -= warmup % 3  # the checked period is a round (rounds at multiples of 3)
    team, x = demo_team(n, blocks, graph, **changes)
    x = integrate(team, x, warmup)
    g = team.config.graph
    c, v = np.array([0.5, 0.0]), np.array([0.1, 0.0])
    problems = []
    for i in range(n):
        heard = set(g.in_neighbours(i)) | {i}
        base = copy.deepcopy(team)
        base.step(0.5, x.copy(), c, v)
        ref = robot_view(base, i)
        for k in range(n):
            other = copy.deepcopy(team)
            y_hat = getattr(other.observer, "y_hat", None)
            if isinstance(y_hat, np.ndarray):
                y_hat[k] += 0.37  # robot k broadcasts a different ŷ
            if other.radios is not None:  # and its links carry different messages
                other.observer.links[other.observer.allowed.src == k] += 0.37
            x_m = x.copy()
            if k != i:
                x_m[k] += 0.21  # and measures something else
            other.step(0.5, x_m, c, v)
            got = robot_view(other, i)
            same = len(ref) == len(got) and all(
                np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
                for a, b in zip(ref, got, strict=True)
            )
            if k not in heard and not same:
                problems.append(f"robot {i + 1} used robot {k + 1}'s data without a link")
            elif k in heard and k != i and same and require_reaction:
                problems.append(f"robot {i + 1} ignored its in-neighbour {k + 1}'s message")
    return problems
