"""One control period of the whole team with the paper's blocks, compiled as one call.

This is not a second implementation: it calls, in the order of Fig. 1, the
same compiled functions the blocks call (observer :func:`~.observer.estimate_one`,
:func:`~.observer.residual_row`, :func:`~.observer.advance_one`,
:func:`~.observer.integrate_inputs`; controller :func:`~.controller.collective_one`;
supervisor :func:`~.supervisor.supervise`; fault estimator
:func:`~.fault_estimator.estimate_faults`; decision :func:`~.fdir.decide`), each
equation written once (only the mission's x_d = c + offsets of eq. 14, one addition, is
spelled out in both paths). Composed in one compiled call, the period costs no Python
overhead per block, and the per-entry functions are fused into two passes over
the team's N × N state instead of one pass per equation (the state is memory-bound
at N = 400): ⁱx̂, ⁱû_g and ∫ⁱû_g in one, then each robot's residual, its norms and
its next ŷ (written to a second buffer that the caller swaps in, since every robot
reads its in-neighbours' current messages). :class:`~.team.Team` uses it whenever
the team runs the paper's blocks (any thresholds rule included: ⁱμ_k comes in as
an array), and composes the blocks' Python methods otherwise.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange

from .applied import DriveRecord, lag_input, limit_input
from .controller import ControllerRecord, collective_one
from .decision import DecisionRecord, decide_in_groups, decide_parallel
from .fault_estimator import EstimatorRecord, estimate_faults
from .observer import (
    ObserverRecord,
    advance_one,
    estimate_one,
    integrate_inputs,
    residual_row,
    row_norms,
)
from .supervisor import SupervisorRecord, Surroundings, supervise

RAISED = 1  # some flag was raised (detection events to report)
SWITCHED = 2  # some robot switched behaviour (reactive events to report)
SATURATED = 4  # some robot's nominal input was beyond its command range (saturated)


class PeriodInputs(NamedTuple):
    """What a period is given: the measurements, the members and the mission."""

    x_m: np.ndarray  # (N, n) each robot's own noisy position
    rows: np.ndarray  # (M,) team row i is robot rows[i]
    c: np.ndarray  # (n,) the desired centroid σ₁,d and its velocity
    c_dot: np.ndarray
    offsets: np.ndarray  # (M, n) the formation's slots and their rates
    rates: np.ndarray
    fdir: bool  # the fault estimator and the decision run


class PeriodBuffers(NamedTuple):
    """The period's outputs and scratch, allocated by the team at its size."""

    x_own: np.ndarray  # (M, n) the members' own measurements
    x_d: np.ndarray  # (M, n) the mission's desired positions and velocities (eq. 14)
    xd_dot: np.ndarray
    x_hat: np.ndarray  # (M, M, n) the estimates before the update (eq. 21)
    u_g: np.ndarray  # (M, n) u_g,i (eq. 16)
    u_mem: np.ndarray  # (M, n) uᵢ, then Δuᵢ (eqs. 8, 22)
    du: np.ndarray
    row: np.ndarray  # (B, M·n) one robot's residual, for each of B groups of robots (scratch)
    r_norm: np.ndarray  # (M, M) ‖ⁱr_k‖
    u: np.ndarray  # (N, 2) nominal input, original robot axis
    u_bar: np.ndarray  # (N, 2) the compensated command (eq. 28)


