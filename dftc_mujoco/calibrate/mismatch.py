"""The mismatch ‖ẋ − u‖ of a robot model: the command programme, its measurement, the drive's
lag, the recommended ξ̄ and what the thresholds then detect."""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..sim.robots import TRACKING
from .physics import OffPlane, Trouble, Watch

if TYPE_CHECKING:
    from .drift import Drift

PAPER_XI_BAR = 0.005
CONTROL_PERIOD = 0.01
TIMESTEP = 0.002
STARTUP_QUIET = 0.002  # m/s: the start-up is over once the mismatch stays below this
STARTUP_MAX = 3.0  # s
JUMP_HOLD = 4.0  # s each command jump is held
SETTLED_FOR = 0.2  # s the mismatch must stay low for a response to count as settled
LAG_MIN = 0.05  # s: a faster drive is taken to move at its command (ẋ = u, the paper)
LAG_CANDIDATES = np.geomspace(0.005, 20.0, 121)  # s, the time constants tried


@dataclass(frozen=True)
class Programme:
    """Planar commands (K, 2) at the control rate, and where each jump starts."""

    u: np.ndarray
    jumps: tuple[int, ...]  # sample index of each command jump
    startup: int  # samples of zero command at the start (the start-up window)


def programme(limit: float = 1.0, dt: float = CONTROL_PERIOD) -> Programme:
    """The command programme of the module docstring, within ±``limit`` m/s per axis."""
    cap = 0.8 * min(limit, 1e9)
    speeds = [min(v, cap) for v in (0.1, 0.3, 0.5)]
    parts: list[np.ndarray] = []
    jumps: list[int] = []

    def add(u: np.ndarray, jump: bool = False) -> None:
        if jump:
            jumps.append(sum(len(p) for p in parts))
        parts.append(np.atleast_2d(u))

    def hold(v, seconds, jump=False):
        add(np.tile(v, (round(seconds / dt), 1)), jump)

    def ramp(v0, v1, accel=0.25):
        v0, v1 = np.asarray(v0, float), np.asarray(v1, float)
        k = max(1, round(np.linalg.norm(v1 - v0) / accel / dt))
        add(v0 + np.outer(np.arange(1, k + 1) / k, v1 - v0))

    hold([0.0, 0.0], STARTUP_MAX)
    startup = len(parts[0])
    v0 = speeds[0]
    ramp([0, 0], [v0, 0])
    hold([v0, 0.0], 3.0)
    prev = v0
    for v in speeds[1:]:
        ramp([prev, 0], [v, 0])
        hold([v, 0.0], 2.0 if v < speeds[-1] else 1.0)
        prev = v
    ramp([prev, 0], [v0, 0])
    for radius, speed in ((0.5, speeds[0]), (1.0, speeds[1])):  # turns at v/R
        ramp([v0, 0], [speed, 0])
        k = round(2 * np.pi * radius / speed / dt)
        ang = np.arange(1, k + 1) * dt * speed / radius
        add(speed * np.stack([np.cos(ang), np.sin(ang)], axis=1))
        ramp([speed, 0], [v0, 0])
    k = round(20 / dt)  # figure-eight at up to ~2.5 v0 (each axis within the cap)
    tt = np.arange(1, k + 1) * dt
    w = 2 * np.pi / 20
    fig8 = np.stack([v0 * np.cos(w * tt), min(2 * v0, cap) * np.sin(2 * w * tt)], axis=1)
    add(fig8)
    ramp(fig8[-1], [0, 0])
    step = speeds[1]
    hold([step, 0.0], JUMP_HOLD, jump=True)  # step 0 -> v
    hold([0.0, step], JUMP_HOLD, jump=True)  # 90° switch
    hold([0.0, -step], JUMP_HOLD, jump=True)  # reversal
    hold([0.0, 0.0], JUMP_HOLD, jump=True)  # stop
    return Programme(np.vstack(parts), tuple(jumps), startup)


