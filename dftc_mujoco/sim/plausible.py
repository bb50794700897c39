"""What a robot file's ``[calibration]`` values can be for a planar robot: a value beyond
these is a unit slip (mm/s typed as m/s, ms as s), and each would switch a guarantee off in
silence (a drift offset of 100 m widens every threshold until no fault is detected, a
response time of 10⁶ s holds every exclusion past the end of the run)."""

from __future__ import annotations

#: key: (largest plausible value, its unit, an example in that unit, what a larger one does)
LIMITS: dict[str, tuple[float, str, str, str]] = {
    "xi_bar": (1.0, "m/s", "5 mm/s is 0.005", "widens every threshold: no fault is detected"),
    "mismatch": (1.0, "m/s", "2 mm/s is 0.002", "leaves no room for the noise ξ"),
    "startup_mismatch": (1.0, "m/s", "2 mm/s is 0.002", "is no settling robot's"),
    "startup_time": (60.0, "s", "0.5 s is 0.5", "is no settling robot's"),
    "response_time": (60.0, "s", "60 ms is 0.06", "holds every exclusion past the run's end"),
    "lag": (60.0, "s", "80 ms is 0.08", "makes the drive model ignore every command"),
    "drift_bound": (1.0, "m", "2.7 mm is 0.0027", "widens every threshold: no fault is detected"),
    "drift_startup": (1.0, "m", "4.7 mm is 0.0047", "widens every threshold at the start"),
    "drift_replan": (1.0, "m", "2.4 mm is 0.0024", "widens every threshold after a re-plan"),
    "drift_settle": (3600.0, "s", "5 s is 5.0", "keeps the start-up's bound for the whole run"),
    "saturation": (1.0, "", "a share of the commands: 5 % is 0.05", "is more than all of them"),
    "compensation_G": (10.0, "s", "the paper's is 0.01", "switches the compensation off"),
    "timestep": (0.01, "s", "0.5 ms is 0.0005", "is longer than a control period"),
    "track": (10.0, "m", "45 cm is 0.45", "is no planar robot's axle"),
}
#: [m/s²] the least acceleration limit a robot that follows a mission can have
LEAST_ACCEL = 0.01


def calibration_problem(key: str, value: float) -> str | None:
    """Why ``[calibration] key = value`` cannot be a planar robot's, or None."""
    if key == "accel":
        if 0 < value < LEAST_ACCEL:
            return (
                f"{value:g} m/s² would take the robot {1.0 / value:g} s to reach 1 m/s: no "
                f"mission can be followed (expected 0, no limit, or at least {LEAST_ACCEL:g} "
                "m/s²; the disk's is 16)"
            )
        return None
    if key not in LIMITS:
        return None
    high, unit, example, does = LIMITS[key]
    if value <= high:
        return None
    shown = f"{value:g} {unit}".rstrip()
    return (
        f"{shown} is beyond any planar robot's (expected at most {high:g}; {example}): "
        f"a unit slip? it {does}"
    )
