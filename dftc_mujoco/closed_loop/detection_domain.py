"""Eq. 46's domain: the faults whose detection within Δt_d,max the thresholds promise.

Eq. 46 bounds the time every teammate needs to flag a fault of the reference size once the
thresholds have settled (T_s), and while they stay settled over the fault's whole window
[t_f, t_f + Δt_d,max]. The simulation knows each fault's onset (the robots do not) and says,
as events, which faults fall outside that domain and why:

- ``detection_past_end``: the window passes the end of the run;
- ``detection_not_guaranteed``: the fault comes before the thresholds settle (T_s, or the
  restarted rule's own after an exclusion);
- ``detection_window_restarted``: another robot's exclusion within the window restarted the
  thresholds, which start again from the residuals' bound (``docs/thresholds.md``,
  "Recovery"), so the promise made at the onset no longer holds.

The campaign rows' ``in_domain`` (:func:`.campaign.task.fault_facts`) reads these events.
"""

from __future__ import annotations

import math

from ..core.events import Kind
from ..core.record import Events


class DetectionDomain:
    """Eq. 46's domain of the faults of a run that ends at ``end`` [s], told as ``events``."""

    def __init__(self, events: Events, end: float) -> None:
        self.events, self.end = events, end
        self.windows: list[tuple[int, float, float]] = []  # robot (from 1), onset, window's end

    def onset(self, t: float, robot: int, dt_d_max: float) -> None:
        """A fault of ``robot`` (numbered from 1) begins at ``t``, before the team's period;
        ``dt_d_max``: Δt_d,max then."""
        left = round(self.end - t, 6)  # the run left after its onset
        if left < dt_d_max:
            limit = round(dt_d_max, 6)
            self.events.add(t, Kind.DETECTION_PAST_END, robot=robot, left=left, dt_d_max=limit)

    def after_period(
        self, t: float, robot: int, settles_at: float, restarted: float | None, dt_d_max: float
    ) -> None:
        """After the team's period of the onset (an exclusion now restarted the rule):
        before the thresholds settle at ``settles_at``, or its window opens."""
        if t < settles_at:
            until = settles_at if math.isfinite(settles_at) else None  # None: not in the run
            self.events.add(
                t, Kind.DETECTION_NOT_GUARANTEED, robot=robot, until=until, restarted=restarted
            )
        else:
            self.windows.append((robot, round(t, 6), t + dt_d_max))  # onset as its event's

    def excluded(self, t: float, robot: int, settles_at: float) -> None:
        """``robot`` was excluded at ``t`` and the thresholds restarted (they settle again at
        ``settles_at``): the open windows of the other robots' faults lose the promise."""
        until = settles_at if math.isfinite(settles_at) else None
        for r, t_f, end in self.windows:
            if r != robot and t_f < t <= end + 1e-9:
                self.events.add(t, Kind.DETECTION_WINDOW_RESTARTED, robot=r, onset=t_f, until=until)
        self.windows.clear()  # cut, ended, or the excluded robot's own
