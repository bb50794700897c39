"""The team's row of the run's log: its outputs on the original robot axis.

A log row takes the team's inputs, membership, desired positions, reactive and flagged
robots and fault estimates, and at the rows that keep them the N × N estimates, residuals
and thresholds (float32 in the log). For the paper's (compiled) blocks one compiled call
writes them all, after an exclusion too, the rows of the robots that left filled with NaN
or False (:func:`_team_row`: 1.4 µs a row at N = 4, where placing the arrays in Python took
3.7, and 14 after an exclusion); a team of plug-in blocks writes its row in Python
(:func:`placed_row`, :func:`~.team_axis.place`).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numba import njit

from ..decision import flagged_by_teammates
from ..supervisor import Supervisor
from ..thresholds.paper import ThresholdRecord, factored_at
from .team_axis import place


class RowTeam(Protocol):
    """What a log row reads of the team (:class:`~.team.Team` is one): the period's outputs,
    on the members' axis except ``u``, ``active``, ``phi_hat`` (the original robot axis)."""

    compiled: bool  # the period ran compiled: one compiled call writes the row
    members: np.ndarray
    u: np.ndarray
    active: np.ndarray
    x_d: np.ndarray
    x_hat: np.ndarray
    mu: np.ndarray
    supervisor: Supervisor  # its ``active``: each robot's obstacle, -1 for none

    @property
    def threshold_factors(self) -> ThresholdRecord | None: ...
    @property
    def r_norm(self) -> np.ndarray: ...
    @property
    def flag(self) -> np.ndarray: ...
    @property
    def phi_hat(self) -> np.ndarray: ...


#: the log's fields the team writes, in the order the compiled call takes them
FIELDS = ("u", "active", "x_d", "reactive", "flagged", "phi_hat", "x_hat", "residual", "threshold")


#: the factors passed where the thresholds come as an array (:func:`write_row`)
_NO_FACTORS = (np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.bool_), 0.0)


@njit(cache=True)
def _team_row(
    log_u, log_active, log_xd, log_reactive, log_flagged, log_phi, log_x_hat, log_res, log_th,
    row, row_nn, fdir, members, u, active, x_d, supervised, flag, phi_hat, x_hat, r_norm,
    mu, coef, bound, finite, eta,
):  # fmt: skip  # pragma: no cover - compiled
    """Row ``row`` of the log's fields (:data:`FIELDS`, each with its time axis first) from
    the team's arrays: ``u``,
    ``active`` and ``phi_hat`` on the original robot axis (N), the others on the members'
    (M, robots ``members``), placed on the original axis with NaN or False for the robots
    that left; the N × N fields into row ``row_nn`` unless it is -1; ``phi_hat`` and the
    thresholds only with FDIR (``fdir``): the array ``mu`` (M, M), or where it is empty
    (0, 0) eq. 40 from the factors the period read (``coef``, ``bound``, ``finite``, ``eta``
    of :class:`~.thresholds.paper.ThresholdRecord`, the numbers ``Thresholds.mu`` writes)."""
    factored = mu.shape[0] == 0
    n, m = u.shape[0], members.shape[0]
    whole = m == n
    for i in range(n):
        for d in range(2):
            log_u[row, i, d] = u[i, d]
            if fdir:
                log_phi[row, i, d] = phi_hat[i, d]
        log_active[row, i] = active[i]
    if whole:  # no indirection: loops the compiler vectorises (N = 1000: 1M pairs a row)
        for i in range(n):
            for d in range(2):
                log_xd[row, i, d] = x_d[i, d]
            log_reactive[row, i] = supervised[i] >= 0
        flagged_by_teammates(flag, log_flagged[row])
    else:
        for i in range(n):
            for d in range(2):
                log_xd[row, i, d] = np.nan
            log_reactive[row, i] = False
            log_flagged[row, i] = False
        for a in range(m):  # row by row, in memory order (flagged_by_teammates)
            i = members[a]
            for d in range(2):
                log_xd[row, i, d] = x_d[a, d]
            log_reactive[row, i] = supervised[a] >= 0
            for b in range(m):
                if flag[a, b] and a != b:
                    log_flagged[row, members[b]] = True
    if row_nn < 0:
        return
    log_xh = log_x_hat.reshape(log_x_hat.shape[0], n, 2 * n)
    if whole:
        xh = x_hat.reshape(n, 2 * n)
        for i in range(n):
            dst, src = log_xh[row_nn, i], xh[i]
            for a in range(2 * n):
                dst[a] = src[a]
            dst, src = log_res[row_nn, i], r_norm[i]
            for k in range(n):
                dst[k] = src[k]
            if fdir and factored:
                dst = log_th[row_nn, i]
                for k in range(n):
                    dst[k] = factored_at(coef, bound, finite, eta, i, k)
            elif fdir:
                dst, src = log_th[row_nn, i], mu[i]
                for k in range(n):
                    dst[k] = src[k]
        return
    log_xh[row_nn] = np.nan
    log_res[row_nn] = np.nan
    if fdir:
        log_th[row_nn] = np.nan
    for a in range(m):
        i = members[a]
        for b in range(m):
            k = members[b]
            for d in range(2):
                log_xh[row_nn, i, 2 * k + d] = x_hat[a, b, d]
            log_res[row_nn, i, k] = r_norm[a, b]
            if fdir:
                log_th[row_nn, i, k] = (
                    factored_at(coef, bound, finite, eta, a, b) if factored else mu[a, b]
                )


