"""What the threshold rules assume, checked before a run and monitored during it.

Every rule of ``docs/thresholds.md`` is a bound *under premises*: measurement noise
within η̄, a drift of y_k within what ξ̄ and ē allow, a start within the initial-error
bound ε̄, a planar robot on a strongly connected graph, inputs that the robot really
applied. This module holds those premises in one place:

* before the run, :func:`initial_error_bound` derives ε̄ from the scenario itself (the
  start positions against the planned slots, in the rule's own meaning) and refuses a
  stated bound below it; :func:`rule_refusals` refuses configurations outside a rule's
  premises;
* during the run, :class:`Monitor` compares what the simulator knows (the true noise,
  the true positions and velocities, contacts, heights, the current graph) with those
  premises every control period, records each span of a violated premise as a
  ``premise_violated`` event and says, for any instant, which premises were violated
  then (so that every flag is labelled).

It never holds a control law and the onboard blocks never import it: the robots do not
know the truth, the simulator does.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit

from ..core.events import Kind
from ..errors import InputError, SimulationError, raised_line
from ..onboard.fault_estimator import ANTI_WINDUP_BAND

if TYPE_CHECKING:
    from ..onboard.execution.team import Team

#: the premises, in the order the tables print them, with a one-line meaning each
PREMISES: dict[str, str] = {
    "noise": "‖η_i‖ ≤ η̄ (eq. 4)",
    "mismatch": "‖ẋ_i − applied input‖ ≤ ξ̄ (eq. 2; the applied input after the drive's limits)",
    "initial_error": "every robot starts within ε̄ of its planned slot (initial_error_bound)",
    "saturation": "the compensated command ū stays out of the anti-windup's band below the "
    "robot's command range (no saturation, ∫e never skipped)",
    "contact": "no contact between a robot and a teammate or a cylinder",
    "planar": "the base stays on the floor, level, inside the arena",
    "connectivity": "the members' graph is strongly connected (over a network: the links "
    "that delivered within network.connectivity_window)",
    "network": "every round's message arrives on every link in time and intact (delays and "
    "consecutive losses within the network's declared bounds; no radio fault)",
    "slot": "a silent robot without a fault, judged by sight, stays within the sighting "
    "tolerance of its slot (onboard/sighting.py)",
}


@dataclass(frozen=True)
class StartBound:
    """ε̄ of a run: the value the rule uses, the one the scenario implies and where from."""

    value: float  # ε̄ the rule uses [m]
    implied: float  # the least ε̄ the start positions allow [m]
    robot: int  # the robot (0-based) that sets ``implied``
    offset: float  # that robot's distance from its planned slot [m]
    meaning: str  # "robot" or "stacked"
    derived: bool  # True: "auto"


def implied_initial_error(
    x0: np.ndarray, slots: np.ndarray, eta_bar: float, meaning: str
) -> tuple[float, int, float]:
    """The least ε̄ valid for start positions ``x0`` and planned slots ``slots`` (N, 2).

    Every robot starts believing its teammates are at their slots and itself where it
    measures itself (the observer's reset), so with a_k = slot_k − x_k(0):
    "robot" (l1, drive) bounds each ‖a_k‖; "stacked" (eq. 40, block_row) bounds
    ‖ỹ*_k(0)‖ = √((N − 1)‖a_k‖² + ‖η_k(0)‖²) ≤ √((N − 1)‖a_k‖² + η̄²).
    Returns (ε̄, the robot that sets it, its offset ‖a_k‖); ε̄ carries a relative 1e-9
    (and 1 nm) on top of the rounding of the positions.
    """
    a = np.linalg.norm(np.asarray(slots, float) - np.asarray(x0, float), axis=1)
    n = len(a)
    if meaning == "robot":
        need = a
    else:
        need = np.sqrt(max(n - 1, 0) * a**2 + eta_bar**2)
    k = int(np.argmax(need))
    return float(need[k]) * (1 + 1e-9) + 1e-9, k, float(a[k])


def initial_error_bound(
    stated: float | str,
    x0: np.ndarray,
    slots: np.ndarray,
    eta_bar: float,
    meaning: str,
    where: str,
) -> tuple[StartBound, str | None]:
    """ε̄ for the run and, if the stated one is below what the start implies, a refusal."""
    implied, k, off = implied_initial_error(x0, slots, eta_bar, meaning)
    if stated == "auto":
        return StartBound(implied, implied, k, off, meaning, True), None
    value = float(stated)
    bound = StartBound(value, implied, k, off, meaning, False)
    if value >= implied:
        return bound, None
    what = (
        "each robot's start distance from its planned slot"
        if meaning == "robot"
        else "the stacked start error of every observer, √(N − 1) × a robot's offset"
    )
    return bound, (
        f"{where}: fdir.initial_error_bound = {value:g} m is smaller than the {implied:.4g} m "
        f"this scenario implies (robot {k + 1} starts {off:.4g} m from its planned slot; the "
        f"rule bounds {what}); set it to at least {math.ceil(implied * 1000) / 1000:g} or "
        '"auto"'
    )


#: what a thresholds rule's ``initial_error`` may say ``initial_error_bound`` bounds
MEANINGS = ("stacked", "robot")
_ABSENT = object()  # a rule that declares no initial_error


def rule_meaning(rule: object, name: str, where: str) -> str:
    """What ``fdir.initial_error_bound`` bounds for thresholds block ``rule`` (named
    ``name``): its ``initial_error``, "stacked" where it declares none. A declaration that
    cannot be read or says something else is refused in one line (it used to be read as
    "stacked", in silence)."""
    if inspect.getattr_static(rule, "initial_error", _ABSENT) is _ABSENT:
        return "stacked"
    try:
        meaning = rule.initial_error  # type: ignore[attr-defined]
    except Exception as exc:  # a property of the block's own that raises
        raise InputError(
            f"{where}: onboard block thresholds ({name}) raised {raised_line(exc)} when its "
            "initial_error was read; nothing ran"
        ) from exc
    if isinstance(meaning, str) and meaning in MEANINGS:
        return meaning
    raise InputError(
        f"{where}: onboard block thresholds ({name}) declares initial_error = {meaning!r}; "
        'expected "stacked" (fdir.initial_error_bound bounds ‖ỹ*_k(0)‖ over every observer, '
        'eq. 40) or "robot" (each robot\'s start distance from its planned slot)'
    )


def rule_refusals(rule: str, compensate: bool, low_pass: float, where: str) -> list[str]:
    """Configurations outside a built-in rule's premises, one line each."""
    out = []
    if rule == "drive" and not compensate:
        out.append(
            f'{where}: onboard.thresholds = "drive" needs fdir.compensate = true (it bounds '
            "y_m,k − y_m,k(0) = G φ̂_k, which holds only while φ̂ is applied; without it ∫e "
            'winds up and no Φ̄ exists); use "l1" or "block_row"'
        )
    if rule == "drive" and low_pass > 0:
        out.append(
            f'{where}: onboard.thresholds = "drive" needs fdir.phi_low_pass = 0 (a filtered '
            "compensation breaks the identity y_m,k − y_m,k(0) = G φ̂_k it rests on)"
        )
    return out


# --------------------------------------------------------------------------- at run time

#: a robot's base may move this far up or down from its start height [m] ...
HEIGHT_TOLERANCE = 0.05
#: ... and tilt this far from level [rad] (about 29°) before the run stops: the planar
#: model of eq. 1 no longer describes it
TILT_TOLERANCE = 0.5
#: a flag is labelled with the premises its robot violated at least this long before it [s]
#: (the decision window plus the observer's mixing); on slow graphs the observer's own memory
#: (:func:`memory`) is longer and is used instead
LOOKBACK = 2.0
#: the observer's memory is the time its error needs to decay to this fraction (eq. 41)
MEMORY_FRACTION = 0.01
#: a span of a violated premise ends once the premise has held this long [s]
GAP = 0.1

_NOISE, _MISMATCH, _SATURATION, _CONTACT, _PLANAR = range(5)
_PER_PERIOD = ("noise", "mismatch", "saturation", "contact", "planar")


@njit(cache=True)
def _check(
    x, eta, u, u_bar, phi_hat, height, level, depth, watched, x0, int_u, slow, z0, value,
    h, eta_bar, step, offset, phi_bar, limit, t, spans, order, seq, last, rows, add, top,
    top_robot,
):  # fmt: skip  # pragma: no cover - compiled
    """One period of the premise checks, every robot at once; ``value`` (5, N) gets each
    premise's excess over its bound (> 0: violated), and the spans of violation are kept
    here (:func:`_spans`). Returns (the first robot that left the plane or -1, how many
    spans have ended and await their event).

    The truth of the period: positions ``x``, noise ``eta``, applied inputs ``u``, commands
    ``u_bar``, fault estimates ``phi_hat`` (N, 2); each base's ``height``, ``level`` (the
    z-axis component of its z-axis: cos of its tilt) and contact ``depth`` with a teammate
    or a cylinder (0: none) (N,). The drift premise (l1, block_row): D_k = y_k − y_k(0),
    y_k = x_k − h Σ u_k (the applied input), splits into S_k moving by at most h ξ̄
    (``step``) per period towards D_k and an offset E_k = D_k − S_k within ē (``offset``);
    with ``phi_bar`` > 0 (the drive rule) the premise is ‖φ̂_k‖ ≤ Φ̄ instead. Robots not
    ``watched`` (excluded, or with an active fault) are not judged on noise, drift and
    saturation."""
    n = x.shape[0]
    for i in range(n):
        for p in range(5):
            value[p, i] = 0.0
        d0 = x[i, 0] - x0[i, 0] - int_u[i, 0]
        d1 = x[i, 1] - x0[i, 1] - int_u[i, 1]
        g0, g1 = d0 - slow[i, 0], d1 - slow[i, 1]
        gap = np.sqrt(g0 * g0 + g1 * g1)
        if gap > step:
            g0, g1 = g0 * step / gap, g1 * step / gap
        slow[i, 0] += g0
        slow[i, 1] += g1
        int_u[i, 0] += h * u[i, 0]
        int_u[i, 1] += h * u[i, 1]
        if watched[i]:
            e = np.sqrt(eta[i, 0] ** 2 + eta[i, 1] ** 2)
            value[_NOISE, i] = max(e - eta_bar * (1 + 1e-9), 0.0)
            if phi_bar > 0:
                f = np.sqrt(phi_hat[i, 0] ** 2 + phi_hat[i, 1] ** 2)
                value[_MISMATCH, i] = max(f - phi_bar, 0.0)
            else:
                e0, e1 = d0 - slow[i, 0], d1 - slow[i, 1]
                value[_MISMATCH, i] = max(np.sqrt(e0 * e0 + e1 * e1) - offset, 0.0)
            over = max(abs(u_bar[i, 0]), abs(u_bar[i, 1])) - limit
            value[_SATURATION, i] = max(over, 0.0)
        value[_CONTACT, i] = depth[i]
        up = abs(height[i] - z0[i]) - HEIGHT_TOLERANCE
        tilt = np.arccos(min(max(level[i], -1.0), 1.0)) - TILT_TOLERANCE
        value[_PLANAR, i] = max(up, tilt, 0.0)
    return _spans(value, t, spans, order, seq, last, rows, add, top, top_robot)


@njit(cache=True)
def _spans(value, t, spans, order, seq, last, rows, add, top, top_robot):  # pragma: no cover
    """The spans of the per-period premises after a period's ``value`` (5, N) at ``t``:
    ``spans`` (3, 5, N) holds each open span's start (NaN: none open), worst value and
    last instant violated, ``order`` (5, N) the rank it opened in (``seq`` [0]: the next
    rank, shared with the team-wide spans, so that spans ending together are told in the
    order they began); ``last`` (premises, N) the last instant each robot violated each
    premise (rows ``rows``); ``top``, ``top_robot`` (5,) each premise's worst value and
    robot (-1: none yet). A value reported is the excess plus ``add`` (the bound).
    Returns (the first robot whose ``planar`` premise failed or -1, spans ended by ``t``)."""
    n = value.shape[1]
    planar = -1
    for p in range(5):
        for i in range(n):
            if value[p, i] > 0:
                v = value[p, i] + add[p]
                last[rows[p], i] = t
                if np.isnan(spans[0, p, i]):
                    spans[0, p, i] = t
                    spans[1, p, i] = v
                    order[p, i] = seq[0]
                    seq[0] += 1
                else:
                    spans[1, p, i] = max(spans[1, p, i], v)
                spans[2, p, i] = t
                if top_robot[p] < 0 or v > top[p]:
                    top[p] = v
                    top_robot[p] = i
                if p == _PLANAR and planar < 0:
                    planar = i
    ended = 0
    for p in range(5):
        for i in range(n):
            if not np.isnan(spans[0, p, i]) and t - spans[2, p, i] >= GAP - 1e-9:
                ended += 1
    return planar, ended


class Monitor:
    """The premises of the run's threshold rule, checked against the truth every period.

    ``bounds`` names each premise's bound as the rule uses it. Each span during which a
    premise is violated becomes one ``premise_violated`` event (``premise``, ``robot``
    1-based or None for the team, ``value`` the worst, ``bound``, ``t``, ``until``);
    :meth:`violated` says which premises robot k violated within its ``memory`` (at least
    :data:`LOOKBACK` s) before an instant, for labelling its flags; :meth:`table`
    summarises the run.
    A base that leaves the plane raises :class:`~dftc_mujoco.errors.SimulationError`
    (the run stops: the planar model no longer holds).
    """

    def __init__(
        self,
        *,
        n: int,
        dt: float,
        eta_bar: float,
        xi_bar: float,
        drift_bound: float,
        phi_bar: float,
        command_limit: float,
        start: StartBound,
        x0: np.ndarray,
        z0: np.ndarray,
        events: Any,
        memory: Callable[[int], float] | None = None,
    ) -> None:
        self.n, self.h, self.events = n, dt, events
        # each robot's residual memory [s], computed when a flag about it is first labelled
        self._memory_of = memory
        self._memory: dict[int, float] = {}
        self.eta_bar, self.step = eta_bar, dt * xi_bar
        self.offset, self.phi_bar = drift_bound, phi_bar
        # the anti-windup may skip ∫e from ANTI_WINDUP_BAND below the range on: from there the
        # identity y_m,k − y_m,k(0) = G φ̂_k of the rules may fail
        self.limit = command_limit - ANTI_WINDUP_BAND if np.isfinite(command_limit) else 1e300
        self.start = start
        self.bounds = {
            "noise": eta_bar,
            "mismatch": phi_bar if phi_bar > 0 else drift_bound,
            "initial_error": start.value,
            "saturation": self.limit,
            "contact": 0.0,
            "planar": HEIGHT_TOLERANCE,
            "connectivity": 0.0,
            "network": 0.0,
            "slot": 0.0,
        }
        self.x0 = np.array(x0, dtype=float)
        self.z0 = np.array(z0, dtype=float)
        self.int_u = np.zeros((n, 2))
        self.slow = np.zeros((n, 2))
        self.value = np.zeros((5, n))
        self.watched = np.ones(n, bool)
        self.split = False  # an exclusion left the graph not strongly connected
        self.last = np.full((len(PREMISES), n), -np.inf)  # last instant violated, per robot
        self.team_last = np.full(len(PREMISES), -np.inf)  # team-wide premises
        # premise -> (value, robot 1-based), of the premises checked outside the period
        self.worst: dict[str, tuple[float, int | None]] = {p: (0.0, None) for p in PREMISES}
        # their spans: (premise, robot) -> [t0, worst, last, rank it opened in]
        self.spans: dict[tuple[str, int | None], list[float]] = {}
        self.count = dict.fromkeys(PREMISES, 0)
        self._index = {p: k for k, p in enumerate(PREMISES)}
        # the per-period premises' spans, kept by the compiled check (:func:`_spans`)
        self.period_spans = np.full((3, len(_PER_PERIOD), n), np.nan)
        self._order = np.zeros((len(_PER_PERIOD), n), np.int64)
        self._seq = np.zeros(1, np.int64)
        self._rows = np.array([self._index[p] for p in _PER_PERIOD], np.int64)
        self._add = np.array(
            [0.0 if p == "contact" else self.limit if p == "saturation" else self.bounds[p]
             for p in _PER_PERIOD]
        )  # fmt: skip
        self._top = np.zeros(len(_PER_PERIOD))
        self._top_robot = np.full(len(_PER_PERIOD), -1, np.int64)
        self.worst["initial_error"] = (start.implied, start.robot + 1)
        if start.implied > start.value:
            self._violate("initial_error", start.robot, start.implied, 0.0)

    @classmethod
    def for_team(
        cls,
        team: Team,
        rule: str,
        command_limit: float,
        start: StartBound,
        x0: np.ndarray,
        z0: np.ndarray,
        events: Any,
    ) -> Monitor:
        """The premises of a run's threshold rule (its name ``rule``) for ``team``
        (:class:`~.onboard.team.Team`), watched against the truth: its bounds read from the
        team's configuration and thresholds block (Φ̄ for the drive rule, else ē)."""
        th, cfg = team.thresholds, team.config
        phi_bar = float(getattr(th, "phi_bar", 0.0)) if rule == "drive" else 0.0
        return cls(
            n=team.n,
            dt=cfg.dt,
            eta_bar=cfg.eta_bar,
            xi_bar=cfg.xi_bar,
            drift_bound=float(getattr(th, "drift", cfg.drift_bound)),
            phi_bar=phi_bar,
            command_limit=command_limit,
            start=start,
            x0=x0,
            z0=z0,
            events=events,
            memory=lambda k: memory(cfg.graph, cfg.ko, k),  # the start's graph
        )

    def period(
        self,
        t: float,
        x: np.ndarray,
        eta: np.ndarray,
        u: np.ndarray,
        u_bar: np.ndarray,
        phi_hat: np.ndarray,
        height: np.ndarray,
        level: np.ndarray,
        depth: np.ndarray,
    ) -> None:
        """Check one control period against the truth sensed at its start: true positions
        ``x``, noise ``eta``, applied inputs ``u``, commands ``u_bar`` and fault estimates
        ``phi_hat`` (N, 2); each base's ``height``, ``level`` (cos of its tilt) and contact
        ``depth`` (N,) (:class:`~.physics_step.Sensed`)."""
        planar, ended = _check(
            x, eta, u, u_bar, phi_hat, height, level, depth, self.watched, self.x0, self.int_u,
            self.slow, self.z0, self.value, self.h, self.eta_bar, self.step, self.offset,
            self.phi_bar, self.limit, t, self.period_spans, self._order, self._seq, self.last,
            self._rows, self._add, self._top, self._top_robot,
        )  # fmt: skip
        if planar >= 0:
            i = planar
            tilt = np.degrees(np.arccos(np.clip(level[i], -1.0, 1.0)))
            self.finish(t)
            raise SimulationError(
                f"robot {i + 1} left the plane at t = {t:.2f} s: its base is at height "
                f"{height[i]:.3f} m (started at {self.z0[i]:.3f} m, tolerance "
                f"{HEIGHT_TOLERANCE:g} m) and tilted {tilt:.0f}° (tolerance "
                f"{np.degrees(TILT_TOLERANCE):.0f}°): the planar model of eq. 1 no longer "
                "describes it; the run was stopped"
            )
        if ended or self.spans:
            self._close(t, False)

    def graph_changed(self, t: float, strongly_connected: bool) -> None:
        """After an exclusion: a graph that is not strongly connected violates the premise
        of every rule from now on (its thresholds are unbounded)."""
        if not strongly_connected:
            self.split = True
            self._violate("connectivity", None, 1.0, t)

    def joint_graph(self, t: float, parts: int) -> None:
        """At a round: the links that delivered within the window leave the members' graph in
        ``parts`` strongly connected parts (more than 1 breaks the premise)."""
        if parts > 1:
            self._violate("connectivity", None, float(parts), t)

    def network(self, t: float, links: int) -> None:
        """At a round of the observers, ``links`` links lacked the round's message or carried
        a corrupted one: the team's residuals leave the rules' identity (value: how many)."""
        self._violate("network", None, float(links), t)

    def slot(
        self, t: float, judged: np.ndarray, x: np.ndarray, slots: np.ndarray, tol: float
    ) -> None:
        """Silent robots that their listeners judged by sight this period (``judged`` (N,)):
        a healthy one at its true position ``x`` farther than ``tol`` from its slot
        (``slots`` (N, 2)) breaks the premise of the sighting rule."""
        self.bounds["slot"] = tol
        for j in np.flatnonzero(judged & self.watched):
            off = float(np.hypot(*(x[j] - slots[j])))
            if off > tol:
                self._violate("slot", int(j), off, t)

    def _violate(self, name: str, robot: int | None, value: float, t: float) -> None:
        k = self._index[name]
        if robot is None:
            self.team_last[k] = t
        else:
            self.last[k, robot] = t
        key = (name, robot)
        span = self.spans.get(key)
        if span is None:
            self.spans[key] = [t, value, t, int(self._seq[0])]
            self._seq[0] += 1
        else:
            span[1] = max(span[1], value)
            span[2] = t
        if value > self.worst[name][0] or self.worst[name][1] is None:
            self.worst[name] = (value, None if robot is None else robot + 1)

    def _close(self, t: float, final: bool) -> None:
        """Tell the spans that ended by ``t`` (every open one if ``final``) as events, in
        the order they began."""
        ended = []  # (rank, premise, robot, t0, worst, last)
        for key in list(self.spans):
            t0, worst, last, rank = self.spans[key]
            if final or t - last >= GAP - 1e-9:
                name, robot = key
                if name == "connectivity" and self.split:
                    if not final:
                        continue  # an exclusion split the graph: it lasts until the end
                    last = t
                del self.spans[key]
                ended.append((rank, name, robot, t0, worst, last))
        spans = self.period_spans
        open_ = ~np.isnan(spans[0])
        due = open_ if final else open_ & (t - spans[2] >= GAP - 1e-9)
        for p, i in zip(*np.nonzero(due), strict=True):
            name = _PER_PERIOD[p]
            ended.append((int(self._order[p, i]), name, int(i), *spans[:, p, i].tolist()))
            spans[0, p, i] = np.nan
        for _, name, robot, t0, worst, last in sorted(ended, key=lambda e: e[0]):
            self.count[name] += 1
            self.events.add(
                t0,
                Kind.PREMISE_VIOLATED,
                premise=name,
                robot=None if robot is None else robot + 1,
                value=float(worst),
                bound=float(self.bounds[name]),
                until=round(float(last), 6),
            )

    def violated(self, robot: int, t: float) -> list[str]:
        """The premises robot ``robot`` (0-based), or the team, violated within the memory of
        its residuals before ``t``, in :data:`PREMISES` order."""
        if robot not in self._memory:
            found = self._memory_of(robot) if self._memory_of is not None else 0.0
            self._memory[robot] = max(found, LOOKBACK)
        since = t - self._memory[robot]
        return [
            p
            for k, p in enumerate(PREMISES)
            if self.last[k, robot] >= since
            or self.team_last[k] >= since
            or (p == "connectivity" and self.split)  # a split lasts to the end of the run
        ]

    def finish(self, t: float) -> None:
        """Close every open span at the end of the run."""
        self._close(t, True)

    def table(self) -> dict[str, dict[str, Any]]:
        """Per premise: held or not, its worst value (robot) against its bound, spans."""
        out = {}
        for p, meaning in PREMISES.items():
            worst, robot = self.worst[p]
            held = self.count[p] == 0 and not any(k[0] == p for k in self.spans)
            if p in _PER_PERIOD:
                q = _PER_PERIOD.index(p)
                worst = float(self._top[q])
                robot = int(self._top_robot[q]) + 1 if self._top_robot[q] >= 0 else None
                held = held and bool(np.isnan(self.period_spans[0, q]).all())
            if p == "initial_error":
                held = self.start.implied <= self.start.value
            out[p] = {
                "held": bool(held),
                "worst": float(worst),
                "robot": robot,
                "bound": float(self.bounds[p]),
                "spans": int(self.count[p]),
                "meaning": meaning,
            }
        out["initial_error"]["derived"] = self.start.derived
        return out


def memory(graph: Any, ko: float, robot: int) -> float:
    """How long robot ``robot``'s residuals remember what happened to it [s]: the time after
    which κ_k e^(−λ_k t) of eq. 41 (the decay of the observer's error for k) is below
    :data:`MEMORY_FRACTION`. 8 s on the paper's graph, 210 s on a 100-robot ring with
    chord 2, 1360 s at 400: a premise violated that long before a flag may still be in it.
    Only the robots flagged need it, so it is computed for one robot at a time."""
    from ..onboard.thresholds import decay_bound_of

    kappa, lam = decay_bound_of(graph, ko, robot)
    if not lam > 0.0:
        return math.inf
    return math.log(max(kappa, 1.0) / MEMORY_FRACTION) / lam