@dataclass(frozen=True)
class Calibration:
    """What calibrate measured for one model."""

    model: str
    smooth_max: float
    smooth_p99: float
    all_max: float
    all_p99: float
    samples: int
    jump_samples: int
    startup_mismatch: float = 0.0
    startup_time: float = 0.0
    response_time: float = 0.0
    saturation: float = 0.0  # share of commands that the actuators clamped
    command_limit: float = math.inf
    settled: bool = True  # every jump response settled within JUMP_HOLD
    notes: tuple[str, ...] = field(default_factory=tuple)
    compensation_G: float | None = None  # the smallest G (x I) whose loop does not ring
    drift: Drift | None = None  # the drift split in a mission (threshold rules)
    lag: float = 0.0  # τ of the drive lag the robot models (0: none, ẋ = u) [s]
    lag_fit: float = 0.0  # the best-fitting τ, modelled or not [s]
    fast_lag: float = 0.0  # the best τ where the paper's rules take ẋ = u: the drive rule's [s]
    rms_command: float = 0.0  # rms ‖ẋ − u‖ over the programme [m/s]
    rms_lag: float = 0.0  # rms ‖ẋ − v̂‖ with the fitted lag [m/s]
    accel: float = math.inf  # a_max of the nominal input's change (inf: not limited) [m/s²]
    timestep: float = 0.0  # the shorter physics step its drive needs (0: the scene's) [s]
    track: float = 0.0  # a skid steer's effective axle width (0: not measured) [m]
    tracking: float = 1.0  # the share of its smooth commands the robot moves at (tracking())

    @property
    def recommended_xi_bar(self) -> float:
        """ξ̄ that follows: the smooth-command maximum, up to 0.5 mm/s, at least the paper's."""
        return max(PAPER_XI_BAR, math.ceil(self.smooth_max / 0.0005 - 1e-9) * 0.0005)

    def table(self) -> dict[str, float]:
        """What ``--write`` stores (the robot file's ``[calibration]`` keys)."""
        return {
            "xi_bar": self.recommended_xi_bar,
            "mismatch": round(self.smooth_max, 7),
            "startup_mismatch": round(self.startup_mismatch, 6),
            "startup_time": round(self.startup_time, 3),
            "response_time": round(self.response_time, 3),
            "saturation": round(self.saturation, 4),
            **({"lag": round(self.lag, 4)} if self.lag > 0 else {}),
            **({"fast_lag": round(self.fast_lag, 4)} if self.fast_lag > 0 else {}),
            **({"compensation_G": self.compensation_G} if self.compensation_G else {}),
            **({"accel": self.accel} if math.isfinite(self.accel) else {}),
            **({"timestep": self.timestep} if self.timestep else {}),
            **({"track": round(self.track, 4)} if self.track else {}),
            **(
                {"tracking": round(self.tracking, 3)}
                if not TRACKING[0] <= self.tracking <= TRACKING[1]
                else {}
            ),
            **(
                {
                    "drift_bound": round(self.drift.drift_bound, 6),
                    "drift_startup": round(self.drift.startup, 6),
                    "drift_settle": self.drift.settle,
                    **(
                        {"drift_replan": round(self.drift.replan, 6)}
                        if self.drift.replan is not None
                        else {}
                    ),
                }
                if self.drift
                else {}
            ),
        }


def step_for(robot: Any) -> float:
    """The physics step a robot is measured at: the scene's, or its calibrated shorter one."""
    return min(TIMESTEP, robot.timestep)


def robot_with(name: str, measured: dict[str, float] | None = None) -> Any:
    """Robot model ``name`` with what this calibration has measured so far (``measured``:
    its physics step, a skid steer's track) in place of its file's values."""
    from ..sim import robots

    robot = robots.get(name, where="MODEL")
    if not measured:
        return robot
    return dataclasses.replace(robot, calibration={**robot.calibration, **measured})


