"""The N onboard DFTC stacks of Fig. 1, batched on a leading robot axis.

Row i of every array belongs to robot i and is computed from robot i's own
measurement and inputs, the messages ʲŷ of its in-neighbours j (delivered by
:class:`~dftc_mujoco.onboard.observer.Messages` along the graph's edges), its
own sensing of obstacles and the mission every robot is given.

Robots are identified by their index in the original team (0-based). The
*members* are those still in the team; collective vectors (ⁱŷ, ⁱx̂, ⁱr, the
thresholds, the flags) are sized by the members and shrink at an exclusion
(eqs. 42-43). The local fault estimator is a per-robot block and keeps
running on every robot, member or not.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..graph import Graph
from ..mission import FormationPlan, formation_offsets, replan
from ..scenario import Formation
from . import controller, kernel, observer
from .fault_estimator import FaultEstimator
from .fdir import Decision, Thresholds
from .supervisor import Supervisor


@dataclass(frozen=True)
class TeamConfig:
    """Everything the onboard stacks are configured with (no simulator state)."""

    graph: Graph
    kc: float
    ko: float
    K: np.ndarray
    G: np.ndarray
    theta: float
    dt: float  # control period
    eta_bar: float
    xi_bar: float
    formation: Formation
    obstacle_position: np.ndarray  # (O, 2) what the robots' sensors report
    obstacle_safe: np.ndarray  # (O,) d of eq. 17
    obstacle_activation: np.ndarray  # (O,)
    detection_window: float = 0.2
    dt_d_max: float = 5.0
    initial_error_bound: float = 1.0
    replan_time: float = 4.0
    excluded_safe: float = 0.35  # d around a robot that was excluded (it is still a body)
    excluded_activation: float = 0.45
    phi_low_pass: float = 0.0
    command_limit: float = np.inf  # per-axis planar command range of the robots [m/s]
    compiled: bool = True  # use the numba kernel (onboard/kernel.py) when it is installed
    fdir: bool = True  # False: nominal DFTC only (no compensation, no decisions)
    compensate: bool = True  # False: φ̂ estimated but not applied (ū = u)


@dataclass
class TeamOutput:
    """One control period of the whole team, on the *original* robot axis (N).

    Entries of robots that are no longer members are NaN (or False / 0).
    """

    u: np.ndarray  # (N, 2) nominal input uᵢ of eq. 8 (0 once excluded)
    u_bar: np.ndarray  # (N, 2) input sent to the actuators, ūᵢ = uᵢ − φ̂ᵢ (eq. 28)
    phi_hat: np.ndarray  # (N, 2)
    x_hat: np.ndarray  # (N, N, 2) ⁱx̂ at this instant (before the update)
    x_d: np.ndarray  # (N, 2) desired positions of the members
    residual: np.ndarray  # (N, N) ‖ⁱr_k‖ (eq. 35)
    threshold: np.ndarray  # (N, N) ⁱμ_k (eq. 40)
    flag: np.ndarray  # (N, N) robot i currently flags robot k
    flagged: np.ndarray  # (N,) bool: some teammate (i ≠ k) currently flags robot k
    reactive: np.ndarray  # (N,) bool
    avoiding: np.ndarray  # (N,) int: cylinder index, O + robot id for an excluded robot, or -1
    active: np.ndarray  # (N,) bool: member of the team
    events: list[dict[str, Any]] = field(default_factory=list)


class Team:
    """The team's onboard computers; :meth:`step` advances all of them by one period."""

    def __init__(self, config: TeamConfig, x_m0: np.ndarray, centroid0: np.ndarray) -> None:
        n = config.graph.n
        self.config = config
        self.n = n
        self.members = np.arange(n)
        self.gone = np.zeros(0, dtype=np.int64)  # robots excluded so far
        self.graph = config.graph
        offsets = formation_offsets(config.formation, n)
        self.plan = FormationPlan.fixed(offsets)
        self.messages = observer.Messages(self.graph.edges, n)
        # every robot starts believing its teammates are at their planned slots
        self.state = observer.ObserverState.initial(x_m0, prior=centroid0 + offsets)
        self.supervisor = Supervisor(n, config.theta)
        self.estimator = FaultEstimator(
            config.K,
            config.G,
            config.dt,
            x_m0,
            command_limit=config.command_limit,
            low_pass=config.phi_low_pass,
        )
        self.thresholds = Thresholds(
            self.graph,
            config.ko,
            config.eta_bar,
            config.xi_bar,
            np.full(n, config.initial_error_bound),
        )
        self.decision = Decision(n, config.detection_window, config.dt)
        self._others = ~np.eye(n, dtype=bool)  # i ≠ k
        self._nobody = np.full(n, -1)
        self._nobody.setflags(write=False)
        self.active = np.ones(n, bool)  # member of the team, on the original robot axis
        # the numba kernel computes the same period when it covers this configuration
        self.compiled = bool(
            config.compiled
            and kernel.AVAILABLE
            and config.fdir
            and config.compensate
            and config.phi_low_pass == 0
        )
        self._K = np.ascontiguousarray(config.K, dtype=float)
        self._g_inv = np.linalg.inv(config.G)
        self.first_detection: dict[int, float] = {}  # robot id -> earliest flag by anyone
        self.pending: dict[int, float] = {}  # robot id -> exclusion instant t_r (eq. 43)
        self.detected: set[tuple[int, int]] = set()  # (by, robot) pairs already reported

    # ------------------------------------------------------------------ one period

    def step(
        self,
        t: float,
        x_m: np.ndarray,
        c: np.ndarray,
        c_dot: np.ndarray,
        sensed_bodies: np.ndarray | None = None,
    ) -> TeamOutput:
        """One control period for every robot.

        ``x_m`` (N, 2): each robot's own noisy position; ``c``, ``c_dot``: the
        desired centroid and its velocity (σ₁,d, σ̇₁,d); ``sensed_bodies``
        (N, 2): where each robot's range sensor sees every robot (used only
        for robots that were excluded, which become obstacles).
        """
        cfg = self.config
        events: list[dict[str, Any]] = []
        if self.pending:
            self._exclusions_due(t, events)
        mem = self.members
        m = len(mem)

        offsets, rates = self.plan.at(t)
        if self.compiled:
            return self._compiled_step(t, x_m, c, c_dot, offsets, rates, sensed_bodies, events)
        x_d = c + offsets  # J⁻¹σ_d for the members
        xd_dot = c_dot + rates
        x_hat = self.state.estimate()  # eq. 21
        u_hat_g = controller.collective_input(x_hat, x_d, xd_dot, cfg.kc)  # eq. 15
        u_g = controller.own_input(u_hat_g)  # eq. 16
        whole = m == self.n
        x_own = x_m if whole else x_m[mem]
        obs_p, obs_d, obs_a = self._obstacles(sensed_bodies)
        u_mem, delta_u = self.supervisor.step(x_own, u_g, obs_p, obs_d, obs_a)
        r = observer.residual(self.state, self.messages, x_own)  # eq. 35
        observer.update(self.state, r, u_hat_g, delta_u, u_mem, cfg.ko, cfg.dt)

        if whole:
            u = u_mem
        else:
            u = np.zeros((self.n, 2))
            u[mem] = u_mem  # an excluded robot is told to stay where it is
        r_norm = np.sqrt(np.einsum("ikd,ikd->ik", r, r))
        mu = self.thresholds.mu(t)
        if cfg.fdir:
            u_bar = self.estimator.step(x_m, u)  # eqs. 28-31, nominal u (NOTES 2)
            if not cfg.compensate:
                u_bar = u
            raised = self.decision.update(r_norm, mu)
            if raised.any():
                self._report(t, raised, events)
        else:
            u_bar = u

        return self._output(u, u_bar, x_hat, x_d, r_norm, mu, events)

    def _compiled_step(self, t, x_m, c, c_dot, offsets, rates, sensed, events) -> TeamOutput:
        """The same period as :meth:`step`, through the numba kernel (onboard/kernel.py)."""
        cfg = self.config
        st, est, dec, mem = self.state, self.estimator, self.decision, self.members
        x_hat = st.estimate()  # eq. 21, before the update (for the log)
        mu = self.thresholds.mu(t)
        before = dec.flag.copy()
        m = len(mem)
        u, u_bar, r_norm = np.empty((self.n, 2)), np.empty((self.n, 2)), np.empty((m, m))
        obs_p, obs_d, obs_a = self._obstacles(sensed)
        kernel.team_step(
            t,
            np.ascontiguousarray(x_m, dtype=float),
            np.asarray(c, float),
            np.asarray(c_dot, float),
            offsets,
            rates,
            mem,
            self.gone,
            st.y_hat,
            st.int_u_hat,
            st.int_u_own,
            self.messages.src,
            self.messages.first_edge,
            self.messages.in_degree,
            cfg.kc,
            cfg.ko,
            cfg.dt,
            obs_p,
            obs_d,
            obs_a,
            cfg.theta,
            self.supervisor.release,
            self.supervisor.active,
            est.z,
            est.int_e,
            est.phi_hat,
            self._K,
            self._g_inv,
            est.command_limit,
            dec.above,
            dec.below,
            dec.flag,
            mu,
            dec.window,
            u,
            u_bar,
            r_norm,
        )
        est.applied[...] = est.phi_hat  # no low-pass on this path: applied = φ̂
        raised = dec.flag & ~before
        if raised.any():
            self._report(t, raised, events)
        return self._output(u, u_bar, x_hat, c + offsets, r_norm, mu, events)

    def _output(self, u, u_bar, x_hat, x_d, r_norm, mu, events) -> TeamOutput:
        """The period's outputs on the original robot axis (members' arrays expanded)."""
        mem, m, dec = self.members, len(self.members), self.decision
        return TeamOutput(
            u=u,
            u_bar=u_bar,
            phi_hat=self.estimator.phi_hat.copy(),
            x_hat=_expand(x_hat, mem, self.n, (2,)),
            x_d=_expand(x_d, mem, self.n, (2,)),
            residual=_expand(r_norm, mem, self.n),
            threshold=_expand(mu, mem, self.n),
            flag=_expand(dec.flag.copy(), mem, self.n, fill=False),
            flagged=_expand((dec.flag & self._others[:m, :m]).any(axis=0), mem, self.n, fill=False),
            reactive=_expand(self.supervisor.reactive, mem, self.n, fill=False),
            avoiding=self._avoiding(),
            active=self.active.copy(),
            events=events,
        )

    # ------------------------------------------------------------------ FDIR

    def _report(self, t: float, raised: np.ndarray, events: list[dict[str, Any]]) -> None:
        """Detection events for first flags; schedule exclusions (eq. 43)."""
        for pi, pk in zip(*np.nonzero(raised), strict=True):
            by, robot = int(self.members[pi]), int(self.members[pk])
            if (by, robot) in self.detected:
                continue
            self.detected.add((by, robot))
            events.append({"kind": "detection", "t": t, "by": by, "robot": robot})
            if robot not in self.first_detection:
                self.first_detection[robot] = t
                self.pending[robot] = t + self.config.dt_d_max  # t_r = min ⁱt_d + Δt_d,max
                events.append(
                    {
                        "kind": "exclusion_scheduled",
                        "t": t,
                        "robot": robot,
                        "t_r": t + self.config.dt_d_max,
                    }
                )

    def _exclusions_due(self, t: float, events: list[dict[str, Any]]) -> None:
        """At t_r, drop a robot that some teammate still flags (NOTES 10)."""
        for robot, t_r in sorted(self.pending.items(), key=lambda kv: kv[1]):
            if t + 1e-9 < t_r:
                continue
            del self.pending[robot]
            self.first_detection.pop(robot, None)
            p = int(np.flatnonzero(self.members == robot)[0])
            flaggers = [int(self.members[i]) for i in np.flatnonzero(self.decision.flag[:, p])]
            detectors = sorted(by for by, k in self.detected if k == robot)
            if not flaggers:
                events.append(
                    {
                        "kind": "exclusion_cancelled",
                        "t": t,
                        "robot": robot,
                        "detected_by": detectors,
                    }
                )
                self.detected = {(b, k) for b, k in self.detected if k != robot}
                continue
            self._exclude(t, p)
            events.append(
                {
                    "kind": "exclusion",
                    "t": t,
                    "robot": robot,
                    "flagged_by": flaggers,
                    "detected_by": detectors,
                }
            )
            if not self.graph.is_strongly_connected():
                events.append(
                    {
                        "kind": "graph_not_strongly_connected",
                        "t": t,
                        "robots": [int(k) for k in self.members],
                    }
                )

    def _exclude(self, t: float, p: int) -> None:
        """Resize every collective vector from M n to (M − 1) n (§5.2.2) and re-plan."""
        keep = np.delete(np.arange(len(self.members)), p)
        bound = self.thresholds.bracket(t)[keep]  # ‖ỹ*_k(t_r)‖ for the remaining k
        old_offsets, _ = self.plan.at(t)
        self.gone = np.append(self.gone, self.members[p])
        self.active[self.members[p]] = False
        self.members = self.members[keep]
        self.graph = self.graph.without(p)
        s = self.state
        s.y_hat = s.y_hat[np.ix_(keep, keep)]
        s.int_u_hat = s.int_u_hat[np.ix_(keep, keep)]
        s.int_u_own = s.int_u_own[keep]
        self.messages = observer.Messages(self.graph.edges, len(keep))
        self.supervisor.active = self.supervisor.active[keep]
        self.supervisor.n_robots = len(keep)
        self.decision.drop(p)
        cfg = self.config
        self.thresholds = Thresholds(self.graph, cfg.ko, cfg.eta_bar, cfg.xi_bar, bound, t0=t)
        target = replan(cfg.formation, old_offsets[keep])
        self.plan = FormationPlan(old_offsets[keep], target, t0=t, blend=cfg.replan_time)

    def _avoiding(self) -> np.ndarray:
        """What each robot avoids: cylinder o as o, excluded robot j as O + j, nothing as -1."""
        n_cyl = len(self.config.obstacle_position)
        act = self.supervisor.active
        if act.max() < 0:
            return self._nobody  # shared, read-only
        gone = self.gone
        label = np.where(
            act >= n_cyl, n_cyl + gone[np.clip(act - n_cyl, 0, None)] if len(gone) else act, act
        )
        out = np.full(self.n, -1)
        out[self.members] = label
        return out

    def _obstacles(self, sensed: np.ndarray | None) -> tuple[np.ndarray, ...]:
        cfg = self.config
        gone = self.gone
        if sensed is None or len(gone) == 0:
            return cfg.obstacle_position, cfg.obstacle_safe, cfg.obstacle_activation
        return (
            np.vstack([cfg.obstacle_position, sensed[gone]]),
            np.concatenate([cfg.obstacle_safe, np.full(len(gone), cfg.excluded_safe)]),
            np.concatenate([cfg.obstacle_activation, np.full(len(gone), cfg.excluded_activation)]),
        )


def _expand(
    a: np.ndarray, members: np.ndarray, n: int, tail: tuple[int, ...] = (), fill: Any = np.nan
) -> np.ndarray:
    """Place a members-indexed array on the original robot axis (and axes)."""
    m = len(members)
    if m == n:
        return a  # the whole team: no copy (callers copy what they keep)
    dtype = bool if fill is False else float
    if a.ndim - len(tail) == 1:
        out = np.full((n, *a.shape[1:]), fill, dtype=dtype)
        out[members] = a
    else:
        out = np.full((n, n, *a.shape[2:]), fill, dtype=dtype)
        out[members[:, None], members[None, :]] = a  # (np.ix_ costs more, every step)
    return out
