"""The team's period through the blocks' Python methods: the *general* path.

When a user's block replaces one of the paper's, :class:`~.team.Team` cannot run the
compiled period (:mod:`.period`): it calls each block's methods here, in the order of
Fig. 1, and both paths compute the same thing for the paper's blocks (tested).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from ..applied import DriveModel
from ..block import BadOutput, Block, TeamConfig, blame_not_finite, shaped
from ..controller import Controller
from ..decision import Decision
from ..detector import Detector
from ..fault_estimator import FaultEstimator
from ..observer import Observer
from ..radio import Rounds
from ..supervisor import Supervisor
from .period import RAISED, SATURATED, SWITCHED


class GeneralTeam(Protocol):
    """What one period of the general path reads and writes of the team (:class:`~.team.Team`
    is one): its blocks, its drive model and network rounds, the surroundings its range
    sensors gave, and the period's arrays on the members' axis."""

    config: TeamConfig
    n: int
    members: np.ndarray
    observer: Observer
    controller: Controller
    supervisor: Supervisor
    estimator: FaultEstimator
    decision: Decision
    detector: Detector
    drive: DriveModel
    rounds: Rounds
    #: the obstacles' positions, safe distances and activation distances; teammates seen
    obs_p: np.ndarray
    obs_d: np.ndarray
    obs_a: np.ndarray
    mates: np.ndarray
    sensed: bool  # the range sensors read this period
    supervisor_sees_mates: bool  # the supervisor's step() takes ``teammates``
    estimator_holds: bool  # the fault estimator's step() takes ``hold``
    touch: np.ndarray  # each robot's bumper, held
    x_d: np.ndarray
    xd_dot: np.ndarray
    x_hat: np.ndarray
    u: np.ndarray
    u_bar: np.ndarray
    r_norm: np.ndarray
    mu: np.ndarray
    raised: np.ndarray


def judged(
    value: object, shape: tuple[int, ...], block: Block, method: str, mem: Any, what: str
) -> np.ndarray:
    """What a detection ingredient must be (a residual, a detector's scores and bounds): an
    array of ``shape`` of real numbers, none NaN. A NaN compares false with everything: the
    pair it stands on would never be flagged, and the run say ``status: ok``."""
    out = shaped(value, shape, block, method)
    if out.dtype.kind not in "fiu":
        raise BadOutput(block, f"returned from {method} an array of {out.dtype}, expected numbers,")
    if out.dtype.kind == "f" and np.isnan(out).any():
        i, k = (int(mem[j]) + 1 for j in np.argwhere(np.isnan(out))[0][:2])
        raise BadOutput(
            block,
            f"returned from {method} nan as robot {i}'s {what} on robot {k} (a NaN never "
            "flags: detection of that pair would be off), expected a number,",
        )
    return out


def general_period(
    team: GeneralTeam,
    x_m: np.ndarray,
    c: np.ndarray,
    c_dot: np.ndarray,
    offsets: np.ndarray,
    rates: np.ndarray,
) -> int:
    """One period of :class:`~.team.Team` ``team`` through its blocks' Python methods
    (any block set); returns RAISED | SWITCHED | SATURATED bits. The arguments are those
    of the compiled period (:class:`~.period.PeriodInputs`)."""
    cfg, mem = team.config, team.members
    whole = len(mem) == team.n
    x_own = x_m if whole else x_m[mem]
    np.add(c, offsets, out=team.x_d)  # J⁻¹σ_d, the mission (eq. 14)
    np.add(c_dot, rates, out=team.xd_dot)
    before = np.array(team.supervisor.active, copy=True)
    m = len(mem)
    own, pairs, stacked = (m, 2), (m, m), (m, m, 2)  # what each output must be
    ob, ctl, sup = team.observer, team.controller, team.supervisor
    x_hat = shaped(ob.estimate(), stacked, ob, "estimate()")  # eq. 21
    team.x_hat = np.array(x_hat, dtype=float)
    u_hat_g = shaped(
        ctl.collective_input(x_hat, team.x_d, team.xd_dot), stacked, ctl, "collective_input()"
    )  # eq. 15
    u_g = shaped(ctl.own_input(u_hat_g), own, ctl, "own_input()")  # eq. 16
    mates = team.mates if team.sensed and cfg.teammate_safe > 0 else None
    if mates is not None and team.supervisor_sees_mates:
        u_mem, delta_u = team.supervisor.step(
            x_own, u_g, team.obs_p, team.obs_d, team.obs_a, teammates=mates
        )
    else:
        u_mem, delta_u = team.supervisor.step(x_own, u_g, team.obs_p, team.obs_d, team.obs_a)
    # the applied input (Remark 4.1), saturated here
    u_mem = np.array(shaped(u_mem, own, sup, "step()[0]"), dtype=float)
    delta_u = np.array(shaped(delta_u, own, sup, "step()[1]"), dtype=float)
    avoiding = np.asarray(getattr(sup, "active", np.full(len(mem), -1)), dtype=np.intp)
    saturated = team.drive.limit(u_mem, np.ascontiguousarray(u_g, float), delta_u, mem, avoiding)
    if not whole:
        team.u[:] = 0.0  # an excluded robot is told to stay where it is
    team.u[mem] = u_mem
    team.drive.deliver(team.u)  # with a lag, u becomes what the drive delivers
    if team.drive.lagged:
        u_mem = team.u[mem]
        delta_u = u_mem - u_g
    if team.rounds.now:
        r = judged(ob.residual(x_own), stacked, ob, "residual()", mem, "residual")  # eq. 35
        team.r_norm = np.sqrt(np.einsum("ikd,ikd->ik", r, r))
        if cfg.fdir:  # what the detector judges by, on this period's messages (‖r‖ vs μ)
            de = team.detector
            judgement = de.judge(team.r_norm, team.mu, team.observer, x_own)
            if not isinstance(judgement, tuple | list) or len(judgement) != 2:
                got = f"{type(judgement).__name__}"
                raise BadOutput(de, f"returned from judge() a {got}, expected (scores, bounds),")
            score, bound = judgement
            team.r_norm = judged(score, pairs, de, "judge()[0]", mem, "score")
            team.mu = judged(bound, pairs, de, "judge()[1]", mem, "bound")
    else:  # between two rounds of the network only the integrals move
        r = np.zeros_like(team.x_hat)
    team.observer.update(r, u_hat_g, delta_u, u_mem)  # eqs. 19-21
    code = SWITCHED if not np.array_equal(before, team.supervisor.active) else 0
    if saturated:
        code |= SATURATED
    if cfg.fdir:
        if team.estimator_holds:  # eqs. 28-31, nominal u (docs/notes.md, 2)
            u_bar = team.estimator.step(x_m, team.u, hold=team.touch)
        else:
            u_bar = team.estimator.step(x_m, team.u)
        u_bar = shaped(u_bar, team.u.shape, team.estimator, "step()")
        if not cfg.compensate:
            team.u_bar[:] = team.drive.command
        elif team.drive.lagged:  # ū = command − φ̂ (eq. 28); the estimator's is u − φ̂
            team.u_bar[:] = team.drive.command - (team.u - u_bar)
        else:
            team.u_bar[:] = u_bar
        if team.rounds.now:
            raised = team.decision.update(team.r_norm, team.mu)
            team.raised = np.asarray(shaped(raised, pairs, team.decision, "update()"), bool)
            if team.raised.any():  # eq. 39
                code |= RAISED
    else:
        team.u_bar[:] = team.drive.command
    if not np.isfinite(team.u_bar).all():  # the commands: which block's output was not finite
        est = team.estimator
        blame_not_finite(
            [
                (x_hat, ob, "estimate()"),
                (u_hat_g, ctl, "collective_input()"),
                (u_g, ctl, "own_input()"),
                (u_mem, sup, "step()[0]"),
                (delta_u, sup, "step()[1]"),
                *([(u_bar, est, "step()")] if cfg.fdir else []),
            ]
        )
    return code
