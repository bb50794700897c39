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

An actuator may also move its joints through a **fixed tendon** (``forward = ½ q_L + ½
q_R``, ``turn = −½ q_L + ½ q_R``): its length is then L = Σ c_j q_j (the tendon's
coefficients times its gear), and the drive's joints are mapped to the actuators through
that **transmission** matrix M (actuators × joints): L̇* = M v for joint velocities v.
The kinds above then act on L (a torque motor's loop gain K = I_a/τ takes the inertia a
tendon sees, I_a = 1/Σ_j c_j²/I_j, which for a joint is I/gear²).

The **joints' own losses** are part of what an actuator has to overcome: a joint's damping d
and friction loss f take d·v + f·sign(v) of its torque at velocity v, so the command adds
the actuator force that delivers it (Mᵀ F = d·v + f·sign(v), ctrl += F/gain), as the gear
is read: a weak velocity servo against a damped wheel (kv 1 against d = 2) otherwise
delivers a third of the speed asked for. Damping below :data:`LOSS_SHARE` of the servo's
own is left as it is, and so are a position servo's losses (it holds its target however
the joint resists, and its target may jump: a steering module's turn).

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
#: [joint units / s] below this speed a joint's friction loss is compensated in proportion
FRICTION_SPEED = 0.01
#: a joint's damping below this share of its servo's own (kv·gear²) costs it less than that
#: share of its speed: left uncompensated (the built-in diffdrive's wheels: 0.06 %)
LOSS_SHARE = 0.01

_AFFINE = int(mujoco.mjtBias.mjBIAS_AFFINE)
_NONE_BIAS = int(mujoco.mjtBias.mjBIAS_NONE)
_FIXED_GAIN = int(mujoco.mjtGain.mjGAIN_FIXED)
_JOINT_TRN = (int(mujoco.mjtTrn.mjTRN_JOINT), int(mujoco.mjtTrn.mjTRN_JOINTINPARENT))
_TENDON_TRN = int(mujoco.mjtTrn.mjTRN_TENDON)
_WRAP_JOINT = int(mujoco.mjtWrap.mjWRAP_JOINT)
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
    # L = Σ c q: (joint id in the robot's own model, c) of each joint it moves (gear included)
    moment: tuple[tuple[int, float], ...] = ()
    tendon: str = ""  # the fixed tendon it pulls ("" for a joint transmission)
    damping: float = 0.0  # of its joint (a tendon: the most of its joints'): losses it overcomes
    frictionloss: float = 0.0
    # the range its (first) joint is limited to, (-inf, inf) when it is not
    joint_range: tuple[float, float] = (-np.inf, np.inf)

    @property
    def velocity_limit(self) -> float:
        """Largest joint velocity the ctrl range lets the actuator hold (inf otherwise): a
        velocity servo's, after the joint's own damping and friction loss take their share;
        a torque motor's against that damping (its full force spent on it). A tendon's for
        every joint it moves at once (a motor: each joint's least share of its force)."""
        if self.kind == POSITION or self.ctrlrange is None:
            return np.inf
        lo, hi = self.ctrlrange
        reach = min(abs(lo), abs(hi)) * self.gain
        if self.kind == MOTOR:  # L̇ where the damping takes all the force: d v = reach·c
            least = min(abs(c) for _, c in self.moment)
            return (reach * least - self.frictionloss) / self.damping if self.damping else np.inf
        if self.tendon:
            return reach / (self.kv * sum(abs(c) for _, c in self.moment))
        g = abs(self.gear)
        damping = self.damping if self.damping >= LOSS_SHARE * self.kv * g * g else 0.0
        return max(reach - self.frictionloss / g, 0.0) / (self.kv * g + damping / g)

    @property
    def what(self) -> str:
        """What it moves, for messages: its joint, or its tendon."""
        return f"tendon {self.tendon!r}" if self.tendon else repr(self.joint)


