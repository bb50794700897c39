"""Recovery: the exclusion of a faulty robot at a common instant (eqs. 42-43, docs/notes.md, 10).

The first flag raised on robot k by anyone fixes its exclusion instant t_r = min ⁱt_d +
Δt_d,max (eq. 43); at t_r robot k is excluded if some member still flags it, and the
exclusion is cancelled otherwise. Two rules keep the protocol from destroying the team:
exclusion needs teammates (a robot's own flag is reported but neither schedules
nor confirms its own exclusion, unless ``self_exclusion``, the paper's eq. 43 read
literally), and a fault hypothesis: when more robots are flagged by teammates at one instant
than :func:`admitted` allows (``max_faults``, or a minority of the members left), something
systemic is wrong (a premise, not a fault): a ``systemic_anomaly`` event names them and
nobody is excluded until every flag is down. A robot excluded before is no longer counted: a
later fault is judged by the team that is left, as the first was. A contact postpones: a
robot whose bumper touched something from T_s + Δt_d,max before its first flag on (a contact
breaks the premises, and the flags it causes say nothing of the actuators) is excluded only
if a teammate still flags it T_s + Δt_d,max after its last contact
(``postpone_on_contact``): a contact is a new start for the residuals it disturbed, which
eq. 46 covers from the thresholds' settle time T_s on (with T_s beyond the run, no exclusion
of a robot that touched something is due within it). :class:`Recovery` keeps that
bookkeeping and says what is due; :class:`~.team.Team` owns the vectors that an exclusion
resizes and applies it (the observers, thresholds and decisions drop the robot, the
formation is re-planned).
Robots are on the original axis (0-based); events carry them 1-based.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ..core.events import Event, Kind, make
from ..core.graph import Graph

#: a flagged robot's largest residual/threshold must have fallen to this fraction of its value
#: at the last postponement for the flags to count as a contact's decaying trace
DECAYING = 0.9


def admitted(max_faults: int, members: int) -> int:
    """How many robots may be faulty at once in a team of ``members``: ``max_faults``, or
    with 0 ("auto") a minority of them, ⌊(M − 1)/2⌋ (at least 1)."""
    return max_faults if max_faults > 0 else max(1, (members - 1) // 2)


class Recovery:
    """Which robots are to be excluded when, from the flags the team raises."""

    def __init__(
        self,
        dt_d_max: float,
        max_faults: int,
        self_exclusion: bool = False,
        postpone_on_contact: bool = True,
        run_length: float = float("inf"),
    ) -> None:
        self.dt_d_max = float(dt_d_max)
        self.run_length = float(run_length)  # an exclusion due later is said to be so
        self.max_faults = int(max_faults)
        self.self_exclusion = bool(self_exclusion)
        self.postpone_on_contact = bool(postpone_on_contact)
        self.last_contact: dict[int, float] = {}  # robot -> the last time its bumper touched
        self.since: dict[int, float] = {}  # robot -> from when a contact postpones its t_r
        self.settle = 0.0  # T_s of the thresholds (Team.settle_time), waited after a contact
        self.anomaly: list[int] | None = None  # the robots flagged while an anomaly lasts
        self.first_detection: dict[int, float] = {}  # robot -> earliest flag by anyone
        self.pending: dict[int, float] = {}  # robot -> exclusion instant t_r (eq. 43)
        self.detected: set[tuple[int, int]] = set()  # (by, robot) pairs already reported
        # robot -> (t, its largest residual/threshold among teammates) when a contact last
        # postponed it: a contact's transient decays, a fault's signature does not
        self.ratio_at: dict[int, tuple[float, float]] = {}
        self.waiting: set[int] = set()  # robots whose own estimate has not confirmed yet

    def flagged(self, t: float, pairs: Iterable[tuple[int, int]]) -> list[Event]:
        """Robot ``by`` raised a flag on ``robot`` at ``t`` for each pair: a ``detection``
        event for each first flag of a pair, and the exclusion scheduled at t_r (eq. 43)
        for each robot flagged for the first time."""
        events: list[Event] = []
        for by, robot in pairs:
            if (by, robot) in self.detected:
                continue
            self.detected.add((by, robot))
            events.append(make(t, Kind.DETECTION, by=by + 1, robot=robot + 1))
            if not self.counts(by, robot):
                continue  # its own flag is reported, but exclusion needs teammates
            if robot not in self.first_detection:
                t_r = t + self.dt_d_max  # t_r = min ⁱt_d + Δt_d,max
                self.first_detection[robot] = t
                self.pending[robot] = t_r
                # a contact up to T_s + Δt_d,max earlier may explain it (a new start)
                self.since[robot] = t - self.settle - self.dt_d_max
                late = {"after_run": True} if t_r > self.run_length else {}
                events.append(make(t, Kind.EXCLUSION_SCHEDULED, robot=robot + 1, t_r=t_r, **late))
        return events

    def counts(self, by: int, robot: int) -> bool:
        """Whether robot ``by`` flagging ``robot`` counts towards its exclusion."""
        return by != robot or self.self_exclusion

    def hypothesis(self, t: float, flagged: list[int], excluded: int, members: int) -> Event | None:
        """The robots flagged by teammates now among ``members`` robots (``excluded`` were
        excluded before): an event when a ``systemic_anomaly`` begins or ends.

        It begins when more robots are flagged at once than :func:`admitted` allows in the
        team as it is now, and it lasts until no robot is flagged by a teammate any more: the
        whole episode is systemic, and every exclusion that comes due meanwhile is
        cancelled."""
        if self.anomaly is None:
            bound = admitted(self.max_faults, members)
            if len(flagged) <= bound:
                return None
            self.anomaly = sorted(flagged)
            return make(
                t,
                Kind.SYSTEMIC_ANOMALY,
                robots=[r + 1 for r in self.anomaly],
                max_faults=bound,
                excluded=excluded,
            )
        if flagged:
            self.anomaly = sorted(set(self.anomaly) | set(flagged))
            return None
        robots, self.anomaly = self.anomaly, None
        return make(t, Kind.SYSTEMIC_ANOMALY_OVER, robots=[r + 1 for r in robots])

    def due(self, t: float) -> list[int]:
        """The robots whose t_r has come, earliest first; they are no longer pending."""
        ready = sorted((t_r, r) for r, t_r in self.pending.items() if t + 1e-9 >= t_r)
        for _, robot in ready:
            del self.pending[robot]
            self.first_detection.pop(robot, None)
        return [robot for _, robot in ready]

    def contact(self, t: float, robots: Iterable[int]) -> None:
        """The bumpers of ``robots`` touch something at ``t``."""
        for robot in robots:
            self.last_contact[int(robot)] = t

    def postpone(self, t: float, robot: int, ratio: float = np.nan) -> Event | None:
        """At t_r: an ``exclusion_postponed`` event when ``robot`` touched something since its
        window began (its new t_r is its last contact + T_s + Δt_d,max, and that window must
        be free of contact in turn), or when the flags a contact raised are still decaying
        (:meth:`transient`); None when it may be excluded now. ``ratio``: the largest
        ‖ⁱr_k‖ / ⁱμ_k among its teammates now."""
        since = self.since.pop(robot, np.inf)
        last = self.last_contact.get(robot)
        if not self.postpone_on_contact or last is None:
            return None  # never touched anything
        if last < since:  # no contact since its window began: is a contact's trace decaying?
            self.since[robot] = since
            return self.transient(t, robot, ratio)
        self.ratio_at[robot] = (t, ratio)
        t_r = max(last + self.settle + self.dt_d_max, t + 1e-9)  # inf: T_s beyond the run
        self.pending[robot] = t_r
        self.first_detection[robot] = last
        self.since[robot] = last + 1e-9  # only a later contact postpones it again
        return make(
            t,
            Kind.EXCLUSION_POSTPONED,
            robot=robot + 1,
            reason="contact",
            last_contact=last,
            t_r=t_r if np.isfinite(t_r) else None,  # None: not within the run
        )

    def transient(self, t: float, robot: int, ratio: float) -> Event | None:
        """A robot a contact postponed is still flagged at its new t_r: if its largest
        residual/threshold among teammates fell by at least :data:`DECAYING` since then, the
        flags are the contact's trace decaying through the observers (a push moves y_m,k for
        good, and the consensus observer forgets it at its own rate, slower than T_s on a
        graph that an exclusion thinned): the exclusion waits until that decay, extrapolated,
        brings the ratio under 1, + Δt_d,max (``reason = "decaying"``). A fault's signature
        does not decay (a stop's residual grows to φ/k_o and stays), so a robot whose ratio
        holds or grows is excluded. None: exclude now."""
        before = self.ratio_at.get(robot)
        if before is None or not (np.isfinite(ratio) and ratio > 0.0):
            return None
        t0, r0 = before
        if not (t > t0 and np.isfinite(r0) and ratio < DECAYING * r0):
            return None
        rate = np.log(r0 / ratio) / (t - t0)  # 1/s, the trace's decay rate so far
        t_r = float(t + max(np.log(ratio), 0.0) / rate + self.dt_d_max)
        self.pending[robot] = t_r
        self.first_detection[robot] = t
        self.ratio_at[robot] = (t, ratio)
        return make(
            t,
            Kind.EXCLUSION_POSTPONED,
            robot=robot + 1,
            reason="decaying",
            last_contact=self.last_contact[robot],
            t_r=t_r,
            ratio=round(float(ratio), 4),
            was=round(float(r0), 4),
        )

    def unconfirmed(self, t: float, robot: int, phi_bar: float) -> Event | None:
        """At t_r: ``robot`` is still flagged, but since its first flag its own fault estimate
        has not stayed beyond Φ̄ (``phi_bar``), nor its command beyond range, for a decision
        window (:mod:`.estimate_alarm`): its signal moved as a healthy robot's, and the flags
        are the observers' memory of an earlier break of the premises. It is judged again Δt_d,max
        later (and kept once nobody flags it); an ``exclusion_postponed`` event (``reason =
        "estimate"``) the first time in a row, None after."""
        t_r = t + self.dt_d_max
        self.pending[robot] = t_r
        self.first_detection[robot] = t
        self.since[robot] = t - self.settle - self.dt_d_max  # a new window for contacts too
        if robot in self.waiting:
            return None
        self.waiting.add(robot)
        return make(
            t,
            Kind.EXCLUSION_POSTPONED,
            robot=robot + 1,
            reason="estimate",
            t_r=t_r if np.isfinite(t_r) else None,
            phi_bar=round(float(phi_bar), 4),
        )

    def detectors(self, robot: int) -> list[int]:
        """Every robot that ever flagged ``robot`` (1-based, sorted)."""
        return sorted(by + 1 for by, k in self.detected if k == robot)

    def cancel(self, t: float, robot: int, reason: str = "not flagged") -> Event:
        """``robot`` stays at its t_r (no teammate flags it, or a ``systemic_anomaly`` holds),
        and its detections are forgotten."""
        event = make(
            t,
            Kind.EXCLUSION_CANCELLED,
            robot=robot + 1,
            detected_by=self.detectors(robot),
            reason=reason,
        )
        self.detected = {(b, k) for b, k in self.detected if k != robot}
        self.since.pop(robot, None)
        self.ratio_at.pop(robot, None)
        self.waiting.discard(robot)
        return event

    def exclusion(self, t: float, robot: int, flaggers: list[int]) -> Event:
        """The ``exclusion`` event of ``robot``, still flagged at t_r by ``flaggers``."""
        self.waiting.discard(robot)
        return make(
            t,
            Kind.EXCLUSION,
            robot=robot + 1,
            flagged_by=flaggers,
            detected_by=self.detectors(robot),
        )


def split_event(t: float, graph: Graph, members: np.ndarray) -> Event:
    """The ``graph_not_strongly_connected`` event: the members' strongly connected
    components and, for each, the robots it hears nothing from (directly or through
    others): its estimates of them, and the residuals and thresholds built on them, have
    no bound any more (eqs. 19, 35)."""
    ids = members + 1
    groups = graph.components()
    unheard = graph.unheard()
    cost = []
    for g in groups:
        lost = np.flatnonzero(unheard[g[0]])
        cost.append([int(k) for k in ids[lost]])
    return make(
        t,
        Kind.GRAPH_NOT_STRONGLY_CONNECTED,
        robots=[int(k) for k in ids],
        components=[[int(k) for k in ids[g]] for g in groups],
        unheard=cost,  # per component: the robots whose estimates lost their bound
        pairs=int(unheard.sum()),
    )


def worst_ratio(r_norm: np.ndarray, mu: np.ndarray, p: int) -> float:
    """The largest ‖ⁱr_k‖ / ⁱμ_k among robot k's teammates (k at member position ``p``, the
    (M, M) residual norms and thresholds): what each teammate knows of k, gathered as its
    flags are (NaN when no teammate can judge it)."""
    r = np.asarray(r_norm, float)[:, p]
    m = np.asarray(mu, float)[:, p]
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(m > 0, r / m, np.inf)
    ratio[p] = 0.0  # its own judgement is not a teammate's
    ratio = ratio[np.isfinite(ratio)]
    return float(ratio.max()) if len(ratio) else float("nan")