def measure(name: str, measured: dict[str, float] | None = None) -> Calibration:
    """Drive one robot of model ``name`` through :func:`programme` and measure ‖ẋ − u‖, at
    its physics step (:func:`step_for`, :func:`robot_with`). Raises
    :class:`~.physics.OffPlane` when the robot leaves the plane after its start-up."""
    import mujoco

    from ..sim import scene
    from ..sim.plant import Plant

    robot = robot_with(name, measured)
    step = step_for(robot)
    sc = scene.compose(robot, np.zeros((1, 2)), timestep=step)
    data = Plant.initial_data(sc)
    drive = robot.adapter(sc, data, CONTROL_PERIOD)
    limit = drive.command_limit
    prog = programme(limit)
    nsub = round(CONTROL_PERIOD / step)
    velocity = np.empty((len(prog.u), 2))
    clamped = np.zeros(len(prog.u), bool)
    # the speeds the drive asks of its wheels (not its steering) and those they turn at
    act = drive.actuation  # under a transmission, its columns are the joints, none steered
    spun = ~act.pos if act.moment is None else np.ones(act.dof_adr.shape[1], bool)
    dofs = act.dof_adr[0][spun]
    asked = np.empty((len(prog.u), int(spun.sum())))
    turned = np.empty_like(asked)
    vel = np.empty(6)
    site = int(sc.site[0])
    ids = drive.controlled()[0]
    driven = sc.actuator[0]
    lo, hi = sc.model.actuator_ctrlrange[driven].T
    limited = sc.model.actuator_ctrllimited[driven].astype(bool)
    watch = None
    for k, u in enumerate(prog.u):
        if k == prog.startup:  # settled: from here on it must stay a planar robot
            watch = Watch(sc.model, data, int(sc.body[0]), sc.model.geom("floor").id)
        asked[k] = drive.wheel_speeds(u[None])[0][spun]
        ctrl = drive.command(u[None])[0]
        data.ctrl[ids] = ctrl
        c = ctrl[: len(driven)]
        clamped[k] = bool((limited & ((c <= lo) | (c >= hi))).any())
        mujoco.mj_step(sc.model, data, nstep=nsub)
        mujoco.mj_objectVelocity(sc.model, data, mujoco.mjtObj.mjOBJ_SITE, site, vel, 0)
        velocity[k] = vel[3:5]
        turned[k] = data.qvel[dofs]
        t = (k + 1) * CONTROL_PERIOD
        if data.warning.number.any() or not np.isfinite(data.qvel).all():
            raise OffPlane(Trouble(t, "the physics diverged (MuJoCo's accelerations blew up)"))
        if watch is not None:
            watch.check(t)
            if watch.trouble is not None:
                raise OffPlane(watch.trouble)
    mismatch = np.hypot(*(velocity - prog.u).T)
    tau, rms_lag = fit_lag(prog.u, velocity, prog.startup)
    rms = float(np.sqrt(np.mean(mismatch[prog.startup :] ** 2)))
    lag, fast_lag = lag_choice(tau, rms_lag, rms)
    expected = lag_response(prog.u, tau) if lag > 0 else prog.u  # the drive model's
    if lag > 0:  # measure the rest against the drive model the robot will run
        mismatch = np.hypot(*(velocity - expected).T)
    cal = _analyse(robot.name, prog, mismatch, clamped, limit)
    share = tracking(prog, velocity, expected, limit)
    if not TRACKING[0] <= share <= TRACKING[1]:
        wheels = wheel_share(prog, asked, turned)
        cal = dataclasses.replace(cal, notes=(*cal.notes, _tracking_note(share, wheels)))
    return dataclasses.replace(
        cal,
        tracking=share,
        lag=lag,
        lag_fit=tau,
        fast_lag=fast_lag,
        rms_command=rms,
        rms_lag=rms_lag,
        timestep=step if step < TIMESTEP else 0.0,
        track=float(robot.calibration.get("track", 0.0)),
    )


def tracking(prog: Programme, velocity: np.ndarray, model: np.ndarray, limit: float) -> float:
    """The share of its commands a robot moves at on the smooth part of the programme: the
    least-squares k of ẋ ≈ k v̂ (v̂ the command, or the drive model's response to it) over
    the samples whose v̂ is at least a fifth of the command range. 1 for a drive that moves
    as the drive model assumes; a steady shortfall is no lag and no ξ̄ describes it."""
    smooth = slice(prog.startup, prog.jumps[0])
    v, m = velocity[smooth], model[smooth]
    big = np.hypot(*m.T) >= 0.2 * min(limit, 1.0)
    if not big.any():
        return 1.0
    return float(np.sum(v[big] * m[big]) / np.sum(m[big] * m[big]))


