"""Reading the ``[[faults]]`` tables: actuator faults (bias, stop and the zoo), sensor
faults and radio faults (:mod:`.parts`), each kind with the keys it reads."""

from __future__ import annotations

import math

import numpy as np

from ..runtime.tomlcheck import N_DIM, Table, _ro
from .parts import ACTUATOR_FAULTS, RADIO_FAULTS, SENSOR_FAULTS, Fault, RadioFault


def read_fault(t: Table, n: int | None, duration: float | None) -> Fault | RadioFault:
    """One ``[[faults]]`` table: an actuator, sensor or radio fault, every key checked."""
    kind = t.string("kind", choices=(*ACTUATOR_FAULTS, *SENSOR_FAULTS, *RADIO_FAULTS))
    at = t.number("t", low=0.0, strict_low=False)
    if duration is not None and t.ok("t") and at >= duration:
        t.report("t", f"fault at {at:g} s is after the end of the run (duration = {duration:g} s)")
    if kind == "link_down":
        link = t.array("link", (2,), what="[from, to], robots numbered from 1")
        if t.ok("link"):
            if np.any(link != np.round(link)) or (
                n is not None and not np.all((link >= 1) & (link <= n))
            ):
                t.report("link", f"expected two robots in 1..{n}, got {link.tolist()}")
        t.finish()
        return RadioFault(kind, at, link=(int(link[0]) - 1, int(link[1]) - 1))
    robot = t.integer("robot")
    if n is not None and t.ok("robot") and not 1 <= robot <= n:
        t.report("robot", f"robot {robot} out of range: robots are numbered 1..{n}")
    if kind in RADIO_FAULTS:
        offset = t.number("value", low=0.0) if kind == "corrupt" else 0.0
        t.finish()
        return RadioFault(kind, at, robot=robot - 1, value=offset)
    if not t.ok("kind"):
        t.used.update(t.data)  # which keys belong here depends on the kind
        return Fault(robot - 1, kind, at)
    if kind in SENSOR_FAULTS:
        unit = "m" if kind == "sensor_bias" else "m/s"
        value = t.array("value", (N_DIM,), what=f"an [x, y] pair in {unit}")
        _not_zero(t, value)
        end = _fault_end(t, at)
        t.finish()
        return Fault(robot - 1, kind, at, value, 0.0, end)
    end = _fault_end(t, at)
    if kind == "loss_of_effectiveness":
        g = t.number("value", low=0.0, strict_low=False, high=1.0)
        if t.ok("value") and g >= 1.0:
            t.report("value", "expected the remaining effectiveness below 1 (1 is no fault)")
        t.finish()
        return Fault(robot - 1, kind, at, _ro([g, g]), 0.0, end)
    if kind == "drift":
        rate = t.array("value", (N_DIM,), what="an [x, y] pair in m/s²")
        _not_zero(t, rate)
        t.finish()
        return Fault(robot - 1, kind, at, rate, 0.0, end)
    if kind == "stuck":
        t.finish()
        return Fault(robot - 1, kind, at, _ro([0.0, 0.0]), 0.0, end)
    if kind == "intermittent":
        period = t.number("period", low=0.0)
        duty = t.number("duty", low=0.0, high=1.0)
        t.finish()
        return Fault(robot - 1, kind, at, _ro([0.0, 0.0]), 0.0, end, period, duty)
    if kind == "bias":
        value = t.array("value", (N_DIM,), what="an [x, y] pair in m/s")
        _not_zero(t, value)
        tau = t.number("time_constant", 0.0, low=0.0, strict_low=False)
        fault = Fault(robot - 1, kind, at, value, tau, end)
    else:  # a stop fault has no bias; zeros are accepted (Scenario.to_dict writes them)
        value = t.array("value", (N_DIM,), [0.0, 0.0], what="an [x, y] pair")
        if t.ok("value") and np.any(value != 0):
            t.report(
                "value", f"expected [0.0, 0.0] or no value for a stop fault, got {value.tolist()}"
            )
        tau = t.number("time_constant", 0.0, low=0.0, strict_low=False)
        if t.ok("time_constant") and tau != 0:
            t.report(
                "time_constant", f"expected 0 or no time_constant for a stop fault, got {tau:g}"
            )
        fault = Fault(robot - 1, kind, at, end=end)
    t.finish()
    return fault


def _not_zero(t: Table, value: np.ndarray) -> None:
    """A bias, drift or sensor fault of [0, 0] changes nothing, yet its robot would count as
    the faulty one (a teammate's flag on it a detection, not a false alarm): refused, as a
    loss of effectiveness of 1 is."""
    if t.ok("value") and not np.any(value):
        t.report("value", "expected a nonzero [x, y] pair ([0, 0] is no fault)")


def _fault_end(t: Table, at: float) -> float:
    """A fault's optional ``end`` [s], after its start (inf: it lasts to the end)."""
    if "end" not in t.data:
        return float("inf")
    end = t.number("end", low=0.0)
    if t.ok("t", "end") and end <= at:
        t.report("end", f"expected a time after t = {at:g} s, got {end:g}")
    return end


def timing_problem(f: Fault, h: float, duration: float) -> tuple[str, str] | None:
    """The key and why fault ``f`` cannot act as written with control period ``h`` in a run
    of ``duration``, or None. The faults switch at the control instants k·h
    (:mod:`~dftc_mujoco.sim.faults`, :mod:`~dftc_mujoco.sim.sensors`): a fault shorter than a
    period, or an intermittent one whose on or off windows are, would act for a whole period
    or not at all (a 5 ms bias acted 10 ms; 1.5 ms on of every 5 ms acted at every instant);
    one that spans no instant before the end changes nothing, yet its robot would count as
    the faulty one, as a fault of size 0 would."""
    if f.t >= duration:  # read_fault said so
        return None
    short = h * (1 - 1e-9)
    if f.end - f.t < short:
        return "end", (
            f"it lasts {f.end - f.t:g} s, less than a control period ({h:g} s), at whose "
            f"instants the faults switch: expected end >= t + {h:g}"
        )
    if f.kind == "intermittent":
        on = f.duty * f.period
        if on < short:
            return "duty", (
                f"its on windows ({on:g} s of every {f.period:g} s) are shorter than a control "
                f"period ({h:g} s), at whose instants the faults switch: expected period × duty "
                f">= {h:g} s"
            )
        if 0 < f.period - on < short:
            return "duty", (
                f"its off windows ({f.period - on:g} s of every {f.period:g} s) are shorter than "
                f"a control period ({h:g} s), at whose instants the faults switch: expected "
                f"period × (1 - duty) >= {h:g} s, or duty = 1"
            )
    k = math.ceil(f.t / h)  # the first instant k·h at or after t, as the loop computes it
    k += (k * h < f.t) - ((k - 1) * h >= f.t)
    if k * h >= duration:
        return "t", (
            f"the run ends at {duration:g} s before a control instant (every {h:g} s) at or "
            f"after t = {f.t:g} s: it would never act"
        )
    return None