def classify(model: mujoco.MjModel, a: int) -> ActuatorInfo | str:
    """What actuator ``a`` of ``model`` is, or a sentence saying why it cannot be driven."""
    gear = float(model.actuator_gear[a, 0])
    trn = int(model.actuator_trntype[a])
    tendon = ""
    if trn == _TENDON_TRN:
        moment = _tendon_moment(model, int(model.actuator_trnid[a, 0]), gear)
        if isinstance(moment, str):
            return moment
        tendon = model.tendon(int(model.actuator_trnid[a, 0])).name or "unnamed"
    elif trn in _JOINT_TRN:
        moment = ((int(model.actuator_trnid[a, 0]), gear),)
    else:
        return "drives no joint (a site or body transmission); expected a joint or tendon actuator"
    j = moment[0][0]
    jtype = int(model.jnt_type[j])
    if any(int(model.jnt_type[k]) not in (_SLIDE, _HINGE) for k, _ in moment):
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
        moment=moment,
        tendon=tendon,
        damping=max(float(model.dof_damping[model.jnt_dofadr[k]]) for k, _ in moment),
        frictionloss=max(float(model.dof_frictionloss[model.jnt_dofadr[k]]) for k, _ in moment),
        joint_range=(
            (float(model.jnt_range[j, 0]), float(model.jnt_range[j, 1]))
            if model.jnt_limited[j]
            else (-np.inf, np.inf)
        ),
    )


def _tendon_moment(
    model: mujoco.MjModel, t: int, gear: float
) -> tuple[tuple[int, float], ...] | str:
    """(joint, coefficient × gear) of fixed tendon ``t``, or why it cannot drive joints."""
    start, count = int(model.tendon_adr[t]), int(model.tendon_num[t])
    wraps = range(start, start + count)
    if count == 0 or any(int(model.wrap_type[w]) != _WRAP_JOINT for w in wraps):
        return "pulls a spatial tendon (sites, geoms or pulleys); expected a fixed tendon of joints"
    return tuple(
        (int(model.wrap_objid[w]), float(model.wrap_prm[w]) * gear)
        for w in range(start, start + count)
    )


def motor_gain(info: ActuatorInfo, time_constant: float) -> float:
    """K of a torque motor's inner velocity loop: its length L settles with ``time_constant``
    (``info.inertia`` is the inertia L sees: I/gear² for a joint)."""
    return info.inertia / time_constant


def seen_inertia(full: np.ndarray, dofs: list[int], coefs: list[float]) -> float:
    """The inertia an actuator of length L = Σ c_j q_j sees, 1/Σ c_j²/I_j, from the diagonal
    of the joint-space inertia ``full`` (armature included): I/gear² for one joint."""
    return 1.0 / sum(c * c / full[d, d] for d, c in zip(dofs, coefs, strict=True))