def wheel_share(prog: Programme, asked: np.ndarray, turned: np.ndarray) -> float:
    """The share of the speeds the drive asked of its wheels that they turned at, on the
    smooth part of the programme: the least-squares k of q̇ ≈ k q̇* over the samples whose
    asked speed is at least a fifth of the largest (each wheel a column of ``asked`` and
    ``turned``). 1 where the servos deliver what the drive asks."""
    smooth = slice(prog.startup, prog.jumps[0])
    a, q = asked[smooth].ravel(), turned[smooth].ravel()
    big = np.abs(a) >= 0.2 * np.abs(a).max() if a.size and np.abs(a).max() > 0 else None
    if big is None or not big.any():
        return 1.0
    return float(np.sum(q[big] * a[big]) / np.sum(a[big] * a[big]))


def _tracking_note(share: float, wheels: float) -> str:
    """The warning for a robot that moves at a steady share of its commands, with what its
    wheels did: turned as asked (the base slips, sinks or bumps over them, or the drive
    model's geometry is not the wheels'), or not (the servos cannot carry their load)."""
    said = (
        f"on smooth commands the robot moves at {share:.0%} of its command, steadily (no lag "
        "and no ξ̄ describes that)"
    )
    if TRACKING[0] <= wheels <= TRACKING[1]:
        return (
            f"{said}, while its wheels turn at {wheels:.0%} of the speeds its drive asks for: "
            "the servos deliver, but the wheels do not move the base as the drive model "
            "assumes. Check the wheels' radius and axle (the robot file's or the model's "
            "geometry), and how they touch the floor: wheels that sink into it under the "
            "robot's weight (soft contacts: solref, solimp), slip, or roll on a few thin "
            "rollers with gaps between them"
        )
    return (
        f"{said}: its wheels turn at only {wheels:.0%} of the speeds its drive asks for, so "
        "its servos cannot carry the load; check their gains (kv, kp), force range and "
        "control range, and friction loss or damping on its passive joints (rollers, "
        "casters)"
    )


def lag_response(u: np.ndarray, tau: float, dt: float = CONTROL_PERIOD) -> np.ndarray:
    """Velocity (K, 2) at the end of each period of a first-order lag ``tau`` from rest,
    its command ``u`` (K, 2) held over each period (the model of ``onboard/applied.py``)."""
    from scipy.signal import lfilter

    from ..onboard.applied import lag_coefficients

    a, _ = lag_coefficients(tau, dt)
    if a == 0.0:
        return np.array(u, dtype=float)
    return lfilter([a], [1.0, a - 1.0], u, axis=0)


def at_search_edge(tau: float) -> bool:
    """Whether a fitted τ is the longest lag tried: no lag in the search range fits."""
    return tau >= 0.99 * LAG_CANDIDATES[-1]


def lag_choice(tau: float, rms_lag: float, rms: float) -> tuple[float, float]:
    """(lag, fast_lag) stored for a best-fitting ``tau`` whose rms mismatch is ``rms_lag``
    against ``rms`` without a lag: ``lag`` where τ ≥ :data:`LAG_MIN` halves the mismatch,
    ``fast_lag`` where it only lowers it; neither at the edge of the search."""
    if at_search_edge(tau):
        return 0.0, 0.0
    if tau >= LAG_MIN and rms_lag < 0.5 * rms:
        return tau, 0.0
    return 0.0, (tau if rms_lag < rms else 0.0)


def fit_lag(u: np.ndarray, v: np.ndarray, skip: int = 0) -> tuple[float, float]:
    """The τ of :data:`LAG_CANDIDATES` whose :func:`lag_response` to ``u`` fits the measured
    velocities ``v`` best (rms of ‖v − v̂‖ from sample ``skip`` on); returns (τ, that rms)."""
    from scipy.optimize import minimize_scalar

    def rms(log_tau: float) -> float:
        err = v[skip:] - lag_response(u, float(np.exp(log_tau)))[skip:]
        return float(np.sqrt(np.mean(np.einsum("kd,kd->k", err, err))))

    logs = np.log(LAG_CANDIDATES)
    i = int(np.argmin([rms(x) for x in logs]))
    lo, hi = logs[max(i - 1, 0)], logs[min(i + 1, len(logs) - 1)]
    best = minimize_scalar(rms, bounds=(lo, hi), method="bounded", options={"xatol": 1e-4})
    tau = round(float(np.exp(best.x)), 4)
    return tau, rms(float(np.log(tau)))


