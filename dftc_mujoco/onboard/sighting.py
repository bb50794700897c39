"""Seeing a silent teammate: its listeners judge it by where it is (docs/thresholds.md,
"Silent robots").

A robot whose radio fell silent (``robot_silent``) leaves its teammates' residuals: no
message of it reaches them, so an actuator fault of it moves nothing they compute. They
still see it. Robot i that listens to a silent robot j and has it within its range sensor's
reach (``sighting_range``) compares where it sees j with j's slot, σ₁,d + d_j (the mission's
centroid and j's offset in the formation, which every robot knows): a healthy robot follows
its slot, a stopped or biased one falls away from it at the speed of the fault. Robot i
raises a flag on j when j stays farther than ``sighting_tolerance`` from its slot for a
detection window. The flag counts towards j's exclusion as a residual's flag does
(eq. 43) and lowers when j is back within the tolerance.

The rule holds under the premise ``slot`` (closed_loop/premises.py): a silent robot without a fault
stays within the tolerance of its slot while it is judged. It is not judged before it was
once seen within the tolerance, away from obstacles, after falling silent (the start of a
run, a re-plan). Where eq. 18 may move it off its slot (within an obstacle's or a
teammate's activation distance and d + ‖σ̇₁,d + ḋ_j‖/θ, where avoidance can engage for a
robot on its slot) and for :data:`HOLD` s after, the tolerance is wider by the detour
avoidance may take: twice that obstacle's safe distance d.
Only what robot i knows is used: its links, its range sensor, the mission and the plan.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..core.events import Event, Kind, make
from .block import TeamConfig
from .observer import Observer
from .radio import Radios
from .recovery import Recovery


class WatchingTeam(Protocol):
    """What the sighting reads of the team (:class:`~.team.Team` is one)."""

    config: TeamConfig
    members: np.ndarray
    gone: np.ndarray  # the robots excluded so far
    observer: Observer
    radios: Radios | None  # None on the ideal network
    recovery: Recovery


#: [s] a silent robot keeps the wider tolerance this long after it was near something
HOLD = 2.0


class Sighting:
    """The team's sightings of silent robots, on the original robot axis."""

    def __init__(self, n: int, tolerance: float, reach: float, window: float, dt: float) -> None:
        self.tolerance, self.reach, self.dt = float(tolerance), float(reach), float(dt)
        self.window = max(1, round(window / dt))  # periods beyond the tolerance before a flag
        self.flag = np.zeros((n, n), bool)  # [by, robot]: robot ``by`` flags ``robot`` by sight
        self.count = np.zeros((n, n), np.int64)  # periods each pair saw the robot off its slot
        self.armed = np.zeros(n, bool)  # seen within the tolerance since it fell silent
        self.near_until = np.full(n, -np.inf)  # the wider tolerance holds until this instant
        self.detour = np.zeros(n)  # [m] how much wider: what eq. 18 may move the robot by
        self.judged = np.zeros(n, bool)  # judged by some listener in the last period
        self.error = np.full(n, np.nan)  # how far each judged robot is from its slot [m]
        self.slots = np.zeros((n, 2))  # each member's slot σ₁,d + d_j at the last period

    def step(
        self,
        t: float,
        silent: np.ndarray,
        listeners: dict[int, np.ndarray],
        members: np.ndarray,
        seen: np.ndarray,
        slots: np.ndarray,
        detour: np.ndarray,
        rows: np.ndarray | None = None,
    ) -> tuple[list[tuple[int, int]], list[Event]]:
        """One period. ``silent`` (N,) robots reported silent; ``listeners[p]`` the team
        positions that listen to the member at position ``p`` (a list, or a dict by ``p``);
        ``seen`` (N, 2) where the range sensors see every robot; ``slots`` (M, 2) the
        members' slots σ₁,d + d_j;
        ``detour`` (M,) [m] how far eq. 18 may move each member off its slot where it is
        (0 away from obstacles and teammates); ``rows``: the team positions to look at
        (None: all; the others are neither silent nor watched).
        Returns the (by, robot) pairs raised now (original axis) and their events."""
        self.judged[:] = False
        raised: list[tuple[int, int]] = []
        events: list[Event] = []
        for p in range(len(members)) if rows is None else rows:
            j = members[p]
            if not silent[j]:
                if self.armed[j] or self.flag[:, j].any():
                    self.forget(int(j))
                continue
            if detour[p] > 0:
                was = self.detour[j] if t < self.near_until[j] else 0.0
                self.near_until[j], self.detour[j] = t + HOLD, max(was, detour[p])
            off = float(np.hypot(*(seen[j] - slots[p])))
            if not self.armed[j]:  # first seen on its slot, away from everything
                self.armed[j] = off <= self.tolerance and t >= self.near_until[j]
                continue
            tol = self.tolerance + (self.detour[j] if t < self.near_until[j] else 0.0)
            within = off <= tol
            by = members[listeners[p]]
            if np.isfinite(self.reach):
                d = np.hypot(*(seen[by] - seen[j]).T)
                by = by[d <= self.reach]
            if not len(by):
                continue
            self.judged[j] = True
            self.error[j] = off
            if within:
                self.count[by, j] = 0
                self.flag[by, j] = False
                continue
            self.count[by, j] += 1
            for i in by[(self.count[by, j] >= self.window) & ~self.flag[by, j]]:
                self.flag[i, j] = True
                raised.append((int(i), int(j)))
                events.append(
                    make(
                        t,
                        Kind.SIGHTING,
                        by=int(i) + 1,
                        robot=int(j) + 1,
                        distance=round(off, 4),
                        tolerance=round(float(tol), 4),
                    )
                )
        return raised, events

    def watch(
        self,
        t: float,
        team: WatchingTeam,
        c: np.ndarray,
        c_dot: np.ndarray,
        plan: tuple[np.ndarray, np.ndarray],
        seen: np.ndarray,
    ) -> list[Event]:
        """One period of ``team`` (:class:`~.team.Team`): its radios' silent robots, its
        links, the slots ``c`` + offsets moving at ``c_dot`` + rates (``plan``: the
        formation's offsets and rates); raises the flags that are due (they count towards
        exclusion, eq. 43) and returns the events."""
        offsets, rates = plan
        if team.radios is None:  # an ideal network: no radio falls silent
            return []
        silent = team.radios.silent_robot
        if not silent.any() and not self.armed.any():
            return []
        cfg, members = team.config, team.members
        obs = team.observer
        src, dst = obs.allowed.src, obs.link_dst()
        rows = np.flatnonzero(silent[members] | self.armed[members])  # the silent, watched
        listeners = {int(p): dst[src == p] for p in rows}
        x, mine = seen[members], seen[members[rows]]
        # eq. 18 engages only where r̂ᵀu_g < θ (d − ‖x − x_o‖): for a robot on its slot,
        # u_g is the slot's velocity, so within d + ‖σ̇₁,d + ḋ_j‖/θ
        step = np.hypot(*(c_dot + rates[rows]).T) / cfg.theta
        # near something, eq. 18 moves it around it: at most the thing's safe diameter
        near = np.zeros(len(rows))
        if len(cfg.obstacle_position):
            d = np.hypot(*(mine[:, None, :] - cfg.obstacle_position[None]).transpose(2, 0, 1))
            reach = np.minimum(cfg.obstacle_activation[None], cfg.obstacle_safe + step[:, None])
            near = np.maximum(near, np.where(d <= reach, 2 * cfg.obstacle_safe, 0).max(1))
        if len(team.gone):
            d = np.hypot(*(mine[:, None, :] - seen[team.gone][None]).transpose(2, 0, 1))
            reach = np.minimum(cfg.excluded_activation, cfg.excluded_safe + step)
            hit = (d <= reach[:, None]).any(axis=1)
            near[hit] = np.maximum(near[hit], 2 * cfg.excluded_safe)
        if cfg.teammate_safe > 0 and len(members) > 1:
            d = np.hypot(*(mine[:, None, :] - x[None]).transpose(2, 0, 1))
            d[np.arange(len(rows)), rows] = np.inf  # not itself
            reach = np.minimum(cfg.teammate_activation, cfg.teammate_safe + step)
            mate = (d <= reach[:, None]).any(axis=1)
            near[mate] = np.maximum(near[mate], 2 * cfg.teammate_safe)
        detour = np.zeros(len(members))
        detour[rows] = near
        self.slots[members] = c + offsets
        raised, events = self.step(
            t, silent, listeners, members, seen, self.slots[members], detour, rows
        )
        if raised:
            events += team.recovery.flagged(t, raised)
        return events

    def forget(self, j: int) -> None:
        """Robot ``j`` is heard again, or left the team: its sightings end."""
        self.flag[:, j] = self.flag[j, :] = False
        self.count[:, j] = self.count[j, :] = 0
        self.armed[j] = False
