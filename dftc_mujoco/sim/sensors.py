"""Faults of the robots' position sensors, injected where they live: on the measurement
x_m = x + η (eq. 4) each robot receives, never on the true state."""

from __future__ import annotations

import math

import numpy as np

from ..scenario import SENSOR_FAULTS, Fault


class SensorFaults:
    """The scenario's sensor faults: a bias (``value`` m) or a drift (``value`` × (t − t_f),
    m/s) added to a robot's measured position from ``t`` until ``end``."""

    def __init__(self, faults: tuple[Fault, ...], n: int) -> None:
        self.faults = [f for f in faults if f.kind in SENSOR_FAULTS]
        self.offset = np.zeros((n, 2))
        self.started = [False] * len(self.faults)
        self.ended = [False] * len(self.faults)
        self.due = min((f.t for f in self.faults), default=math.inf)  # next time to act
        self.active = False  # some sensor fault acts now

    def apply(self, t: float, x_m: np.ndarray) -> tuple[list[Fault], list[Fault]]:
        """Add the faults' offsets at ``t`` to ``x_m`` (N, 2) in place; returns the faults
        that start now and those that end now."""
        began, over = [], []
        self.offset[:] = 0.0
        for k, f in enumerate(self.faults):
            if t < f.t:
                continue
            if t >= f.end:
                if not self.ended[k]:
                    self.ended[k] = True
                    over.append(f)
                continue
            if not self.started[k]:
                self.started[k] = True
                began.append(f)
            scale = 1.0 if f.kind == "sensor_bias" else t - f.t
            self.offset[f.robot] += scale * np.asarray(f.value, float)
        self.active = any(s and not e for s, e in zip(self.started, self.ended, strict=True))
        x_m += self.offset
        waiting = [f.t for k, f in enumerate(self.faults) if not self.started[k]]
        ending = [f.end for k, f in enumerate(self.faults) if self.started[k] and not self.ended[k]]
        self.due = -math.inf if self.active else min(waiting + ending, default=math.inf)
        return began, over