def _analyse(
    name: str, prog: Programme, mismatch: np.ndarray, clamped: np.ndarray, limit: float
) -> Calibration:
    """Split the samples into start-up, smooth and jump-affected ones (module docstring)."""
    dt = CONTROL_PERIOD
    quiet = round(0.5 / dt)
    start = prog.startup  # the start-up ends once the mismatch stays low for 0.5 s
    low = mismatch[: prog.startup] < STARTUP_QUIET
    for k in range(prog.startup - quiet + 1):
        if low[k : k + quiet].all():
            start = k
            break
    end_jumps = len(prog.u)
    smooth_mask = np.zeros(len(prog.u), bool)
    smooth_mask[prog.startup : prog.jumps[0]] = True
    smooth = mismatch[smooth_mask]
    level = max(float(smooth.max()), STARTUP_QUIET)  # "back to smooth"
    jump = np.zeros(len(prog.u), bool)
    response, settled = 0.0, True
    need = round(SETTLED_FOR / dt)
    bounds = [*prog.jumps, end_jumps]
    for a, b in itertools.pairwise(bounds):
        ok = mismatch[a:b] <= level
        done = next((k for k in range(b - a - need + 1) if ok[k : k + need].all()), None)
        if done is None:
            settled = False
            done = b - a
        jump[a : a + done] = True
        response = max(response, done * dt)
    smooth_mask[prog.jumps[0] :] = ~jump[prog.jumps[0] :]
    smooth = mismatch[smooth_mask]
    measured = np.concatenate([mismatch[start : prog.startup], mismatch[prog.startup :]])
    notes = []
    if clamped[smooth_mask].any():
        notes.append(
            f"the actuators clamped {clamped[smooth_mask].mean():.1%} of the smooth commands "
            f"(command range ±{limit:.3g} m/s per axis): those samples measure saturation, "
            "not the robot"
        )
    if start == prog.startup:
        notes.append(
            f"the robot did not settle within {STARTUP_MAX:g} s of its start: its mismatch "
            f"stayed above {STARTUP_QUIET * 1000:g} mm/s under a zero command"
        )
    if not settled:
        notes.append(
            f"a command jump did not settle within {JUMP_HOLD:g} s: the robot's response is "
            "slower than the programme allows"
        )
    return Calibration(
        name,
        float(smooth.max()),
        float(np.percentile(smooth, 99)),
        float(measured.max()),
        float(np.percentile(measured, 99)),
        len(measured),
        int(jump.sum()),
        startup_mismatch=float(mismatch[:start].max()) if start else 0.0,
        startup_time=start * dt,
        response_time=response,
        saturation=float(clamped.mean()),
        command_limit=limit,
        settled=settled,
        notes=tuple(notes),
    )


