"""Actuator kinds: how a desired joint velocity becomes an actuator command, and how a
fault (bias or stop) is written into the actuator model.

MuJoCo's affine actuators produce ``force = gain·ctrl + b0 + b1·L + b2·L̇`` on the
actuator length L = gear·q of a joint transmission. Three kinds are driven:

* **velocity servo** (``<velocity kv>``: b1 = 0, b2 = −kv): L̇ tracks gain·ctrl/kv, so
  ctrl = (kv/gain)·gear·v for a joint velocity v. A bias φ is b0 = kv·gear·φ (the
  actuator tracks ctrl + φ, after ctrl clamping, like a real offset); a stop sets
  gain = b0 = 0, leaving −kv·L̇: the joint brakes to rest.
* **position servo** (``<position kp kv>``: b1 = −kp): L tracks gain·ctrl/kp, so the
  adapter integrates the velocity command into a target q* ← q* + h·v and sends
  ctrl = (kp/gain)·gear·q*. A bias φ shifts the target by its integral:
  b0 = kp·gear·∫φ (updated every control period); a stop holds the position the joint
  had at the stop (gain = 0, b0 = kp·L_stop).
* **torque motor** (``<motor>``, no bias): an inner velocity loop in the adapter,
  force = K·(gear·v − L̇), ctrl = force/gain, with K = I/(gear²·τ) for the joint's
  inertia I (from the model's mass matrix at the initial pose) and the loop time
  constant τ (``[motor] time_constant`` in the robot file, default
  :data:`MOTOR_TIME_CONSTANT`). Its bias is b0 = K·gear·φ (the bias type is made
  affine with zero coefficients, which changes nothing else); a stop sets gain = 0 and
  b2 = −K: a short-circuited motor that brakes.

Everything here is vectorised over (robots, actuators) and never holds control law:
the planar-to-joint mapping is the drive's (:mod:`.drives`).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

VELOCITY, POSITION, MOTOR = "velocity", "position", "motor"
MOTOR_TIME_CONSTANT = 0.05  # s, default time constant of a torque motor's velocity loop
HOLD_TIME_CONSTANT = 0.2  # s, a held joint (a base's yaw) returns to its target at this rate

_AFFINE = int(mujoco.mjtBias.mjBIAS_AFFINE)
_NONE_BIAS = int(mujoco.mjtBias.mjBIAS_NONE)
_FIXED_GAIN = int(mujoco.mjtGain.mjGAIN_FIXED)
_JOINT_TRN = (int(mujoco.mjtTrn.mjTRN_JOINT), int(mujoco.mjtTrn.mjTRN_JOINTINPARENT))
_DYN_OK = (
    int(mujoco.mjtDyn.mjDYN_NONE),
    int(mujoco.mjtDyn.mjDYN_FILTER),
    int(mujoco.mjtDyn.mjDYN_FILTEREXACT),
)
_SLIDE, _HINGE = int(mujoco.mjtJoint.mjJNT_SLIDE), int(mujoco.mjtJoint.mjJNT_HINGE)


@dataclass(frozen=True)
class ActuatorInfo:
    """One actuator of the robot model as the simulator drives it (the same for every robot)."""

    name: str
    kind: str  # velocity, position or motor
    joint: str
    joint_type: str  # "slide" or "hinge"
    joint_id: int  # in the robot's own compiled model
    gear: float
    gain: float  # gainprm[0]
    kp: float  # position stiffness −b1 (position servos)
    kv: float  # velocity gain −b2 (velocity servos; damping of position servos)
    ctrlrange: tuple[float, float] | None  # None when ctrl is not limited
    inertia: float  # the joint's inertia at the initial pose (motors' loop gain) [kg or kg m²]

    @property
    def velocity_limit(self) -> float:
        """Largest joint velocity the ctrl range lets a velocity servo ask for (inf otherwise)."""
        if self.kind != VELOCITY or self.ctrlrange is None:
            return np.inf
        lo, hi = self.ctrlrange
        return min(abs(lo), abs(hi)) * self.gain / (self.kv * abs(self.gear))


def classify(model: mujoco.MjModel, a: int) -> ActuatorInfo | str:
    """What actuator ``a`` of ``model`` is, or a sentence saying why it cannot be driven."""
    gear = float(model.actuator_gear[a, 0])
    if int(model.actuator_trntype[a]) not in _JOINT_TRN:
        return "drives no joint (tendon, site or body transmission); expected a joint actuator"
    j = int(model.actuator_trnid[a, 0])
    jtype = int(model.jnt_type[j])
    if jtype not in (_SLIDE, _HINGE):
        return "drives a ball or free joint; expected a slide or hinge joint"
    if int(model.actuator_dyntype[a]) not in _DYN_OK:
        return "has activation dynamics (integrator, muscle or user); expected a servo or a motor"
    if int(model.actuator_gaintype[a]) != _FIXED_GAIN or gear == 0.0:
        return "has a non-fixed gain or a zero gear; expected a servo or a motor"
    gain = float(model.actuator_gainprm[a, 0])
    biastype = int(model.actuator_biastype[a])
    kp = kv = 0.0
    if biastype == _AFFINE:
        kp, kv = -float(model.actuator_biasprm[a, 1]), -float(model.actuator_biasprm[a, 2])
    elif biastype != _NONE_BIAS:
        return "has a user-defined bias; expected a servo or a motor"
    if gain <= 0.0 or kp < 0.0 or kv < 0.0:
        return f"has gain {gain:g}, kp {kp:g}, kv {kv:g}; expected positive gains"
    kind = POSITION if kp > 0.0 else VELOCITY if kv > 0.0 else MOTOR
    limited = bool(model.actuator_ctrllimited[a])
    rng = tuple(float(v) for v in model.actuator_ctrlrange[a]) if limited else None
    if kind == VELOCITY and rng is not None and not (rng[0] < 0.0 < rng[1]):
        return f"is a velocity servo whose ctrlrange {rng} does not contain 0"
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) or f"actuator {a}"
    jname = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint {j}"
    return ActuatorInfo(
        name=name,
        kind=kind,
        joint=jname,
        joint_type="slide" if jtype == _SLIDE else "hinge",
        joint_id=j,
        gear=gear,
        gain=gain,
        kp=kp,
        kv=kv,
        ctrlrange=rng,  # type: ignore[arg-type]
        inertia=0.0,
    )


def motor_gain(info: ActuatorInfo, time_constant: float) -> float:
    """K of a torque motor's inner velocity loop: the joint settles with ``time_constant``."""
    return info.inertia / (info.gear**2 * time_constant)


