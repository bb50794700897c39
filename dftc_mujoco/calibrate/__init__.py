"""``python -m dftc_mujoco.calibrate MODEL``: measure a robot model's mismatch ‖ẋ − u‖.

The paper models every robot as ẋ = u + φ + ξ with ‖ξ‖ ≤ ξ̄ (eqs. 1-2). A real body
(mass, actuator lag, wheels, friction) is not an integrator: this drives one robot of
the model, alone and noise-free, from its initial pose through planar velocity
commands at the control rate, and measures how far the velocity of its controlled
point is from the command.

What is measured, separately:

* **start-up**: the robot settles from its initial pose under a zero command (a robot
  on a free joint drops onto its wheels); the start-up lasts until the mismatch has
  stayed below 2 mm/s for 0.5 s (at most :data:`STARTUP_MAX` s) and is reported on its
  own, never counted as smooth;
* **smooth commands**, scaled to the robot's command range: ramps to 0.1, 0.3 and
  0.5 m/s at 0.25 m/s² (each at most 80 % of the range), circles of 0.5 and 1 m and a
  figure-eight;
* **command jumps** (a step, a 90° switch, a reversal, a stop), each held
  :data:`JUMP_HOLD` s: the samples from a jump until the mismatch is back below the
  smooth level count as jump-affected, however long that takes (the robot's own
  response time, reported);
* **saturation**: the share of the commands the actuators clamped;
* **the drive's lag**: the time constant τ of the first-order lag whose response to the
  programme best fits the measured velocity (least squares). When τ is at least
  :data:`LAG_MIN` and the lag model halves the rms mismatch, the robot models its drive
  (``lag`` in ``[calibration]``, ``onboard/applied.py``) and every mismatch above is then
  measured against that model, ‖ẋ − v̂‖, not against the command.

The recommended ξ̄ is the largest mismatch on smooth commands, rounded up to 0.5 mm/s,
and never below the paper's 5 mm/s. With ``--scenario`` (default ``paper_case``) it
also says which constant fault the scenario's thresholds then detect for sure (eq. 46)
and warns when faults of the mission's size would go undetected. ``--write`` stores
the results in the robot file's ``[calibration]`` table (for an MJCF of the older
contract, in its ``<custom>`` numerics, through MjSpec); the MJCF of a robot file is
never edited. Exit codes: 0, 2 bad input, 5 the file cannot be written.
"""

from __future__ import annotations

from .command import main
from .compensation import (
    ACCEL_CANDIDATES,
    G_CANDIDATES,
    Compensation,
    acceleration,
    acceleration_report,
    closed_loop,
    compensation,
    compensation_report,
    turns,
)
from .drift import REPLAN_WINDOW, Drift, drift, split_drift
from .files import check_writable, write
from .mismatch import (
    CONTROL_PERIOD,
    JUMP_HOLD,
    LAG_CANDIDATES,
    LAG_MIN,
    PAPER_XI_BAR,
    SETTLED_FOR,
    STARTUP_MAX,
    STARTUP_QUIET,
    TIMESTEP,
    Calibration,
    Programme,
    _analyse,
    detectability,
    fit_lag,
    lag_response,
    measure,
    programme,
    report,
)

__all__ = [
    "ACCEL_CANDIDATES",
    "CONTROL_PERIOD",
    "G_CANDIDATES",
    "JUMP_HOLD",
    "LAG_CANDIDATES",
    "LAG_MIN",
    "PAPER_XI_BAR",
    "REPLAN_WINDOW",
    "SETTLED_FOR",
    "STARTUP_MAX",
    "STARTUP_QUIET",
    "TIMESTEP",
    "Calibration",
    "Compensation",
    "Drift",
    "Programme",
    "_analyse",
    "acceleration",
    "acceleration_report",
    "check_writable",
    "closed_loop",
    "compensation",
    "compensation_report",
    "detectability",
    "drift",
    "fit_lag",
    "lag_response",
    "main",
    "measure",
    "programme",
    "report",
    "split_drift",
    "turns",
    "write",
]
