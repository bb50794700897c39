"""Each robot's own alarm from its local fault estimate: what confirms an exclusion.

Everything a teammate learns of robot k's actuators comes through robot k's measured
y_m,k, and the fault estimator's algebra fixes it exactly: y_m,k(t) − y_m,k(0) = G φ̂_k(t)
plus K times the steps of ∫e the anti-windup skipped, which it skips only while k's command
ū_k leaves the drive's range (``docs/thresholds.md``, rule drive). So while robot k's own
‖φ̂_k‖ stays within Φ̄, the bound on a healthy robot's estimate (the estimator's ℓ1 gain from
η̄ and ξ̄, :func:`.thresholds.compensation.estimator_gain`), and ū_k within range, its signal
moves as a healthy robot's does, whatever its teammates' residuals still show: those are
the consensus observers' memory of an earlier break of the premises (a start-up its drive
could not follow, a skipped ∫e), which on a long line graph outlasts the break by seconds
(battery run 94 of seed 31: a healthy diffdrive flagged 1–3 s after its start-up's
saturation ended, and excluded). An actuator fault the residuals can see keeps the
estimate out: a stop winds φ̂ past every bound and pushes ū out of range, an uncompensated
or a detectable bias holds ‖φ̂‖ > Φ̄.

:class:`EstimateAlarm` raises robot k's alarm once its estimate has been out (‖φ̂_k‖ > Φ̄
or ū_k beyond the range) for a decision window in a row (Remark 5.2's window, the flags'
own) and lowers it after as long back in; its timer counts how long the estimate has been
out in a row, and ``seen`` whether the alarm went up since the recovery last asked. Robot k
knows both signals itself and says its alarm in its messages, as it says its bumper.

The recovery (``fdir.confirm_by_estimate``) excludes a robot still flagged at its t_r only if
its estimate has then been out for a decision window and twice the robot's calibrated
response time in a row (:attr:`EstimateAlarm.hold`); otherwise the exclusion waits another
Δt_d,max, and is cancelled once nobody flags it; at each later judgement an alarm that went
up since the last one confirms too. A healthy robot that breaks the premises itself raises
the very flags and the very alarm a fault does: a diffdrive that turns on the spot to pass
a teammate with no speed left has its command saturated and its estimate past Φ̄ while it
turns (battery runs: 0.4 s in run 195 of the edge-speed battery as first drawn, its alarm
down again before t_r; 0.66 s in run 168 of that battery, 1.27 times its 0.52 s response,
still out at a t_r of 0.42 s after the first flag). The rule before (the alarm up some time
since the first flag) excluded both. A fault the residuals can see keeps the estimate out
for as long as it acts; an intermittent one, off at its t_r, goes up again before the next
judgement."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .block import TeamConfig
from .decision import count_for, tick

#: the most periods out an alarm's timer counts (int32; 124 days at 100 Hz)
LONGEST = 1 << 30


@njit(cache=True)
def watch_estimates(phi_hat, u_bar, phi_bar, limit, need, timer, alarm, seen):  # pragma: no cover
    """One period of every robot's own alarm, in place. ``phi_hat``, ``u_bar`` (N, 2): the
    fault estimates and the commands; ``phi_bar``: Φ̄; ``limit``: the per-axis command
    range; ``need``: the window in periods; ``timer`` (N,) int32: periods out in a row
    (> 0, up to :data:`LONGEST`) or in (< 0, down to −need); ``alarm`` (N,) bool; ``seen``
    (N,) bool, set when an alarm goes up."""
    bound = phi_bar * phi_bar
    top = max(need, 1)
    for i in range(phi_hat.shape[0]):
        p0, p1 = phi_hat[i, 0], phi_hat[i, 1]
        out = p0 * p0 + p1 * p1 > bound or max(abs(u_bar[i, 0]), abs(u_bar[i, 1])) > limit
        c = timer[i]
        if out:  # how long it has been out: the recovery's hold reads it
            c = min(max(c, 0) + 1, LONGEST)
        else:
            c = tick(c, False, need)
        timer[i] = c
        if c >= top:
            if not alarm[i]:
                seen[i] = True
            alarm[i] = True
        elif -c >= top:
            alarm[i] = False


class AlarmRecord(NamedTuple):
    """What the compiled period (:mod:`.period`) reads and writes of the alarms."""

    timer: np.ndarray  # (N,) int32, periods out (> 0) or in (< 0, down to −need) in a row
    alarm: np.ndarray  # (N,) bool, each robot's own alarm
    seen: np.ndarray  # (N,) bool, went up since the recovery last asked
    phi_bar: float  # Φ̄ [m/s]
    limit: float  # the per-axis command range [m/s]
    need: int  # the window in control periods
    on: bool  # watched (fdir.confirm_by_estimate, with compensation and a finite Φ̄)


#: the hold is this many times the robot's calibrated response time, past the window
RESPONSES = 2


class EstimateAlarm:
    """Every robot's own alarm (original robot axis): ‖φ̂‖ > Φ̄ or ū out of range for
    ``need`` periods in a row. ``on``: the recovery asks it (:meth:`confirms`). ``hold``: the
    periods out in a row that confirm an exclusion at a first judgement."""

    def __init__(
        self, n: int, phi_bar: float, limit: float, need: int, on: bool = True, hold: int = 0
    ) -> None:
        self.phi_bar = float(phi_bar)
        self.limit = float(limit)
        self.need = int(need)
        self.hold = max(int(hold), self.need, 1)
        self.on = bool(on and np.isfinite(self.phi_bar))  # a Python bool, as numba unboxes it
        self.timer = np.zeros(n, np.int32)
        self.alarm = np.zeros(n, bool)
        self.seen = np.zeros(n, bool)

    @classmethod
    def of(cls, config: TeamConfig, n: int, rule_bound: float | None = None) -> EstimateAlarm:
        """The team's alarms: Φ̄ of ``config`` (or a thresholds rule's own larger bound on a
        healthy ‖φ̂‖, ``rule_bound``, such as a real robot's stated ``phi_bar``), Remark 5.2's
        window in control periods, and on with ``fdir.confirm_by_estimate`` where FDIR
        compensates (without compensation Φ̄ bounds nothing). The hold: the window and
        :data:`RESPONSES` times the robot's calibrated response time, in control periods."""
        phi_bar = max(config.phi_bar, float(rule_bound or 0.0))
        need = count_for(config.detection_window, config.dt)
        on = config.confirm_by_estimate and config.fdir and config.compensate
        periods = RESPONSES * config.response_time / config.dt  # inf: never (LONGEST)
        hold = need + int(np.ceil(min(periods, LONGEST) - 1e-9))
        return cls(n, phi_bar, config.command_limit, need, on, hold)

    def record(self) -> AlarmRecord:
        """The state the compiled period updates (:func:`watch_estimates` after ū)."""
        return AlarmRecord(
            self.timer, self.alarm, self.seen, self.phi_bar, self.limit, self.need, self.on
        )

    def step(self, phi_hat: np.ndarray, u_bar: np.ndarray) -> None:
        """One control period, after the estimators and the commands (the general path;
        the compiled period runs it in :func:`.period.deliver`)."""
        watch_estimates(
            phi_hat, u_bar, self.phi_bar, self.limit, self.need, self.timer, self.alarm, self.seen
        )

    def confirms(self, robot: int, heard: bool = True, again: bool = False) -> bool:
        """Whether robot ``robot``'s estimate has been out for :attr:`hold` periods in a row
        now (at its t_r) or, when it is judged ``again``, its alarm went up since it was last
        asked; True when the check is off, or when its teammates do not hear its messages
        (``heard`` False: a silent radio; unheard is not healthy)."""
        if not (self.on and heard):
            return True
        up = bool(self.timer[robot] >= self.hold or (again and self.seen[robot]))
        self.seen[robot] = False
        return up