class Actuation:
    """Actuator commands and fault parameters of a team's driven actuators.

    ``ids`` (N, A) are the actuator ids in the scene, one column per driven role, and
    ``infos`` (A,) what each column is. ``dt`` is the control period (position servos
    integrate over it). Position targets start at the joints' positions in ``data``
    (the robots' initial pose) when :meth:`reset` is called.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        ids: np.ndarray,
        infos: tuple[ActuatorInfo, ...],
        dt: float,
        motor_time_constant: float = MOTOR_TIME_CONSTANT,
    ) -> None:
        self.model, self.data, self.ids, self.infos, self.dt = model, data, ids, infos, dt
        kind = np.array([i.kind for i in infos])
        self.vel, self.pos, self.motor = kind == VELOCITY, kind == POSITION, kind == MOTOR
        self.gear = np.array([i.gear for i in infos])
        self.gain = np.array([i.gain for i in infos])
        self.kp = np.array([i.kp for i in infos])
        self.kv = np.array([i.kv for i in infos])
        self.k_motor = np.array(
            [motor_gain(i, motor_time_constant) if i.kind == MOTOR else 0.0 for i in infos]
        )
        joints = model.actuator_trnid[ids, 0]
        self.qpos_adr = model.jnt_qposadr[joints]
        self.dof_adr = model.jnt_dofadr[joints]
        # ctrl per unit of joint velocity (velocity servos) or joint position (position servos)
        self.per_velocity = np.where(self.vel, self.kv * self.gear / self.gain, 0.0)
        self.per_position = np.where(self.pos, self.kp * self.gear / self.gain, 0.0)
        self.target = np.zeros(ids.shape)  # position servos' integrated targets [joint units]
        self.bias_integral = np.zeros(ids.shape)  # ∫φ for position servos' bias faults
        self._out = np.zeros(ids.shape)
        self._velocity_only = bool(self.vel.all())  # the common case: one multiply per period
        self._bias_per_velocity = self.kv * self.gear
        if self.motor.any():  # make the bias term usable (affine with zero coefficients)
            m = ids[:, self.motor]
            model.actuator_biastype[m] = _AFFINE
        self.reset()

    @property
    def any_position(self) -> bool:
        return bool(self.pos.any())

    @property
    def velocity_only(self) -> bool:
        """Every actuator a velocity servo: b0 = kv·gear·φ (:meth:`bias_terms`)."""
        return self._velocity_only

    @property
    def bias_per_velocity(self) -> np.ndarray:
        """(A,) kv·gear per column: b0 per unit of joint velocity offset (velocity servos)."""
        return self._bias_per_velocity

    def reset(self) -> None:
        """Position targets at the joints' current positions; no integrated bias."""
        self.target[:] = self.data.qpos[self.qpos_adr]
        self.bias_integral[:] = 0.0

    def command(self, v: np.ndarray) -> np.ndarray:
        """Actuator commands (N, A) for joint velocities ``v`` (N, A) held over one period."""
        out = self._out
        np.multiply(v, self.per_velocity, out=out)
        if self._velocity_only:
            return out
        if self.pos.any():
            self.target += self.dt * np.where(self.pos, v, 0.0)
            out += self.target * self.per_position
        if self.motor.any():
            qvel = self.data.qvel[self.dof_adr]
            force = self.k_motor * self.gear * (v - qvel)
            out += np.where(self.motor, force / self.gain, 0.0)
        return out

    def hold(self, q0: np.ndarray) -> np.ndarray:
        """Commands (N, A) that keep each joint at ``q0`` (N, A): the position itself for a
        position servo, a velocity (q0 − q)/τ_hold for the others."""
        q = self.data.qpos[self.qpos_adr]
        v = (q0 - q) / HOLD_TIME_CONSTANT
        out = np.multiply(v, self.per_velocity)
        out += q0 * self.per_position
        if self.motor.any():
            qvel = self.data.qvel[self.dof_adr]
            out += np.where(self.motor, self.k_motor * self.gear * (v - qvel) / self.gain, 0.0)
        return out

    def bias_terms(self, phi: np.ndarray, advance: bool) -> np.ndarray:
        """b0 (N, A) that shifts each joint's velocity by ``phi`` (N, A) [joint units / s].

        Position servos take the integral of φ; ``advance`` adds one control period of
        it (call with True once per period while a bias acts).
        """
        if self._velocity_only:
            return self._bias_per_velocity * phi
        if self.pos.any() and advance:
            self.bias_integral += self.dt * np.where(self.pos, phi, 0.0)
        b0 = np.where(self.vel, self.kv * self.gear * phi, 0.0)
        b0 += np.where(self.pos, self.kp * self.gear * self.bias_integral, 0.0)
        b0 += np.where(self.motor, self.k_motor * self.gear * phi, 0.0)
        return b0

    def stop_terms(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(gain, b0, b2) (R, A) of stopped actuators for robots ``rows``: velocity servos
        brake (−kv·L̇), position servos hold where they are, motors brake (−K·L̇)."""
        ids = self.ids[rows]
        length = self.data.actuator_length[ids]
        gain = np.zeros(ids.shape)
        b0 = np.where(self.pos, self.kp * length, 0.0) * np.ones(ids.shape)
        b2 = np.where(self.motor, -self.k_motor, -self.kv) * np.ones(ids.shape)
        return gain, b0, b2
