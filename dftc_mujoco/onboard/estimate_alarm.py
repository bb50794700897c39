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
own) and lowers it after as long back in; ``seen`` keeps whether it was up since the
recovery last asked. Robot k knows both signals itself and says its alarm in its messages,
as it says its bumper. The recovery (``fdir.confirm_by_estimate``) excludes a robot still
flagged at its t_r only if its alarm is up then; otherwise the exclusion waits another
Δt_d,max, and is cancelled once nobody flags it; at each later judgement an alarm that was
up some time since the last one confirms. *Up at t_r*, not some time since the first flag:
a healthy robot that breaks the premises itself (a diffdrive that turns on the spot to pass
a teammate with no speed left, its command saturated and its estimate swinging past Φ̄ for
0.4 s: run 195 of the edge-speed battery) raises the very flags and the very alarm a fault
does, but its alarm comes down a window after its signal is healthy again, while the
observers' memory of the break keeps some flags up to t_r. *Since the last judgement*
after that: an intermittent fault whose t_r falls in an off phase is excluded at the next
judgement, however its period and Δt_d,max line up.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .block import TeamConfig
from .decision import count_for, tick


@njit(cache=True)
def watch_estimates(phi_hat, u_bar, phi_bar, limit, need, timer, alarm, seen):  # pragma: no cover
    """One period of every robot's own alarm, in place. ``phi_hat``, ``u_bar`` (N, 2): the
    fault estimates and the commands; ``phi_bar``: Φ̄; ``limit``: the per-axis command
    range; ``need``: the window in periods; ``timer`` (N,) int32, ``alarm`` and ``seen``
    (N,) bool."""
    bound = phi_bar * phi_bar
    top = max(need, 1)
    for i in range(phi_hat.shape[0]):
        p0, p1 = phi_hat[i, 0], phi_hat[i, 1]
        out = p0 * p0 + p1 * p1 > bound or max(abs(u_bar[i, 0]), abs(u_bar[i, 1])) > limit
        c = tick(timer[i], out, need)
        timer[i] = c
        if c >= top:
            alarm[i] = True
        elif -c >= top:
            alarm[i] = False
        if alarm[i]:
            seen[i] = True


class AlarmRecord(NamedTuple):
    """What the compiled period (:mod:`.period`) reads and writes of the alarms."""

    timer: np.ndarray  # (N,) int32, periods out (> 0) or in (< 0), as the decision's timers
    alarm: np.ndarray  # (N,) bool, each robot's own alarm
    seen: np.ndarray  # (N,) bool, up since the recovery last asked
    phi_bar: float  # Φ̄ [m/s]
    limit: float  # the per-axis command range [m/s]
    need: int  # the window in control periods
    on: bool  # watched (fdir.confirm_by_estimate, with compensation and a finite Φ̄)


class EstimateAlarm:
    """Every robot's own alarm (original robot axis): ‖φ̂‖ > Φ̄ or ū out of range for
    ``need`` periods in a row. ``on``: the recovery asks it (:meth:`confirms`)."""

    def __init__(self, n: int, phi_bar: float, limit: float, need: int, on: bool = True) -> None:
        self.phi_bar = float(phi_bar)
        self.limit = float(limit)
        self.need = int(need)
        self.on = bool(on and np.isfinite(self.phi_bar))  # a Python bool, as numba unboxes it
        self.timer = np.zeros(n, np.int32)
        self.alarm = np.zeros(n, bool)
        self.seen = np.zeros(n, bool)

    @classmethod
    def of(cls, config: TeamConfig, n: int, rule_bound: float | None = None) -> EstimateAlarm:
        """The team's alarms: Φ̄ of ``config`` (or a thresholds rule's own larger bound on a
        healthy ‖φ̂‖, ``rule_bound``, such as a real robot's stated ``phi_bar``), Remark 5.2's
        window in control periods, and on with ``fdir.confirm_by_estimate`` where FDIR
        compensates (without compensation Φ̄ bounds nothing)."""
        phi_bar = max(config.phi_bar, float(rule_bound or 0.0))
        need = count_for(config.detection_window, config.dt)
        on = config.confirm_by_estimate and config.fdir and config.compensate
        return cls(n, phi_bar, config.command_limit, need, on)

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

    def restart(self, robot: int) -> None:
        """From now on ``seen`` tells whether robot ``robot``'s alarm was up since now."""
        self.seen[robot] = self.alarm[robot]

    def confirms(self, robot: int, heard: bool = True, again: bool = False) -> bool:
        """Whether robot ``robot``'s alarm is up now (its first judgement at t_r) or, when it
        is judged ``again``, was up since the last :meth:`restart`, which it does again; True
        when the check is off, or when its teammates do not hear its messages (``heard``
        False: a silent radio; unheard is not healthy)."""
        if not (self.on and heard):
            return True
        up = bool(self.seen[robot] if again else self.alarm[robot])
        self.restart(robot)
        return up