def write_row(team: RowTeam, log: dict[str, np.ndarray], row: int, fdir: bool, row_nn: int) -> None:
    """Write the team's outputs into row ``row`` of the log's preallocated arrays (the N × N
    ones into row ``row_nn`` unless it is -1), on the original robot axis: one compiled call
    for a compiled team (:func:`_team_row`), :func:`placed_row` for a team of plug-in blocks
    (whose arrays may be of any type)."""
    if not team.compiled:
        placed_row(team, log, row, fdir, row_nn)
        return
    th = team.threshold_factors if fdir and row_nn >= 0 else None
    if th is not None:  # eq. 40 written from the factors in the compiled row (1.4 µs less)
        mu, factors = th.dense, (th.coef, th.bound, th.finite, th.eta)
    else:  # (not read without thresholds)
        mu, factors = team.mu if fdir and row_nn >= 0 else team.r_norm, _NO_FACTORS
    _team_row(
        log["u"], log["active"], log["x_d"], log["reactive"], log["flagged"], log["phi_hat"],
        log["x_hat"], log["residual"], log["threshold"],  # FIELDS
        row, row_nn, fdir, team.members, team.u, team.active, team.x_d, team.supervisor.active,
        team.flag, team.phi_hat, team.x_hat, team.r_norm, mu, *factors,
    )  # fmt: skip


def placed_row(
    team: RowTeam, log: dict[str, np.ndarray], row: int, fdir: bool, row_nn: int
) -> None:
    """:func:`write_row` in Python: the members' rows placed on the original robot axis
    (:func:`~.team_axis.place`), the others filled."""
    mem = team.members
    scratch = np.zeros((2, len(mem)), bool)
    log["u"][row] = team.u
    log["active"][row] = team.active
    place(log["x_d"][row], team.x_d, mem)
    reactive, flagged = scratch
    np.greater_equal(team.supervisor.active, 0, out=reactive)
    flagged_by_teammates(np.asarray(team.flag, bool), flagged)
    place(log["reactive"][row], reactive, mem, fill=False)
    place(log["flagged"][row], flagged, mem, fill=False)
    if fdir:
        log["phi_hat"][row] = team.phi_hat
    if row_nn >= 0:
        place(log["x_hat"][row_nn], team.x_hat, mem, square=True)
        place(log["residual"][row_nn], team.r_norm, mem, square=True)
        if fdir:
            place(log["threshold"][row_nn], team.mu, mem, square=True)