def _estimates(y, s, xh, xd, vd, u_g, kc, dt, n, blocks):  # pragma: no cover - compiled
    """Pass 1 for every robot i, in ``blocks`` contiguous groups of rows: u_g,i (eq. 16),
    ⁱx̂ (eq. 21) into ``xh`` and ∫ ⁱû_g (eqs. 15, 20) advanced in ``s`` (rows M × M·n)."""
    m = y.shape[0]
    for b in prange(blocks):
        for i in range(b * m // blocks, (b + 1) * m // blocks):
            for d in range(n):  # u_g,i = Γᵢ ⁱû_g (eq. 16): robot i's own block, before ∫ moves
                a = i * n + d
                u_g[i, d] = collective_one(vd[a], kc, xd[a], estimate_one(y[i, a], s[i, a]))
            for a in range(m * n):
                e = estimate_one(y[i, a], s[i, a])  # eq. 21
                xh[i, a] = e
                s[i, a] += dt * collective_one(vd[a], kc, xd[a], e)  # ∫ ⁱû_g of eq. 15 (eq. 20)


def _residuals(
    y_hat, int_u_own, x_own, src, first_edge, in_degree, rows, r_norm, yn, ko, dt
):  # pragma: no cover - compiled
    """Pass 2 for every robot i, in as many contiguous groups of rows as ``rows`` (B, M·n)
    has scratch rows: ⁱr (eq. 35), its norms, and ⁱŷ of the next period (eq. 19) into
    ``yn``."""
    m, _, n = y_hat.shape
    y = y_hat.reshape(m, m * n)
    blocks = rows.shape[0]
    for b in prange(blocks):
        row = rows[b]
        for i in range(b * m // blocks, (b + 1) * m // blocks):
            residual_row(y_hat, int_u_own, x_own, src, first_edge, in_degree, i, row)  # eq. 35
            row_norms(row, i, n, r_norm)
            for a in range(m * n):
                yn[i, a] = advance_one(y[i, a], row[a], ko, dt)  # eq. 19


# the passes over the team's N × N state, each on one core or split over the cores (a team
# of PARALLEL_FROM robots or more: below it, starting the threads costs more than it saves)
estimates = njit(cache=True)(_estimates)
estimates_parallel = njit(cache=True, parallel=True)(_estimates)
residuals = njit(cache=True)(_residuals)
residuals_parallel = njit(cache=True, parallel=True)(_residuals)
PARALLEL_FROM = 200


@njit(cache=True)
def team_period(
    inp: PeriodInputs,
    ob: ObserverRecord,
    ctl: ControllerRecord,
    sup: SupervisorRecord,
    seen: Surroundings,
    drive: DriveRecord,
    est: EstimatorRecord,
    dec: DecisionRecord,
    out: PeriodBuffers,
) -> int:  # pragma: no cover - compiled
    """One period for the members ``inp.rows``; returns RAISED | SWITCHED | SATURATED bits.

    ``inp.x_m``, the drive's ``v_hat`` and ``command``, the estimator's arrays and
    ``out.u``, ``out.u_bar`` are on the original robot axis (N); with a drive lag
    (``drive.lag_a`` > 0) ``out.u`` ends as the velocity the drive model predicts and
    ``drive.command`` as what the drive is told; the others on the members' axis (M).
    Robots that are not members get u = 0 and only run their fault estimator. ŷ of the
    next period goes to ``ob.y_next`` (the observer swaps it in, :meth:`.Observer.advance`).
    """
    x_m, rows, c, c_dot, offsets, rates = (
        inp.x_m,
        inp.rows,
        inp.c,
        inp.c_dot,
        inp.offsets,
        inp.rates,
    )
    x_own, x_d, xd_dot, x_hat = out.x_own, out.x_d, out.xd_dot, out.x_hat
    u_g, u_mem, du, row, r_norm, u, u_bar = (
        out.u_g,
        out.u_mem,
        out.du,
        out.row,
        out.r_norm,
        out.u,
        out.u_bar,
    )
    y_hat, y_next, int_u_hat, int_u_own = ob.y_hat, ob.y_next, ob.int_u_hat, ob.int_u_own
    kc, ko, dt = ctl.kc, ob.ko, ob.dt
    command = drive.command
    m, _, n = y_hat.shape
    code = 0
    for i in range(m):
        for d in range(n):
            x_own[i, d] = x_m[rows[i], d]
            x_d[i, d] = c[d] + offsets[i, d]  # J⁻¹σ_d, the mission (eq. 14)
            xd_dot[i, d] = c_dot[d] + rates[i, d]
    y, s = y_hat.reshape(m, m * n), int_u_hat.reshape(m, m * n)
    xh, xd, vd = x_hat.reshape(m, m * n), x_d.reshape(-1), xd_dot.reshape(-1)
    if row.shape[0] > 1:  # pass 1, robot by robot
        estimates_parallel(y, s, xh, xd, vd, u_g, kc, dt, n, row.shape[0])
    else:
        estimates(y, s, xh, xd, vd, u_g, kc, dt, n, 1)
    # eqs. 8, 18
    if supervise(
        x_own,
        u_g,
        seen.obstacles,
        seen.safe,
        seen.activation,
        sup.theta,
        sup.release,
        sup.active,
        u_mem,
        du,
        seen.mates,
        sup.mate_safe,
        sup.mate_act,
    ):
        code |= SWITCHED
    # the input the robot applies (Remark 4.1): its drive's acceleration and range
    if limit_input(u_mem, u_g, du, drive.input_limit, command, rows, drive.accel_step):
        code |= SATURATED
    yn = y_next.reshape(m, m * n)
    # pass 2: every robot reads its in-neighbours' current messages
    if row.shape[0] > 1:
        residuals_parallel(
            y_hat, int_u_own, x_own, ob.src, ob.first_edge, ob.in_degree, row, r_norm, yn, ko, dt
        )
    else:
        residuals(
            y_hat, int_u_own, x_own, ob.src, ob.first_edge, ob.in_degree, row, r_norm, yn, ko, dt
        )
    if m < u.shape[0]:
        u[:] = 0.0  # an excluded robot is told to stay where it is
    for i in range(m):
        for d in range(2):
            u[rows[i], d] = u_mem[i, d]
    if drive.lag_a > 0.0:  # the drive's lag: integrate what it delivers, command the drive
        lag_input(u, drive.v_hat, command, drive.lag_a, drive.lag_b)
        for i in range(m):
            for d in range(2):
                u_mem[i, d] = u[rows[i], d]
                du[i, d] = u_mem[i, d] - u_g[i, d]
    else:
        command[:] = u
    integrate_inputs(int_u_hat, int_u_own, du, u_mem, dt)  # eqs. 20-21
    if inp.fdir:
        applied = est.applied
        estimate_faults(
            x_m,
            u,
            est.z,
            est.int_e,
            est.phi_hat,
            applied,
            est.K,
            est.g_inv,
            est.dt,
            est.limit,
            est.alpha,
            est.hold,
            u_bar,
        )
        for r in range(u.shape[0]):
            for d in range(2):
                u_bar[r, d] = command[r, d] - (applied[r, d] if est.compensate else 0.0)  # eq. 28
        args = (r_norm, dec.mu, dec.above, dec.below, dec.flag, dec.dt, dec.window)
        if row.shape[0] > 1:
            raised = decide_parallel(*args, dec.exclusive, dec.isolated, dec.raised, row.shape[0])
        else:
            raised = decide_in_groups(*args, dec.exclusive, dec.isolated, dec.raised, 1)
        if raised:  # eq. 39
            code |= RAISED
    else:
        u_bar[:] = command
    return code
