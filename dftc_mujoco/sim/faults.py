"""Actuator faults injected through the actuator model (docs/notes.md, 15).

A *bias* fault φ(t) (a planar velocity offset of the controlled point) is mapped by
the robot's drive to joint-velocity offsets and written into the actuators' bias term
b0, as each actuator kind needs (:mod:`.actuators`): the velocity servo tracks
ctrl + φ after ctrl clamping, like a real offset; a position servo's target drifts
by ∫φ; a torque motor's inner loop is offset. A *stop* zeroes the actuator gain: a
velocity servo or a motor brakes the joint to rest, a position servo holds where it
was. The controller's command is never touched. Works for any N.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from ..errors import InputError
from ..scenario import ACTUATOR_FAULTS, Fault


class ActuatorFaults:
    """Switches the scenario's faults on in the model's actuator parameters.

    ``drive`` is the robots' drive (:mod:`.drives`): it maps a planar φ to joint
    velocities, and its actuation writes them into the actuators of the scene.
    """

    def __init__(self, model: mujoco.MjModel, faults: tuple[Fault, ...], drive: Any) -> None:
        self.model = model
        self.faults = tuple(f for f in faults if f.kind in ACTUATOR_FAULTS)  # the actuators'
        faults = self.faults
        self.drive = drive
        self.actuation = drive.actuation
        self.actuator = drive.actuation.ids  # (N, A)
        self._saved = (
            model.actuator_gainprm[:, 0].copy(),
            model.actuator_biasprm[:, :3].copy(),
            model.actuator_biastype.copy(),
        )
        n = len(self.actuator)
        self.stopped = np.zeros(n, bool)
        self.started = [False] * len(faults)
        self._stop_terms: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        bias = [f for f in faults if f.kind in ("bias", "drift")]  # drift: a growing bias
        self._bias_robots = np.array(sorted({f.robot for f in bias}), dtype=int)
        self._b_robot = np.array([f.robot for f in bias], dtype=int)
        self._b_t = np.array([f.t for f in bias])
        self._b_tau = np.array([f.time_constant for f in bias])
        self._b_value = np.array([f.value for f in bias]).reshape(-1, 2)
        self._b_end = np.array([f.end for f in bias])
        self._b_ramp = np.array([f.kind == "drift" for f in bias], dtype=bool)
        # after this instant a bias profile no longer changes (1 − e^{−40} rounds to 1)
        self._b_settled = np.where(self._b_ramp, np.inf, self._b_t + 40.0 * self._b_tau)
        self._phi = np.zeros((len(self.actuator), 2))  # bias_phi's result, reused
        self._phi_flat = self._phi.reshape(-1)  # a view: its entries written one by one
        # the bias faults as Python numbers (bias_phi every period: no NumPy arrays; paper_case:
        # 3.7-5.5 µs a call when each fault's value was an array, 1.4-2.4 µs since)
        vx, vy = self._b_value.T.tolist()
        self._b_list = list(
            zip(
                (2 * self._b_robot).tolist(), self._b_t.tolist(), self._b_end.tolist(),
                self._b_tau.tolist(), self._b_ramp.tolist(), vx, vy, strict=True,
            )
        )  # fmt: skip
        self.due = min((f.t for f in faults), default=np.inf)  # next time apply() has work
        # the faults _switch reads, and when what it finds may next change (-inf: now)
        self._switched = tuple(f for f in faults if f.kind not in ("bias", "drift"))
        self._switch_due = -np.inf
        self._moving_until = -np.inf  # a bias profile moves (apply() every period) until then
        self.ended = [False] * len(faults)
        self.just_ended: list[Fault] = []  # the faults that ended at the last apply()
        self._mark = self.due  # the next start or end of a fault (apply() looks then)
        self._b0 = model.actuator_biasprm[:, 0]  # a view into the model: the bias terms b0
        # per biased robot running: (its two actuators, their kv·gear, its bias faults), where
        # b0 is kv·gear·φ itself (the disk: apply() 1.8 µs a call where the arrays took 3.4)
        self._direct: list[tuple[list[int], list[float], list[tuple]]] | None = None
        self._bias_rows = self._rows_of(self.stopped)
        self._gain = np.ones(n)  # each robot's remaining effectiveness (loss_of_effectiveness)
        self.stuck = np.zeros(n, bool)  # robots whose actuators keep the command of onset
        self.any_stuck = False  # stuck.any(), read every period
        self._stuck_ctrl: dict[int, np.ndarray] = {}
        if self.actuation.any_position and any(f.kind == "loss_of_effectiveness" for f in faults):
            raise InputError(
                "faults: loss_of_effectiveness is modelled for velocity servos and motors; this "
                "robot drives position servos (whose gain scales the position, not the speed)"
            )

    def _rows_of(self, stopped: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The biased robots that are not ``stopped``, and their actuators (R, A); for a
        drive whose joints are the plane's axes, driven by velocity servos (the disk), the
        same as Python numbers for :meth:`apply` (:attr:`_direct`)."""
        rows = self._bias_robots[~stopped[self._bias_robots]]
        ids = self.actuator[rows]
        if self.drive.planar_joints and self.actuation.velocity_only:
            k = self.actuation.bias_per_velocity.tolist()  # (A,): the same for every robot
            own = [[b[1:] for b in self._b_list if b[0] == 2 * r] for r in rows.tolist()]
            self._direct = [(i, k, o) for i, o in zip(ids.tolist(), own, strict=True)]
        return rows, ids

    def _acting(self, f: Fault, t: float) -> bool:
        """Fault ``f`` acts at ``t``: started, not ended, and (intermittent) in an on window."""
        if t < f.t or t >= f.end:
            return False
        if f.kind == "intermittent":
            return (t - f.t) % f.period < f.duty * f.period - 1e-12
        return True

    def _switch(self, t: float) -> None:
        """Stops (and intermittent stops) that begin or end at ``t``, and the robots' remaining
        effectiveness: the actuators of a robot no longer stopped get their healthy
        parameters back (times its effectiveness)."""
        m, (gain0, bias0, _) = self.model, self._saved
        stopped = np.zeros_like(self.stopped)
        gain = np.ones_like(self._gain)
        stuck = np.zeros_like(self.stuck)
        for f in self.faults:
            if self._acting(f, t):
                if f.kind in ("stop", "intermittent"):
                    stopped[f.robot] = True
                elif f.kind == "loss_of_effectiveness":
                    gain[f.robot] *= float(f.value[0])
                elif f.kind == "stuck":
                    stuck[f.robot] = True
        for robot in np.flatnonzero(self.stuck & ~stuck):
            self._stuck_ctrl.pop(int(robot), None)
        self.stuck, self.any_stuck = stuck, bool(stuck.any())
        for robot in np.flatnonzero(stopped & ~self.stopped):
            self._stop_terms[int(robot)] = self.actuation.stop_terms(np.array([robot]))
        for robot in np.flatnonzero((~stopped & self.stopped) | (gain != self._gain)):
            ids = self.actuator[robot]
            self._stop_terms.pop(int(robot), None)
            if not stopped[robot]:  # healthy again, or working at ``gain``
                m.actuator_gainprm[ids, 0] = gain0[ids] * gain[robot]
                m.actuator_biasprm[ids, 0] = bias0[ids, 0]
                m.actuator_biasprm[ids, 2] = bias0[ids, 2]
        self.stopped, self._gain = stopped, gain
        self._bias_rows = self._rows_of(stopped)
        # until the next start or end of a fault it reads it would change nothing, so
        # apply() (every period while a bias moves) skips it
        self._switch_due = _next_switch(self._switched, t)

    def apply(self, t: float) -> list[Fault]:
        """Write the actuator parameters for time ``t``; returns the faults that start now.

        Called every control period while a bias profile moves or while the drive maps a
        bias through the robot's pose or integrates it (position servos).
        """
        new: list[Fault] = []
        if self.just_ended:
            self.just_ended = []
        if t >= self._mark:  # a fault starts or ends now
            mark = np.inf
            for k, f in enumerate(self.faults):
                if not self.started[k] and t >= f.t:
                    self.started[k] = True
                    new.append(f)
                if self.started[k] and not self.ended[k] and t >= f.end:
                    self.ended[k] = True
                    self.just_ended.append(f)
                if not self.started[k]:
                    mark = min(mark, f.t)
                elif not self.ended[k]:
                    mark = min(mark, f.end)
            self._mark = mark
        if t >= self._switch_due:
            self._switch(t)
        m = self.model
        if self._direct is not None:  # b0 = kv·gear·φ, φ summed as bias_phi sums it
            b0 = self._b0
            for (i0, i1), (k0, k1), own in self._direct:
                px = py = 0.0
                for start, end, tau, ramp, vx, vy in own:
                    age = t - start
                    if age >= 0.0 and t < end:
                        shape = _shape(age, tau, ramp)
                        px += shape * vx
                        py += shape * vy
                b0[i0] = k0 * px
                b0[i1] = k1 * py
        elif len(self._bias_robots):
            phi = self.bias_phi(t)
            # drives map the whole team (a wheel offset depends on each robot's heading)
            b0 = self.actuation.bias_terms(self.drive.joint_velocity(phi), advance=True)
            rows, ids = self._bias_rows  # the biased robots that are not stopped
            self._b0[ids] = b0[rows]  # (an unchanged value: as cheap to write as to compare)
        for robot, (gain, b0, b2) in self._stop_terms.items():
            ids = self.actuator[robot]
            m.actuator_gainprm[ids, 0] = gain[0]
            m.actuator_biasprm[ids, 0] = b0[0]
            m.actuator_biasprm[ids, 2] = b2[0]
        self.due = -np.inf if t < self._moving_until else self._next_due(t)
        return new

    def hold(self, ctrl: np.ndarray) -> np.ndarray:
        """The actuator commands (N, A + H) with the stuck robots' rows kept at the commands
        they had when they got stuck (a copy: the caller's array is not touched)."""
        out = np.array(ctrl, copy=True)
        for robot in np.flatnonzero(self.stuck):
            saved = self._stuck_ctrl.setdefault(int(robot), out[robot].copy())
            out[robot] = saved
        return out

    def _next_due(self, t: float) -> float:
        """When :meth:`apply` next has something to write: every period while a bias
        profile moves (or while the drive maps a bias through the robot's pose or
        integrates it), else the next start or end of a fault."""
        started = (self._b_t <= t) & (self._b_end > t)
        if started.any():  # moving until the last of them ends (or settles: 1 − e^{−40} = 1)
            ends = self._b_end[started]
            if not (self.drive.pose_dependent or self.actuation.any_position):
                ends = np.minimum(ends, self._b_settled[started])
            until = ends.max()
            if until > t:
                self._moving_until = until
                return -np.inf
        return _next_switch(self.faults, t)

    def bias_phi(self, t: float) -> np.ndarray:
        """Σ of value·(1 − e^{−(t − t_f)/τ}) for t ≥ t_f over each robot's bias faults, (N, 2)."""
        flat = self._phi_flat  # robot r's φ at 2r, 2r + 1
        flat.fill(0.0)
        for at, start, end, tau, ramp, vx, vy in self._b_list:
            age = t - start
            if age >= 0.0 and t < end:
                shape = _shape(age, tau, ramp)
                flat[at] += shape * vx
                flat[at + 1] += shape * vy
        return self._phi

    def _bias_profile(self, t: np.ndarray) -> np.ndarray:
        phi = np.zeros((len(t), len(self.actuator), 2))
        if len(self._b_robot):
            age = t[:, None] - self._b_t[None, :]
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                shape = np.where(self._b_tau > 0, 1.0 - np.exp(-age / self._b_tau), 1.0)
            shape = np.where(self._b_ramp[None, :], age, shape)  # a drift grows with age
            shape = np.where((age >= 0) & (t[:, None] < self._b_end[None, :]), shape, 0.0)
            for j, robot in enumerate(self._b_robot):
                phi[:, robot] += shape[:, j, None] * self._b_value[j]
        return phi

    def phi_series(self, t: np.ndarray, v_cmd: np.ndarray) -> np.ndarray:
        """φ (T, N, 2) at logged instants ``t`` (T,) from the logged planar commands ``v_cmd``
        (T, N, 2): a bias is its profile, a stop is −(the command it no longer delivers);
        derived after the run instead of inside it."""
        phi = self._bias_profile(t)
        for f in self.faults:
            if f.kind == "stuck":  # it keeps delivering the command of its onset
                rows = np.array([self._acting(f, float(x)) for x in t], dtype=bool)
                if rows.any():
                    first = int(np.argmax(rows))
                    phi[rows, f.robot] = v_cmd[first, f.robot] - v_cmd[rows, f.robot]
            if f.kind in ("stop", "intermittent", "loss_of_effectiveness"):
                rows = np.array([self._acting(f, float(x)) for x in t], dtype=bool)
                lost = 1.0 if f.kind != "loss_of_effectiveness" else 1.0 - float(f.value[0])
                phi[rows, f.robot] = -lost * v_cmd[rows, f.robot]
        return phi

    def phi(self, t: float, v_cmd: np.ndarray) -> np.ndarray:
        """The additive fault φ of eq. 1 each robot suffers at ``t`` (N, 2), given the planar
        commands ``v_cmd`` (N, 2) the drives are asked for (clipped to the command range)."""
        return self.phi_series(np.array([t]), v_cmd[None])[0]

    def clear(self) -> None:
        """Restore the healthy actuator parameters."""
        gain, bias, biastype = self._saved
        self.model.actuator_gainprm[:, 0] = gain
        self.model.actuator_biasprm[:, :3] = bias
        self.model.actuator_biastype[:] = biastype
        self.stopped[:] = False
        self._bias_rows = self._rows_of(self.stopped)
        self.stuck[:] = False
        self.any_stuck = False
        self._stuck_ctrl.clear()
        self._gain[:] = 1.0
        self.started = [False] * len(self.faults)
        self.ended = [False] * len(self.faults)
        self._stop_terms.clear()
        self.actuation.bias_integral[:] = 0.0
        self.due = self._mark = min((f.t for f in self.faults), default=np.inf)
        self._switch_due = self._moving_until = -np.inf


def _next_switch(faults: tuple[Fault, ...], t: float) -> float:
    """The next start or end after ``t`` of any of ``faults``; -inf while an intermittent one
    acts (its windows switch on and off), inf when none is left."""
    times = []
    for f in faults:
        if t < f.t:
            times.append(f.t)
        elif t < f.end:
            if f.kind == "intermittent":
                return -np.inf
            times.append(f.end)
    return min(times, default=np.inf)


def _shape(age: float, tau: float, ramp: bool) -> float:
    """A bias fault's profile ``age`` s after its onset: 1 − e^{−age/τ} (a step for τ = 0),
    or ``age`` for a drift (value [m/s²] × age); NumPy's exp, as the profile after the run."""
    return age if ramp else (1.0 - np.exp(-age / tau) if tau > 0 else 1.0)
