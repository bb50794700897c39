"""Actuator faults injected through the actuator model (NOTES 15).

A velocity actuator produces ``gain·ctrl + bias0 + bias2·qvel`` with
gain = kv and bias2 = −kv. A *bias* fault φ(t) sets ``bias0 = kv·φ``: the
actuator tracks ctrl + φ, after ctrl clamping, like a real offset. A *stop*
sets gain = bias0 = 0: the force is −kv·qvel and the robot brakes to rest
whatever it is commanded. The controller's command is never touched.
Works for any N (no actuator groups).
"""

from __future__ import annotations

import mujoco
import numpy as np

from ..scenario import Fault


class ActuatorFaults:
    """Switches the scenario's faults on in the model's actuator parameters."""

    def __init__(
        self, model: mujoco.MjModel, faults: tuple[Fault, ...], actuator: np.ndarray, adapter
    ) -> None:
        self.model = model
        self.faults = faults
        self.actuator = actuator  # (N, A)
        self.adapter = adapter
        self.kv = model.actuator_gainprm[actuator, 0].copy()  # (N, A)
        self._gain0 = model.actuator_gainprm[:, 0].copy()
        self._bias0 = model.actuator_biasprm[:, 0].copy()
        self.stopped = np.zeros(len(actuator), bool)
        self.started = [False] * len(faults)
        self._bias_robots = sorted({f.robot for f in faults if f.kind == "bias"})
        self._written: np.ndarray | None = None  # bias terms last written
        bias = [f for f in faults if f.kind == "bias"]
        self._b_robot = np.array([f.robot for f in bias], dtype=int)
        self._b_t = np.array([f.t for f in bias])
        self._b_tau = np.array([f.time_constant for f in bias])
        self._b_value = np.array([f.value for f in bias]).reshape(-1, 2)
        # after this instant a bias profile no longer changes (1 − e^{−40} rounds to 1)
        self._b_settled = self._b_t + 40.0 * self._b_tau
        self.due = min((f.t for f in faults), default=np.inf)  # next time apply() has work

    def apply(self, t: float) -> list[Fault]:
        """Write the actuator parameters for time ``t``; returns the faults that start now."""
        new = []
        for k, f in enumerate(self.faults):
            if not self.started[k] and t >= f.t:
                self.started[k] = True
                new.append(f)
                if f.kind == "stop":
                    self.stopped[f.robot] = True
        if not self._bias_robots and not new:
            return new
        phi = self.bias_phi(t)
        ids = self.actuator[self._bias_robots]
        # adapters map the whole team (a wheel offset depends on each robot's heading)
        offsets = self.kv[self._bias_robots] * self.adapter.bias(phi)[self._bias_robots]
        if self._written is None or not np.array_equal(offsets, self._written):
            self.model.actuator_biasprm[ids, 0] = offsets
            self._written = offsets
        if self.stopped.any():
            stop = self.actuator[self.stopped]
            self.model.actuator_gainprm[stop, 0] = 0.0
            self.model.actuator_biasprm[stop, 0] = 0.0
        self.due = self._next_due(t)
        return new

    def _next_due(self, t: float) -> float:
        """When :meth:`apply` next has something to write: every period while a bias profile
        moves (or while the adapter maps a bias through the robot's pose), else the next start."""
        pending = [f.t for k, f in enumerate(self.faults) if not self.started[k]]
        started = self._b_t <= t
        if started.any() and (
            getattr(self.adapter, "pose_dependent", False) or (self._b_settled[started] > t).any()
        ):
            return -np.inf
        return min(pending, default=np.inf)

    def bias_phi(self, t: float) -> np.ndarray:
        """Σ of value·(1 − e^{−(t − t_f)/τ}) for t ≥ t_f over each robot's bias faults, (N, 2)."""
        phi = np.zeros((len(self.actuator), 2))
        if len(self._b_robot):
            age = t - self._b_t
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                shape = np.where(self._b_tau > 0, 1.0 - np.exp(-age / self._b_tau), 1.0)
            shape = np.where(age >= 0, shape, 0.0)
            np.add.at(phi, self._b_robot, shape[:, None] * self._b_value)
        return phi

    def phi_series(self, t: np.ndarray, ctrl: np.ndarray, heading: np.ndarray) -> np.ndarray:
        """φ (T, N, 2) at logged instants ``t`` (T,) from the logged commands ``ctrl``
        (T, N, A) and headings (T, N): what :meth:`phi` gave at those instants, derived
        after the run instead of inside it."""
        phi = np.zeros((len(t), len(self.actuator), 2))
        if len(self._b_robot):
            age = t[:, None] - self._b_t[None, :]
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                shape = np.where(self._b_tau > 0, 1.0 - np.exp(-age / self._b_tau), 1.0)
            shape = np.where(age >= 0, shape, 0.0)
            for j, robot in enumerate(self._b_robot):
                phi[:, robot] += shape[:, j, None] * self._b_value[j]
        lo, hi = self.model.actuator_ctrlrange[self.actuator].transpose(2, 0, 1)
        for f in self.faults:
            if f.kind != "stop":
                continue
            rows = np.flatnonzero(t >= f.t)
            for r in rows:
                clamped = np.clip(ctrl[r], lo, hi)
                phi[r, f.robot] = -self.adapter.planar(clamped, heading[r])[f.robot]
        return phi

    def phi(self, t: float, ctrl: np.ndarray) -> np.ndarray:
        """The additive fault φ of eq. 1 each robot suffers at ``t``, (N, 2).

        A bias is its profile; a stop is φ = −(clamped command), the velocity
        that the actuators no longer deliver.
        """
        phi = self.bias_phi(t)
        if self.stopped.any():
            lo, hi = self.model.actuator_ctrlrange[self.actuator].transpose(2, 0, 1)
            clamped = np.clip(ctrl, lo, hi)
            phi[self.stopped] = -self.adapter.planar(clamped)[self.stopped]
        return phi

    def clear(self) -> None:
        """Restore the healthy actuator parameters."""
        self.model.actuator_gainprm[:, 0] = self._gain0
        self.model.actuator_biasprm[:, 0] = self._bias0
        self.stopped[:] = False
        self.started = [False] * len(self.faults)
        self._written = None
        self.due = min((f.t for f in self.faults), default=np.inf)
