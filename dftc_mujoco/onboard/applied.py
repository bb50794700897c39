"""The input a robot applies: its nominal input after its own drive's limits (Remark 4.1).

Eq. 21 builds y_m,i = x_m,i − ∫uᵢ from "the real input" of robot i, eq. 22 builds Δuᵢ
from it and the local observer of eq. 29 is driven by it. A drive delivers at most its
command range, so a nominal input of eq. 8 beyond that range is not what the robot
applies: integrated as if it were, the difference reads as a fault (a 100-robot team
started metres from its slots asks for 55 m/s at t = 0 from a 1 m/s drive, and every
robot flags every other one). Here each robot saturates its own nominal input, per axis,
at the part of its range that the compensation of eq. 28 leaves free
(``TeamConfig.input_limit``), and that saturated input is uᵢ everywhere after the
supervisor: in y_m, in Δuᵢ = uᵢ − u_g,i and in the fault estimator. ``fdir.input =
"nominal"`` keeps the unsaturated input (``input_limit`` = inf): the paper's equations
read literally, valid only while no command leaves the range.

A drive that answers its command with a first-order lag τ (``TeamConfig.lag``, the robot
file's calibrated ``lag``) does not move at its command either: robot i then integrates
the velocity its own drive model predicts, v̂ᵢ, the exact response of the lag to the
command held over the period (:func:`lag_input`), in y_m, in Δuᵢ and in its fault
estimator, while the command itself goes to the drive. Without it a slow robot's own lag
is a mismatch of up to τ‖Δu‖ in position (``docs/thresholds.md``) that the compensation
of eq. 28 fights as if it were a fault.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit


def lag_coefficients(lag: float, dt: float) -> tuple[float, float]:
    """(a, b) of :func:`lag_input` for a first-order lag ``lag`` [s] at period ``dt``:
    a = 1 − e^(−h/τ) and b = τa/h; (0, 0) without a lag (the command is the velocity)."""
    if not lag > 0.0:
        return 0.0, 0.0
    a = -math.expm1(-dt / lag)
    return a, lag * a / dt


def lag_arrays(lag: float | np.ndarray, n: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(a, b) (N,) of :func:`lag_input` for each robot's lag (one for all, or (N,)): a robot
    without a lag gets a = 1, b = 0, the limit τ → 0 (its velocity is its command)."""
    lags = np.broadcast_to(np.asarray(lag, dtype=float), (n,))
    pairs = [lag_coefficients(float(tau), dt) if tau > 0.0 else (1.0, 0.0) for tau in lags]
    a, b = (np.array(c, dtype=float).reshape(n) for c in zip(*pairs, strict=True))
    return a, b


def distinct_lags(lag: float | np.ndarray) -> list[float]:
    """The different drive lags of a team (``TeamConfig.lag``: one for all, or (N,))."""
    return sorted({float(tau) for tau in np.atleast_1d(np.asarray(lag, dtype=float))})


@njit(cache=True)
def lag_input(u, v_hat, command, a, b):  # pragma: no cover - compiled
    """The drive model of every robot (N, 2), in place: the commands ``u`` are copied to
    ``command`` and replaced by the mean velocity over the period of a first-order lag
    held at them, u + b(v̂ − u); v̂ advances to the period's end, u + (1 − a)(v̂ − u)
    (``a``, ``b`` (N,): each robot's own lag)."""
    for r in range(u.shape[0]):
        for d in range(u.shape[1]):
            c = u[r, d]
            gap = v_hat[r, d] - c
            command[r, d] = c
            u[r, d] = c + b[r] * gap
            v_hat[r, d] = c + (1.0 - a[r]) * gap


