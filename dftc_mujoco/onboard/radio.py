"""Each robot's radio: which of its links delivered the round's message, and which it no
longer hears (docs/thresholds.md, "Over a network").

Under the network's declared bounds (delay ≤ L periods, at most b losses in a row) the
message of round s is on every link by round s. A robot that finds it missing on a link
for :data:`SILENT_ROUNDS` rounds in a row reports the link silent (``link_silent``) until
it delivers again (``link_heard``); a robot that none of its listeners hears is reported
``robot_silent``: a communication fault, not an actuator fault. The receiver keeps the
last message it got on a silent link: dropping the term from its residual would move the
residual at once by its disagreement with that neighbour (0.84 m in a 16-robot battery
run, which flagged 13 healthy robots), while a held message is a constant input that the
observer integrates back to a zero residual. Only what each receiving robot knows is
used: the rounds its own links carry.
"""

from __future__ import annotations

import numpy as np

from ..core.events import Event, Kind, make
from .observer import Observer

#: rounds in a row without the round's message after which a robot reports a link silent
SILENT_ROUNDS = 2


class Radios:
    """The team's radios: the links into each member (in the observer's ``allowed``
    order), what they missed, and the map from the channel's links to them."""

    def __init__(self, observer: Observer, n: int) -> None:
        links = len(observer.allowed.src)
        self.observer = observer
        self.late = np.zeros(links, dtype=np.int64)  # rounds each link missed in a row
        self.deaf = np.zeros(links, bool)  # links reported silent (their last message held)
        self.missed = 0  # links whose round message was missing at the last round
        self.link_map = np.arange(links)  # the channel's link -> the observer's (-1: gone)
        self.silent_robot = np.zeros(n, bool)
        self.episode = False  # a message fault is reported and not over

    def receive(self, links: np.ndarray, rounds: np.ndarray, offset: np.ndarray) -> None:
        """The channel delivered, on its links ``links``, the messages of ``rounds`` (each
        with ``offset`` [m] from a corrupting sender): each receiving robot keeps them."""
        if not len(links):
            return
        mine = self.link_map[links]
        ok = mine >= 0
        self.observer.receive(mine[ok], rounds[ok], offset[ok])

    def watch(self, t: float, s: int, members: np.ndarray) -> list[Event]:
        """At round ``s``: each robot checks its links for the round's message; returns the
        events of links it stops or starts reading again and of robots nobody hears.
        ``members``: the original robot of each team row."""
        obs = self.observer
        fresh = obs.link_round >= s
        self.missed = int(len(fresh) - np.count_nonzero(fresh))
        if not self.missed and not self.deaf.any():
            self.late[:] = 0
            return []
        self.late = np.where(fresh, 0, self.late + 1)
        deaf = self.late >= SILENT_ROUNDS
        changed = np.flatnonzero(deaf != self.deaf)
        if not len(changed):
            return []
        events = []
        ids = members + 1
        src, dst = obs.allowed.src, obs.link_dst()
        for e in changed:
            sender, heard_by = int(ids[src[e]]), int(ids[dst[e]])
            if deaf[e]:
                since = int(obs.link_round[e])
                events.append(
                    make(t, Kind.LINK_SILENT, robot=sender, heard_by=heard_by, since=since)
                )
            else:
                events.append(make(t, Kind.LINK_HEARD, robot=sender, heard_by=heard_by))
        self.deaf = deaf
        for j in np.unique(src[changed]):
            out = src == j
            robot = int(members[j])
            silent = bool(deaf[out].all())
            if silent and not self.silent_robot[robot]:
                events.append(
                    make(
                        t,
                        Kind.ROBOT_SILENT,
                        robot=robot + 1,
                        reported_by=[int(ids[d]) for d in dst[out]],
                        since=int(obs.link_round[out].max()),
                    )
                )
            self.silent_robot[robot] = silent
        return events

    def message_faults(
        self, t: float, flag: np.ndarray, members: np.ndarray, max_faults: int
    ) -> list[Event]:
        """A robot whose flags stand on more of its columns than the fault hypothesis admits
        cannot be seeing actuator faults (each moves one column only): something it
        receives is wrong. The first robots to show it report it (``message_fault``), naming
        the sender when they have exactly one in-neighbour in common; robots that show it
        later in the same episode got it through the consensus and add nothing. The episode
        ends when no robot shows it any more."""
        many = np.count_nonzero(flag, axis=1) > max(max_faults, 1)
        if not many.any():
            self.episode = False
            return []
        if self.episode:
            return []
        self.episode = True
        first = np.flatnonzero(many)
        obs = self.observer
        src, dst = obs.allowed.src, obs.link_dst()
        common = set.intersection(*(set(src[dst == i].tolist()) for i in first))
        sender = int(members[common.pop()]) + 1 if len(common) == 1 else None
        by = [int(members[i]) + 1 for i in first]
        return [make(t, Kind.MESSAGE_FAULT, robot=sender, reported_by=by)]

    def drop(self, p: int) -> None:
        """Before the observer drops team row ``p``: its links go with it."""
        obs = self.observer
        stay = (obs.allowed.src != p) & (obs.link_dst() != p)
        renumber = np.where(stay, np.cumsum(stay) - 1, -1)
        self.link_map = np.where(self.link_map >= 0, renumber[self.link_map], -1)
        self.late, self.deaf = self.late[stay], self.deaf[stay]


class Rounds:
    """The observers' clock: a round every ``periods`` control periods (1: every period,
    the ideal network). Round s runs at period s R, round 0 at the start on the messages of
    ŷ(0) the robots exchange before it; the threshold rules count time in rounds, s h_o
    (h_o = R × the control period)."""

    def __init__(self, periods: int, observer_period: float) -> None:
        self.periods, self.h_o = max(1, int(periods)), observer_period
        self.period = 0  # control periods stepped so far
        self.now = True  # the observers step in the current period
        self.index = 0  # the round they step now (when ``now``)
        self.content = 0  # the round of the ŷ each robot's radio sends

    def tick(self) -> bool:
        """Count a control period; True when the observers step in it."""
        k, big_r = self.period, self.periods
        self.period += 1
        self.now = big_r == 1 or k % big_r == 0
        if self.now:
            self.index = k // big_r
        return self.now

    def rule_time(self, t: float) -> float:
        """The threshold rules' time of the current round (``t`` itself every period)."""
        return t if self.periods == 1 else self.index * self.h_o

    def stepped(self) -> int:
        """After a round: the round of the ŷ the radios send from now on."""
        self.content = self.index + 1
        return self.content

    def restart_time(self, t: float) -> float:
        """The rules' time of the first round at or after the period about to be stepped
        (an exclusion restarts them there)."""
        if self.periods == 1:
            return t
        return ((self.period + self.periods - 1) // self.periods) * self.h_o