class Actuation:
    """Actuator commands and fault parameters of a team's driven actuators.

    ``ids`` (N, A) are the actuator ids in the scene, one column per driven role, and
    ``infos`` (A,) what each column is. ``dt`` is the control period (position servos
    integrate over it). The drive asks for velocities of its joints (N, J): by default
    each actuator's own joint (J = A, in column order); with ``joints`` (N, J) scene joint
    ids and ``moment`` (A, J) the transmission matrix, L̇* = M v (tendons). Position targets
    start at the joints' positions in ``data`` (the robots' initial pose) when
    :meth:`reset` is called.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        ids: np.ndarray,
        infos: tuple[ActuatorInfo, ...],
        dt: float,
        motor_time_constant: float = MOTOR_TIME_CONSTANT,
        joints: np.ndarray | None = None,
        moment: np.ndarray | None = None,
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
        self.moment = None if moment is None else np.asarray(moment, float)  # None: diagonal
        if joints is None:
            joints = model.actuator_trnid[ids, 0]
        self.qpos_adr = model.jnt_qposadr[joints]
        self.dof_adr = model.jnt_dofadr[joints]
        # ctrl per unit of joint velocity (velocity servos) or joint position (position servos)
        self.per_velocity = np.where(self.vel, self.kv * self.gear / self.gain, 0.0)
        self.per_position = np.where(self.pos, self.kp * self.gear / self.gain, 0.0)
        self.target = np.zeros(self.qpos_adr.shape)  # position servos' targets [joint units]
        self.bias_integral = np.zeros(self.qpos_adr.shape)  # ∫φ for position servos' bias
        self._out = np.zeros(ids.shape)
        self._velocity_only = bool(self.vel.all()) and self.moment is None
        self._bias_per_velocity = self.kv * self.gear
        # the joints' own losses, overcome by the command (module docstring)
        dofs = self.dof_adr[0] if len(self.dof_adr) else np.zeros(0, dtype=int)
        self.damping = model.dof_damping[dofs].copy()
        self.frictionloss = model.dof_frictionloss[dofs].copy()
        if self.moment is None:  # damping below LOSS_SHARE of the servo's own is left as is
            own = np.where(self.motor, self.k_motor, self.kv) * self.gear**2
            self.damping[(self.damping < LOSS_SHARE * own) | self.pos] = 0.0
            self.frictionloss[self.pos] = 0.0  # a position servo's target absorbs its losses
        self._lossy = bool((self.damping > 0).any() or (self.frictionloss > 0).any())
        if self.moment is None:  # F = τ/gear
            self._loss = np.diag(1.0 / (self.gear * self.gain)) if len(infos) else np.zeros((0, 0))
        else:  # Mᵀ F = τ: F = τ M⁺ (a square transmission: exactly)
            self._loss = np.linalg.pinv(self.moment) / self.gain[None, :]
        if self.motor.any():  # make the bias term usable (affine with zero coefficients)
            m = ids[:, self.motor]
            model.actuator_biastype[m] = _AFFINE
        self.reset()

    @property
    def any_position(self) -> bool:
        return bool(self.pos.any())

    @property
    def velocity_only(self) -> bool:
        """Every actuator a velocity servo on its own joint: b0 = kv·gear·φ (:meth:`bias_terms`)."""
        return self._velocity_only

    @property
    def bias_per_velocity(self) -> np.ndarray:
        """(A,) kv·gear per column: b0 per unit of joint velocity offset (velocity servos)."""
        return self._bias_per_velocity

    @property
    def plain(self) -> bool:
        """Every actuator a velocity servo on its own joint whose ctrl is the joint velocity
        itself, with no joint losses to overcome: ctrl = v."""
        return self._velocity_only and not self._lossy and bool((self.per_velocity == 1.0).all())

    def reset(self) -> None:
        """Position targets at the joints' current positions; no integrated bias."""
        self.target[:] = self.data.qpos[self.qpos_adr]
        self.bias_integral[:] = 0.0

    def _lengths(self, x: np.ndarray) -> np.ndarray:
        """Joint quantities (N, J) as the actuators' lengths (N, A): L = M x."""
        return x * self.gear if self.moment is None else x @ self.moment.T

    def losses(self, v: np.ndarray) -> np.ndarray:
        """The commands (N, A) whose force overcomes the joints' damping and friction loss at
        joint velocities ``v`` (N, J) (module docstring)."""
        sign = np.clip(v / FRICTION_SPEED, -1.0, 1.0)
        return (self.damping * v + self.frictionloss * sign) @ self._loss

    def command(self, v: np.ndarray) -> np.ndarray:
        """Actuator commands (N, A) for joint velocities ``v`` (N, J) held over one period."""
        out = self._out
        if self._velocity_only:
            np.multiply(v, self.per_velocity, out=out)
            if self._lossy:
                out += self.losses(v)
            return out
        rate = self._lengths(v)
        if self.moment is None:
            np.multiply(v, self.per_velocity, out=out)
        else:
            np.multiply(rate, np.where(self.vel, self.kv / self.gain, 0.0), out=out)
        if self.pos.any():
            self.target += self.dt * v
            if self.moment is None:
                out += self.target * self.per_position
            else:
                out += self._lengths(self.target) * np.where(self.pos, self.kp / self.gain, 0.0)
        if self.motor.any():
            moving = self._lengths(self.data.qvel[self.dof_adr])
            out += np.where(self.motor, self.k_motor * (rate - moving) / self.gain, 0.0)
        if self._lossy:
            out += self.losses(v)
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
        """b0 (N, A) that shifts each joint's velocity by ``phi`` (N, J) [joint units / s].

        Position servos take the integral of φ; ``advance`` adds one control period of
        it (call with True once per period while a bias acts).
        """
        if self._velocity_only:
            return self._bias_per_velocity * phi
        if self.pos.any() and advance:
            self.bias_integral += self.dt * phi
        rate = self._lengths(phi)
        b0 = np.where(self.vel, self.kv * rate, 0.0)
        b0 += np.where(self.pos, self.kp * self._lengths(self.bias_integral), 0.0)
        b0 += np.where(self.motor, self.k_motor * rate, 0.0)
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