@njit(cache=True)
def limit_input(
    u, u_g, delta_u, limit, previous, rows, step, avoiding, full_step
):  # pragma: no cover - compiled
    """Saturate the nominal inputs ``u`` (M, n) in place: first their change since the last
    period's command ``previous[rows[i]]`` at ``step`` = a_max h in norm (the drive's
    acceleration, inf: none; ``full_step`` for a robot ``avoiding`` (M,) an obstacle, where
    ``step`` is a ramped start's: its avoidance brakes as hard as its drive can), then each
    axis at ±``limit``; Δuᵢ = uᵢ − u_g,i (eq. 22) for the input that results. Returns the
    number of robots whose input was changed."""
    hit = 0
    for i in range(u.shape[0]):
        changed = False
        step_i = full_step if avoiding[i] >= 0 else step
        if step_i < math.inf:
            p0, p1 = previous[rows[i], 0], previous[rows[i], 1]
            d0, d1 = u[i, 0] - p0, u[i, 1] - p1
            gap = math.sqrt(d0 * d0 + d1 * d1)
            if gap > step_i:
                u[i, 0] = p0 + d0 * step_i / gap
                u[i, 1] = p1 + d1 * step_i / gap
                changed = True
        if max(abs(u[i, 0]), abs(u[i, 1])) > limit:
            changed = True
            for d in range(u.shape[1]):
                u[i, d] = min(max(u[i, d], -limit), limit)
        if changed:
            hit += 1
            for d in range(u.shape[1]):
                delta_u[i, d] = u[i, d] - u_g[i, d]
    return hit


class DriveRecord(NamedTuple):
    """What the compiled period (:mod:`.period`) reads and writes of the drive model."""

    input_limit: float  # [m/s] per axis, the range the compensation leaves free
    accel_step: float  # [m/s] the drive's Δu per period (inf: none)
    full_step: float  # [m/s] the same after a ramped start (an avoiding robot's at once)
    lagged: bool  # some robot's drive lags its command
    lag_a: np.ndarray  # (N,) a, b of :func:`lag_input`
    lag_b: np.ndarray
    v_hat: np.ndarray  # (N, 2) the velocity the lag delivers
    command: np.ndarray  # (N, 2) what each robot tells its drive


class DriveModel:
    """Each robot's model of its own drive: its range, acceleration and lag (N robots).

    ``command`` (N, 2) is what each robot last told its drive and ``v_hat`` (N, 2) the
    velocity a first-order lag of ``lag`` [s] delivers (one for all, or each robot's (N,);
    robots start at rest). Until
    ``start_time`` the input changes by at most ``start_accel`` (a ramped start: from rest,
    the drives' lag against a jump to the first commands broke the premise 'mismatch' in
    the first hundredths of a second), then by the drive's own ``accel``.
    """

    def __init__(
        self,
        n: int,
        dt: float,
        input_limit: float,
        accel: float,
        lag: float | np.ndarray,
        start_accel: float = np.inf,
        start_time: float = 0.0,
    ):
        self.command = np.zeros((n, 2))
        self.v_hat = np.zeros((n, 2))
        self.input_limit = float(input_limit)
        self.full_step = float(accel) * dt  # the drive's Δu per period
        # a ramped start: until start_time, at most start_accel (the first commands from rest)
        self.start_step = min(float(start_accel), float(accel)) * dt
        self.start_time = float(start_time)
        self.accel_step = self.start_step if self.start_time > 0 else self.full_step
        self.lag_a, self.lag_b = lag_arrays(lag, n, dt)
        self.lagged = bool(self.lag_b.any())  # b > 0 exactly where a robot's drive lags

    def at(self, t: float) -> None:
        """The acceleration of the period at ``t``: the start's, then the drive's own."""
        self.accel_step = self.start_step if t < self.start_time else self.full_step

    def limit(
        self,
        u: np.ndarray,
        u_g: np.ndarray,
        delta_u: np.ndarray,
        rows: np.ndarray,
        avoiding: np.ndarray,
    ) -> int:
        """Saturate the members' nominal inputs in place (:func:`limit_input`; ``avoiding``
        (M,): the obstacle each avoids, or -1)."""
        return limit_input(
            u, u_g, delta_u, self.input_limit, self.command, rows, self.accel_step, avoiding,
            self.full_step,
        )  # fmt: skip

    def deliver(self, u: np.ndarray) -> None:
        """``u`` (N, 2) becomes the command; with a lag, ``u`` becomes what the drive
        delivers over the period (:func:`lag_input`)."""
        if self.lagged:
            lag_input(u, self.v_hat, self.command, self.lag_a, self.lag_b)
        else:
            self.command[:] = u

    def record(self) -> DriveRecord:
        """The arrays and constants the compiled period uses."""
        return DriveRecord(
            self.input_limit, self.accel_step, self.full_step, self.lagged, self.lag_a,
            self.lag_b, self.v_hat, self.command,
        )  # fmt: skip
