"""The N onboard DFTC stacks of Fig. 1, batched on a leading robot axis.

Row i of every array belongs to robot i and is computed from robot i's own
measurement and inputs, the messages ʲŷ of its in-neighbours j (delivered
along the graph's edges only, :class:`~dftc_mujoco.onboard.observer.Messages`),
its own sensing of obstacles and the mission every robot is given.

A team composes six blocks (observer, controller, supervisor, fault
estimator, thresholds, decision): the paper's (:mod:`dftc_mujoco.blocks.paper`)
by default, or a user's. With the paper's blocks the period runs as one
compiled call (:mod:`.period`) built from the blocks' own compiled functions;
with a user's block the team calls the blocks' Python methods in the same
order (the *general* path). Both paths compute the same thing.

Robots are identified by their index in the original team (0-based inside,
1-based in events). The *members* are those still in the team; collective
vectors (ⁱŷ, ⁱx̂, ⁱr, the thresholds, the flags) are sized by the members and
shrink at an exclusion (eqs. 42-43). The local fault estimator is a per-robot
block and keeps running on every robot, member or not.
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from typing import Any, cast

import numpy as np

from ...core.events import Event, Kind, make
from ...core.mission import FormationPlan, formation_offsets, replan
from ..applied import DriveModel
from ..block import Block, TeamConfig, shaped
from ..controller import Controller
from ..decision import Decision, flagged_by_teammates
from ..detector import Detector
from ..estimate_alarm import EstimateAlarm
from ..fault_estimator import FaultEstimator, held
from ..observer import Observer
from ..paper_blocks import PAPER_BLOCKS, choose_blocks
from ..radio import Radios, Rounds
from ..recovery import Recovery, admitted, split_event, worst_ratio
from ..sighting import Sighting
from ..supervisor import Supervisor, Surroundings, grid_work, obstacle_label
from ..thresholds import Thresholds
from ..thresholds.delays import detection_horizon
from ..thresholds.paper import ThresholdRecord, dense_thresholds
from ..thresholds.settling import refuse_bad_entry, rule_settle_time
from .general import general_period
from .log_row import write_row
from .period import (
    RAISED,
    SWITCHED,
    PeriodBuffers,
    PeriodInputs,
    begin_call,
    commands_call,
    integrate_call,
    rows_call,
    team_period_call,
)
from .records import fields
from .sharing import Sharing
from .team_axis import expand

__all__ = ["PAPER_BLOCKS", "Team", "TeamConfig", "runs_compiled"]

# the blocks the compiled period contains (thresholds enter it as an array)
_COMPILED = ("observer", "controller", "supervisor", "fault_estimator", "decision", "detector")
#: [s] a robot's fault estimator holds from its bumper's first touch until the bumper stayed
#: off this long: a robot jammed against a teammate touches on and off, and each free period
#: wound φ̂ up again (battery run 871: 5.7 m/s of compensation released at the jam's end)
HOLD_AFTER_CONTACT = 0.5
#: [s] a held robot with a lagged drive measures its own velocity over this window
VELOCITY_WINDOW = 0.1


def runs_compiled(blocks: Mapping[str, Block]) -> bool:
    """Whether a team of these blocks can run the compiled period: the paper's own classes
    in every block it contains (a thresholds rule of any class enters it as an array)."""
    return all(type(blocks[k]) is PAPER_BLOCKS[k] for k in _COMPILED if k in blocks)


class Team:
    """The team's onboard computers; :meth:`step` advances all of them by one period.

    After a step the period's outputs are attributes: ``u`` and ``u_bar`` (N, 2)
    on the original robot axis (nominal input of eq. 8 and the compensated one
    sent to the actuators, eq. 28); ``x_hat`` (M, M, 2) the estimates before the
    update (on the compiled path written only while :attr:`estimates` is true), ``x_d``
    (M, 2), ``r_norm`` and ``mu`` (M, M) on the members' axis.
    Events (1-based robots) accumulate in ``events`` until the caller takes them.
    """

    def __init__(
        self,
        config: TeamConfig,
        x_m0: np.ndarray,
        centroid0: np.ndarray,
        blocks: Mapping[str, Block] | None = None,
    ) -> None:
        chosen = choose_blocks(blocks)
        n = config.graph.n
        self.config = config
        self.n = n
        self.blocks = chosen
        # typed as the paper's blocks: a plug-in keeps their interface (README, "Blocks")
        self.observer = cast(Observer, chosen["observer"])
        self.controller = cast(Controller, chosen["controller"])
        self.supervisor = cast(Supervisor, chosen["supervisor"])
        self.estimator = cast(FaultEstimator, chosen["fault_estimator"])
        self.thresholds = cast(Thresholds, chosen["thresholds"])
        # a rule of its own (M, M) array: its shape and least entry are read each round
        # (eq. 40's factors are the paper's own)
        self._dense_rule = type(self.thresholds).mu is not Thresholds.mu
        self.decision = cast(Decision, chosen["decision"])
        self.detector = cast(Detector, chosen["detector"])
        self.members = np.arange(n)
        self.gone = np.zeros(0, dtype=np.int64)  # robots excluded so far
        self.graph = config.graph
        offsets = formation_offsets(config.formation, n)
        self.plan = FormationPlan.fixed(offsets)
        x_m0 = np.asarray(x_m0, dtype=float)
        prior = centroid0 + offsets  # every robot starts believing its teammates are at their slots
        for slot, block in enumerate(chosen.values()):
            block.rng = np.random.default_rng([int(config.seed), 97, slot])  # one per block
            block.t = 0.0
            block.reset(config, x_m0, prior)
        # plug-in blocks are told the time of each period (the paper's read none)
        self._timed = [b for name, b in chosen.items() if type(b) is not PAPER_BLOCKS[name]]
        # the compiled period contains the paper's blocks, not subclasses of them
        self.compiled = bool(config.compiled and runs_compiled(chosen))
        self.active = np.ones(n, bool)  # member of the team, on the original robot axis
        self.u = np.zeros((n, 2))
        self.u_bar = np.zeros((n, 2))
        # each robot's model of its own drive (onboard/applied.py): what it commands, and the
        # velocity v̂ a first-order lag of config.lag delivers
        self.drive = DriveModel(
            n, config.dt, config.input_limit, config.accel, config.lag,
            config.start_accel, config.start_time,
        )  # fmt: skip
        self._reactive = np.zeros(n, bool)  # on the original axis, for switch events
        self.events: list[Event] = []
        self.ended: str | None = None  # why the mission ended early (the team fell apart)
        self.dt_d_max, self.dt_d_max_info = detection_horizon(config, config.graph, self.thresholds)
        # the exclusion protocol (eqs. 42-43) under the fault hypothesis
        self.recovery = Recovery(
            self.dt_d_max,
            config.max_faults,
            config.self_exclusion,
            config.postpone_on_contact,
            config.run_length,
        )
        # each robot's own alarm from its fault estimate confirms its exclusion
        self.alarm = EstimateAlarm.of(config, n, getattr(self.thresholds, "phi_bar", None))
        self._scratch(config, n)
        self._resize()
        # what the team shows before its first period: the robots' first estimates and slots
        np.copyto(self.x_hat, self.observer.estimate())
        self.x_d[:] = prior

    def _scratch(self, config: TeamConfig, n: int) -> None:
        """The state the team keeps between periods besides its blocks': contacts, the
        network's rounds and radios, the sighting of silent robots, what a pass under way
        was given."""
        self._teammates = np.zeros(n, bool)  # scratch: who is flagged by a teammate
        self.sensed = False  # the last period had range-sensor readings
        # a plug-in supervisor whose step() predates teammate avoidance is called without it
        step_params = inspect.signature(self.supervisor.step).parameters
        self.supervisor_sees_mates = "teammates" in step_params
        self.estimator_holds = "hold" in inspect.signature(self.estimator.step).parameters
        self.touch = np.zeros(n, bool)  # each robot's bumper, held HOLD_AFTER_CONTACT s
        self._untouched = np.full(n, np.inf)  # periods each robot's bumper has been off
        self._hold_periods = HOLD_AFTER_CONTACT / config.dt
        # a lagged drive's velocity is the robot's: a jam stops it while the model runs on,
        # so a held robot re-reads v̂ from its own measurements over the last VELOCITY_WINDOW
        self._window = max(1, round(VELOCITY_WINDOW / config.dt))
        self._x_past = np.zeros((self._window, n, 2))
        self._k = 0
        # the network: the observers step in rounds of R periods (1: the ideal network)
        self.rounds = Rounds(  # rounds only over a network (which the radios model)
            config.round_periods if config.networked else 1, config.observer_period
        )
        self.radios = Radios(self.observer, n) if config.networked else None
        tol, reach, wd = config.sighting_tolerance, config.sighting_range, config.detection_window
        see = config.networked and config.fdir and tol > 0 and reach > 0
        self.sighting = Sighting(n, tol, reach, wd, config.dt) if see else None  # silent robots
        #: write the estimates ⁱx̂ this period (the loop asks only at the periods whose log
        #: row or snapshot shows them: they are the largest array a period writes)
        self.estimates = True
        self._norms_kept = True  # the last period wrote r_norm (see _compiled)
        self._code = 0  # what start() found, for finish()
        self._pending: tuple[Any, ...] | None = None  # a shared pass under way (its fields)
        self._given: tuple[Any, ...] = (None,) * 5  # what start() was given, for finish()
        self._mu_t = 0.0
        self.never_flags = False  # the thresholds are +inf everywhere (settle_time looks)
        self.horizon: float | None = None  # the run's duration, once settle_time has looked
        self.settles_at = 0.0  # T_s: faults from then on are in eq. 46's domain
        self.restarted_at: float | None = None  # the last exclusion, which restarted the rule

    def settle_time(self, horizon: float) -> float:
        """T_s of the team's thresholds (:func:`~.thresholds.settling.rule_settle_time`), up
        to ``horizon`` [s]: eq. 46's domain from here on; the recovery waits it after a contact."""
        self.horizon = horizon  # each exclusion's restarted rule settles anew within it
        settled, self.never_flags = rule_settle_time(
            self.thresholds, self.members, self.config.dt, horizon
        )
        self.recovery.settle = settled  # waited after a contact (inf: not within the horizon)
        self.settles_at = settled
        return settled

    @property
    def path(self) -> str:
        """Which path runs the period: ``"compiled"`` or ``"general"``."""
        return "compiled" if self.compiled else "general"

    def _resize(self) -> None:
        """Buffers on the members' axis (allocated at the start and at exclusions only)."""
        m = len(self.members)
        self.x_own = np.empty((m, 2))
        self.x_d = np.empty((m, 2))
        self.xd_dot = np.empty((m, 2))
        self.x_hat = np.full((m, m, 2), np.nan)  # written at the periods that ask (estimates)
        self._u_g = np.empty((m, 2))
        self._u_mem = np.empty((m, 2))
        self._du = np.empty((m, 2))
        # one robot's residual per thread the compiled period's pass runs in (sharing.py)
        cfg = self.config
        threads = cfg.threads if self.compiled and m >= cfg.shared_from else 1
        self._sharing = Sharing(threads) if threads > 1 else None
        self._row = np.empty((threads, m * 2))
        self.mates = np.zeros((m, 2))  # where the range sensors see the members
        # ‖ⁱr_k‖ (none before the first round of a network), then each thread's scratch row
        self._norms = np.zeros((m + threads, m))
        self.raised = np.zeros((m, m), bool)
        self.mu = np.full((m, m), np.inf)  # no thresholds before the first round
        gone = len(self.gone)
        self.obs_p = np.vstack([cfg.obstacle_position.reshape(-1, 2), np.zeros((gone, 2))])
        self._gone_p = self.obs_p[len(cfg.obstacle_position.reshape(-1, 2)) :]  # a view
        self.obs_d = np.concatenate([cfg.obstacle_safe, np.full(gone, cfg.excluded_safe)])
        self.obs_a = np.concatenate(
            [cfg.obstacle_activation, np.full(gone, cfg.excluded_activation)]
        )
        self._seen = Surroundings(self.obs_p, self.obs_d, self.obs_a, self.mates)
        self._flat: list[tuple[Any, ...]] = []  # see _fields
        # the decision's scale is written each round (bound_squares)
        self._buffers = PeriodBuffers(
            self.x_own, self.x_d, self.xd_dot, self.x_hat, self._u_g, self._u_mem, self._du,
            self._row, self._norms, self.u, self.u_bar, grid_work(m), np.full(m * 2, np.nan),
        )  # fmt: skip

    # ------------------------------------------------------------------ one period

    def step(
        self,
        t: float,
        x_m: np.ndarray,
        c: np.ndarray,
        c_dot: np.ndarray,
        sensed_bodies: np.ndarray | None = None,
        touching: np.ndarray | None = None,
    ) -> int:
        """One control period for every robot (:meth:`start`, then :meth:`finish`); returns
        RAISED | SWITCHED | SATURATED bits.

        ``x_m`` (N, 2): each robot's own noisy position; ``c``, ``c_dot``: the
        desired centroid and its velocity (σ₁,d, σ̇₁,d); ``sensed_bodies``
        (N, 2): where each robot's range sensor sees every robot (robots that were
        excluded become obstacles; teammates are avoided when ``teammate_safe`` > 0;
        None: no sensor reading); ``touching`` (N,): each robot's bumper (None: no bumpers).
        """
        self.start(t, x_m, c, c_dot, sensed_bodies, touching)
        return self.finish(t)

    def start(
        self,
        t: float,
        x_m: np.ndarray,
        c: np.ndarray,
        c_dot: np.ndarray,
        sensed_bodies: np.ndarray | None = None,
        touching: np.ndarray | None = None,
    ) -> None:
        """The period up to its commands: once it returns, ``u`` and ``u_bar`` are this
        period's. A team that shares its pass (:attr:`shares`) has handed the pass over the
        N × N state to helper threads, which run it while the caller sends the commands and
        steps the physics; :meth:`finish` ends the period (the arguments: :meth:`step`)."""
        self.drive.at(t)  # the ramped start's acceleration, then the drive's own
        if touching is not None:
            # a jammed robot's bumper flickers; the estimator holds until it stayed off a while
            touched = held(self._untouched, touching, self._hold_periods, self.touch)
            if self.drive.lagged:
                slot = self._k % self._window
                if self._k >= self._window and self.touch.any():
                    seen = (x_m - self._x_past[slot]) / (self._window * self.config.dt)
                    self.drive.v_hat[self.touch] = seen[self.touch]
                self._x_past[slot] = x_m
                self._k += 1
            if touched:
                self.recovery.contact(t, np.flatnonzero(touching & self.active))
        if self.recovery.pending:
            self._exclusions_due(t)
        self.sensed = sensed_bodies is not None
        if sensed_bodies is not None:
            if len(self.gone):
                sensed_bodies.take(self.gone, axis=0, out=self._gone_p)  # the robots that left
            if self.config.teammate_safe > 0:
                if len(self.mates) == self.n:  # every robot a member: a copy, not a gather
                    self.mates[...] = sensed_bodies
                else:
                    sensed_bodies.take(self.members, axis=0, out=self.mates)
        offsets, rates = self.plan.at(t)
        for b in self._timed:
            b.t = t
        radios = self.radios
        if radios is None:  # the paper's network: the observers step every period
            t_rule: float | None = t
        elif self.rounds.tick():  # a round of the observers
            t_rule = self.rounds.rule_time(t)
            self.events += radios.watch(t, self.rounds.index, self.members)
        else:
            t_rule = None
        m = len(self.members)
        if t_rule is not None and self.compiled:  # the record (eq. 40: its factors)
            self._th = self.thresholds.record(t_rule)
            if self._dense_rule and self._th.dense.shape != (m, m):  # read past a smaller one
                shaped(self._th.dense, (m, m), self.thresholds, "mu(t)")
            self._mu, self._mu_t = None, t_rule  # mu written out only when read
        elif t_rule is not None:
            self._mu = shaped(self.thresholds.mu(t_rule), (m, m), self.thresholds, "mu(t)")
        if self._dense_rule and t_rule is not None:  # a rule's own array, every round
            mu = self._th.dense if self.compiled else self.mu
            if not mu.min() >= 0:  # a negative or NaN entry flags everybody or nobody
                refuse_bad_entry(mu, self.members, self.thresholds)
        if self.compiled:
            self._code = self._compiled(x_m, c, c_dot, offsets, rates)
        else:
            self._code = general_period(self, x_m, c, c_dot, offsets, rates)
        if self.alarm.on and not self.compiled:  # the compiled period runs it after ū
            self.alarm.step(self.estimator.phi_hat, self.u_bar)
        self._given = (c, c_dot, offsets, rates, sensed_bodies)

    def join(self) -> None:
        """End a shared pass that :meth:`start` handed to the helper threads, and nothing
        else of the period (for a caller stopped before :meth:`finish`)."""
        if self._pending is not None:
            self._joined(self._pending)

    def finish(self, t: float) -> int:
        """The rest of the period begun by :meth:`start` at ``t``: a shared pass ended and
        integrated, ŷ of the next period swapped in, the messages broadcast, the flags and
        behaviour switches turned into events; returns RAISED | SWITCHED | SATURATED bits."""
        code, pending = self._code, self._pending
        if pending is not None:
            code |= self._joined(pending)
        if self.compiled and self.rounds.now:
            self.observer.advance()  # ŷ of the next period (eq. 19)
        c, c_dot, offsets, rates, sensed_bodies = self._given
        radios = self.radios
        if radios is not None and self.rounds.now:
            self.observer.broadcast(self.rounds.stepped())
        if self.sighting is not None and sensed_bodies is not None:
            self.events += self.sighting.watch(t, self, c, c_dot, (offsets, rates), sensed_bodies)
        if code & RAISED:  # the compiled period's flags are the decision's own array
            self._report(t, self.decision.raised if self.compiled else self.raised)
        if radios is not None and self.rounds.now and self.config.fdir:
            # corrupted messages flag every column at once
            mf = admitted(self.config.max_faults, len(self.members))
            self.events += radios.message_faults(t, self.flag, self.members, mf)
        if code & RAISED or self.recovery.anomaly is not None:
            self._hypothesis(t)
        if code & SWITCHED:
            self._switches(t)
        return code

    @property
    def mu(self) -> np.ndarray:
        """(M, M) this round's thresholds ⁱμ_k (rows observe, columns are monitored)."""
        if self._mu is None:
            self._mu = self.thresholds.mu(self._mu_t)
        return self._mu

    @mu.setter
    def mu(self, value: np.ndarray) -> None:
        self._mu = value
        self._th = dense_thresholds(np.ascontiguousarray(value, dtype=float))

    @property
    def threshold_factors(self) -> ThresholdRecord | None:
        """The :class:`~.thresholds.paper.ThresholdRecord` of eq. 40's factors the compiled
        period read this round, from which :attr:`mu` is written (``Thresholds.mu``: the
        same numbers); None where the thresholds are an array (a rule's own, one set
        through :attr:`mu`, none yet after an exclusion over a network) or the period is
        not compiled."""
        th = self._th
        return th if self.compiled and th.dense.size == 0 else None

    def receive(self, links: np.ndarray, rounds: np.ndarray, offset: np.ndarray) -> None:
        """The network delivered messages (:meth:`.radio.Radios.receive`)."""
        if self.radios is not None:
            self.radios.receive(links, rounds, offset)

    @property
    def missed(self) -> int:
        """Links whose message was missing at the last round of the observers."""
        return self.radios.missed if self.radios is not None else 0

    @property
    def shares(self) -> bool:
        """The period's pass runs shared between threads, beside the commands and the
        physics (a compiled team of ``config.shared_from`` members or more, with
        ``config.threads`` > 1: :class:`~.execution.Execution`)."""
        return self._sharing is not None

    def _compiled(self, x_m, c, c_dot, offsets, rates) -> int:
        """The period as compiled stages over the blocks' state records (:mod:`.period`): one
        call, or (a shared pass) its first stages, the pass handed to the helper threads."""
        # the period's inputs; an ended team's last row shows its estimates
        keep = self.estimates or self.ended is not None
        # ‖ⁱr_k‖ where read: a log row, a snapshot, or the exclusion instant (at the next
        # period's start): a t_r is Δt_d,max after the flag, or a period after a postponement;
        # over a network a round's norms are read until the next round: always kept
        rec, dt = self.recovery, self.config.dt
        norms = keep or bool(rec.pending) or rec.dt_d_max < 2 * dt or self.radios is not None
        self._norms_kept = norms
        inputs = PeriodInputs(
            x_m, self.members, c, c_dot, offsets, rates, self.config.fdir, self.rounds.now,
            keep, norms,
        )  # fmt: skip
        flat = inputs + self._th + self._fields()
        sharing = self._sharing
        if sharing is None:
            return int(team_period_call(*flat))
        begin_call(*flat)  # each robot's own block of the state, before the pass moves it
        sharing.start(lambda lo, hi, b: rows_call(*flat, lo, hi, b), len(self.members))
        self._pending = flat
        try:
            return int(commands_call(*flat))  # beside the helpers' rows
        except BaseException:
            self._joined(flat)
            raise

    def _joined(self, flat: tuple[Any, ...]) -> int:
        """A shared pass ended (the caller taking the rows left) and integrated: RAISED or 0."""
        assert self._sharing is not None
        self._pending = None
        try:
            raised = self._sharing.finish()
        finally:
            integrate_call(*flat)
        return RAISED if raised else 0

    def _fields(self) -> tuple[Any, ...]:
        """The fields of the records after the period's inputs and the thresholds (the
        compiled entries take them in :data:`.period.RECORDS`' order). They change only at an
        exclusion (when :meth:`_resize` forgets them), but for ŷ and ŷ⁺, which swap every
        period, the range sensor's reading and the drive's acceleration after the start: a
        few are kept, each checked by the very objects it was made from."""
        y, sensed, accel = self.observer.y_hat, self.sensed, self.drive.accel_step
        for key_y, key_sensed, key_accel, kept in self._flat:
            if key_y is y and key_sensed == sensed and key_accel == accel:
                return kept
        records = (
            self.observer.record(),
            self.controller.record(),
            self.supervisor.record(sensed),
            self._seen,
            self.drive.record(),
            self.estimator.record(self.touch),
            self.alarm.record(),
            self.decision.record(),
            self._buffers,
        )
        kept = fields(records)
        if len(self._flat) >= 4:
            self._flat.clear()
        self._flat.append((y, sensed, accel, kept))
        return kept

    # ------------------------------------------------------------------ outputs

    @property
    def r_norm(self) -> np.ndarray:
        """(M, M) ‖ⁱr_k‖ of the last round (written where read: see :meth:`_compiled`)."""
        return self._norms[: len(self.members)]

    @r_norm.setter
    def r_norm(self, value: np.ndarray) -> None:
        self._norms[: len(self.members)] = value

    @property
    def flag(self) -> np.ndarray:
        """(M, M) robot i currently flags robot k."""
        return self.decision.flag

    @property
    def reactive(self) -> np.ndarray:
        """(M,) which members are on a reactive behaviour."""
        return np.asarray(self.supervisor.active) >= 0

    @property
    def phi_hat(self) -> np.ndarray:
        """(N, 2) every robot's fault estimate φ̂."""
        return self.estimator.phi_hat

    def outputs(self) -> dict[str, np.ndarray]:
        """The period's outputs on the original robot axis (NaN / False for non-members)."""
        mem, n = self.members, self.n
        flag = np.asarray(self.flag, bool)
        flagged = np.empty(len(mem), bool)  # some teammate flags the member
        flagged_by_teammates(flag, flagged)
        return {
            "u": self.u,
            "u_bar": self.u_bar,
            "phi_hat": self.phi_hat,
            "x_hat": expand(self.x_hat, mem, n, square=True),
            "x_d": expand(self.x_d, mem, n),
            "residual": expand(self.r_norm, mem, n, square=True),
            "threshold": expand(self.mu, mem, n, square=True),
            "flag": expand(flag, mem, n, square=True, fill=False),
            "flagged": expand(flagged, mem, n, fill=False),
            "reactive": expand(self.reactive, mem, n, fill=False),
            "active": self.active,
        }

    def write_row(
        self, log: dict[str, np.ndarray], row: int, fdir: bool = True, row_nn: int = -1
    ) -> None:
        """Write the period's outputs into row ``row`` of preallocated log arrays (original
        robot axis; the fields of :meth:`outputs` but ``u_bar`` and ``flag``); the N × N
        ones (estimates, residuals, thresholds) into row ``row_nn`` unless it is -1
        (:func:`.log_row.write_row`)."""
        write_row(self, log, row, fdir, row_nn)

    def avoiding(self) -> np.ndarray:
        """What each robot avoids, on the original axis: cylinder o as o, robot j (excluded,
        or a teammate) as O + j, nothing as -1."""
        n_cyl = len(self.config.obstacle_position)
        act = np.asarray(self.supervisor.active)
        robots = np.concatenate([self.gone, self.members])  # obstacles after the cylinders
        idx = np.clip(act - n_cyl, 0, max(len(robots) - 1, 0))
        label = np.where(act >= n_cyl, n_cyl + robots[idx] if len(robots) else act, act)
        out = np.full(self.n, -1)
        out[self.members] = label
        return out

    # ------------------------------------------------------------------ events

    def _switches(self, t: float) -> None:
        """reactive_on / reactive_off events for the robots whose behaviour changed."""
        now = expand(self.reactive, self.members, self.n, fill=False)
        changed = np.flatnonzero(now != self._reactive)
        if not len(changed):
            return
        avoiding = self.avoiding()
        n_cyl = len(self.config.obstacle_position)
        for i in changed:
            if now[i]:
                self.events.append(
                    make(
                        t,
                        Kind.REACTIVE_ON,
                        robot=int(i) + 1,
                        obstacle=obstacle_label(int(avoiding[i]), n_cyl),
                    )
                )
            else:
                self.events.append(make(t, Kind.REACTIVE_OFF, robot=int(i) + 1))
        self._reactive = np.array(now, copy=True)

    def _report(self, t: float, raised: np.ndarray) -> None:
        """Detection events for first flags; schedule exclusions (eq. 43)."""
        mem = self.members
        pairs = ((int(mem[i]), int(mem[k])) for i, k in zip(*np.nonzero(raised), strict=True))
        self.events += self.recovery.flagged(t, pairs)

    def _hypothesis(self, t: float) -> None:
        """A ``systemic_anomaly`` begins or ends: more robots flagged by teammates now than
        the fault hypothesis admits in the team as it is (``fdir.max_faults``)."""
        m = len(self.members)
        out = self._teammates[:m]
        flag = np.asarray(self.flag, bool)
        if self.recovery.self_exclusion:
            np.any(flag, axis=0, out=out)
        else:
            flagged_by_teammates(flag, out)
        flagged = [int(k) for k in self.members[out]]
        event = self.recovery.hypothesis(t, flagged, len(self.gone), m)
        if event is not None:
            self.events.append(event)

    def _exclusions_due(self, t: float) -> None:
        """At t_r, drop a robot that some teammate still flags (docs/notes.md, 10), unless a
        systemic anomaly holds."""
        for robot in self.recovery.due(t):
            p = int(np.flatnonzero(self.members == robot)[0])
            flag = np.asarray(self.flag, bool)
            if self.sighting is not None:  # flags raised by sight on a silent robot
                flag = flag | self.sighting.flag[np.ix_(self.members, self.members)]
            flaggers = [int(self.members[i]) + 1 for i in np.flatnonzero(flag[:, p])]
            counted = [b for b in flaggers if self.recovery.counts(b - 1, robot)]
            if self.recovery.anomaly is not None:
                self.events.append(self.recovery.cancel(t, robot, "systemic_anomaly"))
                continue
            if not counted:
                reason = "flagged only by itself" if flaggers else "not flagged"
                self.events.append(self.recovery.cancel(t, robot, reason))
                continue
            if not self._norms_kept:  # _compiled keeps them while an exclusion is pending
                raise RuntimeError("the residuals' norms of the last period were not kept")
            later = self.recovery.postpone(t, robot, worst_ratio(self.r_norm, self.mu, p))
            if later is not None:  # a contact may explain the flags: wait Δt_d,max past it
                self.events.append(later)
                continue
            heard = self.radios is None or not self.radios.silent_robot[robot]
            again = robot in self.recovery.waiting  # judged before, unconfirmed
            if not self.alarm.confirms(robot, heard, again):  # a healthy signal: judge it later
                said = self.recovery.unconfirmed(t, robot, self.alarm.phi_bar)
                if said is not None:
                    self.events.append(said)
                continue
            last_pair = len(self.members) <= 2  # one robot would be left: no team, no mission
            if last_pair:
                self.active[robot] = False
            else:
                self._exclude(t, p)
            self.events.append(self.recovery.exclusion(t, robot, flaggers))
            if last_pair:
                left = [int(k) + 1 for k in self.members if k != robot]
                self.ended = f"the team was reduced to robot {left[0]} alone"
                self.events.append(make(t, Kind.MISSION_ENDED, reason=self.ended, robots=left))
                return
            self._after_exclusion(t)
            if not self.graph.is_strongly_connected():
                self.events.append(split_event(t, self.graph, self.members))

    def _after_exclusion(self, t: float) -> None:
        """Eq. 46 for the team left after an exclusion at ``t``: its domain from the
        restarted rule's own T_s on (its thresholds start again from the residuals' bound, a
        new transient), and ``"auto"`` Δt_d,max on the reduced graph."""
        cfg = self.config
        if self.horizon is not None:  # the restarted rule read (and checked) first
            start = self.rounds.restart_time(t)  # as _exclude restarted it
            self.settles_at, _ = rule_settle_time(
                self.thresholds, self.members, cfg.dt, self.horizon, start, running=True
            )
            self.restarted_at = t
            at = self.settles_at if np.isfinite(self.settles_at) else None
            said = {"t": t, "settle_time": at}
            self.dt_d_max_info.setdefault("settle_after_exclusions", []).append(said)
        if cfg.dt_d_max == "auto" and len(self.members) > 1:  # eq. 46 on the new graph
            before = self.dt_d_max
            self.dt_d_max, info = detection_horizon(cfg, self.graph, self.thresholds, self.members)
            self.recovery.dt_d_max = self.dt_d_max
            self.dt_d_max_info.setdefault("after_exclusions", []).append({"t": t, **info})
            self.events.append(make(t, Kind.DETECTION_HORIZON, value=self.dt_d_max, before=before))

    def _rewire(self, t: float, p: int, gone: int) -> None:
        """The survivors' graph once robot ``gone`` (member ``p``) left: with ``rewire``
        "adopt" or "relay" they take over its links (:meth:`~.graph.Graph.rewired`, a
        ``graph_rewired`` event names the links added); with "none" its links go with it."""
        how = self.config.rewire
        self.graph, added = self.graph.rewired(p) if how != "none" else (self.graph.without(p), [])
        if added:
            links = [[int(self.members[j]) + 1, int(self.members[i]) + 1] for j, i in added]
            self.events.append(make(t, Kind.GRAPH_REWIRED, robot=gone + 1, links=links, how=how))

    def _exclude(self, t: float, p: int) -> None:
        """Resize every collective vector from M n to (M − 1) n (§5.2.2) and re-plan."""
        keep = np.delete(np.arange(len(self.members)), p)
        if self.radios is not None:  # the links of the robot that leaves go with it
            self.radios.drop(p)
        if self.sighting is not None:
            self.sighting.forget(int(self.members[p]))
        old_offsets, _ = self.plan.at(t)
        self.gone = np.append(self.gone, self.members[p])
        self.active[self.members[p]] = False
        gone = int(self.members[p])
        self.members = self.members[keep]
        self._rewire(t, p, gone)
        t_rule = self.rounds.restart_time(t)  # the rules restart at the next round
        for name in ("observer", "controller", "supervisor", "thresholds", "decision", "detector"):
            self.blocks[name].drop(p, self.graph, t_rule if name == "thresholds" else t)
        self._resize()
        cfg = self.config
        target = replan(cfg.formation, old_offsets[keep])
        self.plan = FormationPlan(old_offsets[keep], target, t0=t, blend=cfg.replan_time)