def detectability(
    cal: Calibration, scenario_name: str, robot: str, overrides: dict | None = None
) -> tuple[str, bool]:
    """What the recommended ξ̄ implies for the scenario's thresholds: the smallest constant
    fault they can detect, and whether faults of the mission's size are below it.

    A constant fault φ on robot k moves every residual block towards φ/k_o (docs/notes.md, 8), so
    no robot can flag it unless ‖φ‖ > k_o ⁱμ_k; eq. 46 guarantees the detection above
    twice that. The mission's largest fault is its largest bias, or for a stop the
    robot's command range (a stopped robot's command grows as the team pulls away).
    Returns (the line to print, whether it is a warning).
    """
    from ..blocks import create
    from ..closed_loop.assembly import team_config, threshold_rule
    from ..scenario import load_scenario
    from ..sim import robots

    s = load_scenario(scenario_name, {**(overrides or {}), "noise.xi_bar": cal.recommended_xi_bar})
    model = robots.get(robot, where="MODEL")
    # the robot as it will run: with the lag this calibration measured (the rule "auto"
    # chooses depends on it)
    model = dataclasses.replace(
        model, calibration={**model.calibration, "lag": cal.lag, "fast_lag": cal.fast_lag}
    )
    s = threshold_rule(s, model)
    config = team_config(s, model, cal.command_limit)
    th = create("thresholds", s.onboard.thresholds, s.onboard.params.get("thresholds", {}))
    x0 = np.asarray(s.team.initial_positions)
    th.reset(config, x0, x0)
    mu = np.asarray(th.mu(1e9), float)
    finite = mu[np.isfinite(mu)]
    least = float(finite.min()) if len(finite) else math.inf
    smallest = s.gains.ko * least  # the most sensitive robot's limit
    faults = [float(np.linalg.norm(f.value)) for f in s.faults if f.kind == "bias"]
    if any(f.kind == "stop" for f in s.faults) or not faults:
        faults.append(math.sqrt(2) * min(cal.command_limit, 1e9))
    largest = max(faults)
    line = (
        f"with xi_bar = {cal.recommended_xi_bar:g} m/s, {s.name}'s thresholds "
        f"({s.onboard.thresholds}) let a robot detect a constant fault only above "
        f"{smallest:.3g} m/s (k_o min μ, docs/notes.md, 8; eq. 46 guarantees it above twice that)"
    )
    if smallest < largest:
        return line + f"; the mission's faults reach {largest:.3g} m/s", False
    return (
        line + f", but the mission's largest fault is {largest:.3g} m/s: faults of the "
        "mission's size are undetectable; reduce the robot's mismatch (stiffer actuators, a "
        "control point with less lag) or use a tighter threshold rule",
        True,
    )


def report(cal: Calibration) -> str:
    """The table printed by the command."""
    mm = 1000.0
    lines = [
        f"model {cal.model}: ‖ẋ − u‖ of the controlled point over {cal.samples} commands at "
        f"{1 / CONTROL_PERIOD:g} Hz within ±{cal.command_limit:.3g} m/s per axis "
        f"({cal.jump_samples} while responding to a jump)",
        f"start-up: {cal.startup_time:.2f} s to settle, mismatch up to "
        f"{cal.startup_mismatch * mm:.2f} mm/s (not counted below)",
        f"{'':24}{'max':>10}{'99th pct':>10}   [mm/s]",
        f"{'smooth commands':24}{cal.smooth_max * mm:10.2f}{cal.smooth_p99 * mm:10.2f}",
        f"{'with command jumps':24}{cal.all_max * mm:10.2f}{cal.all_p99 * mm:10.2f}",
        f"response to a jump: {cal.response_time:.2f} s; actuators clamped "
        f"{cal.saturation:.1%} of the commands",
        f"recommended xi_bar: {cal.recommended_xi_bar:g} m/s "
        f"(smooth maximum rounded up, at least the paper's {PAPER_XI_BAR:g})",
    ]
    fit = (
        f"drive lag: a first-order lag of {cal.lag_fit:.3g} s fits best (rms mismatch "
        f"{cal.rms_command * mm:.2f} mm/s against the command, {cal.rms_lag * mm:.2f} mm/s "
        "against the lag)"
    )
    if at_search_edge(cal.lag_fit):
        lines.append(
            f"WARNING: drive lag: the best fit is {cal.lag_fit:.3g} s, the longest lag tried "
            f"(the edge of the search, {LAG_CANDIDATES[0]:g}-{LAG_CANDIDATES[-1]:g} s): no "
            "first-order lag describes this drive (rms mismatch "
            f"{cal.rms_command * mm:.2f} mm/s against the command, {cal.rms_lag * mm:.2f} "
            "mm/s against that lag); none is stored"
        )
    elif cal.lag > 0:
        lines.insert(
            1,
            fit + ": the robot models it (lag), and every mismatch below is ‖ẋ − v̂‖ against "
            "that model",
        )
    else:
        lines.append(
            fit + f"; below {LAG_MIN:g} s or not halving the mismatch, the paper's rules take "
            "ẋ = u" + ("; the drive rule models it (fast_lag)" if cal.fast_lag > 0 else "")
        )
    lines += [f"WARNING: {n}" for n in cal.notes]
    return "\n".join(lines)
