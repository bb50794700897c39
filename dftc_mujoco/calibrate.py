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

import dataclasses
import itertools
import math
import os
import sys
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import write_text
from .errors import EXIT_INPUT, EXIT_OK, EXIT_OUTPUT, ScenarioError

PAPER_XI_BAR = 0.005
CONTROL_PERIOD = 0.01
TIMESTEP = 0.002
STARTUP_QUIET = 0.002  # m/s: the start-up is over once the mismatch stays below this
STARTUP_MAX = 3.0  # s
JUMP_HOLD = 4.0  # s each command jump is held
SETTLED_FOR = 0.2  # s the mismatch must stay low for a response to count as settled
LAG_MIN = 0.05  # s: a faster drive is taken to move at its command (ẋ = u, the paper)
LAG_CANDIDATES = np.geomspace(0.005, 20.0, 121)  # s, the time constants tried
REPLAN_WINDOW = 5.0  # s after an exclusion that count as the re-plan's transient


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
    k = round(20 / dt)  # figure-eight at up to ~2.5 v0
    tt = np.arange(1, k + 1) * dt
    w = 2 * np.pi / 20
    fig8 = np.stack([v0 * np.cos(w * tt), 2 * v0 * np.sin(2 * w * tt)], axis=1)
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
    rms_command: float = 0.0  # rms ‖ẋ − u‖ over the programme [m/s]
    rms_lag: float = 0.0  # rms ‖ẋ − v̂‖ with the fitted lag [m/s]
    accel: float = math.inf  # a_max of the nominal input's change (inf: not limited) [m/s²]

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
            **({"compensation_G": self.compensation_G} if self.compensation_G else {}),
            **({"accel": self.accel} if math.isfinite(self.accel) else {}),
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


def measure(name: str) -> Calibration:
    """Drive one robot of model ``name`` through :func:`programme` and measure ‖ẋ − u‖."""
    import mujoco

    from .sim import robots, scene
    from .sim.plant import Plant

    robot = robots.get(name, where="MODEL")
    sc = scene.compose(robot, np.zeros((1, 2)), timestep=TIMESTEP)
    data = Plant.initial_data(sc)
    drive = robot.adapter(sc, data, CONTROL_PERIOD)
    limit = drive.command_limit
    prog = programme(limit)
    nsub = round(CONTROL_PERIOD / TIMESTEP)
    velocity = np.empty((len(prog.u), 2))
    clamped = np.zeros(len(prog.u), bool)
    vel = np.empty(6)
    site = int(sc.site[0])
    ids = drive.controlled()[0]
    driven = sc.actuator[0]
    lo, hi = sc.model.actuator_ctrlrange[driven].T
    limited = sc.model.actuator_ctrllimited[driven].astype(bool)
    for k, u in enumerate(prog.u):
        ctrl = drive.command(u[None])[0]
        data.ctrl[ids] = ctrl
        c = ctrl[: len(driven)]
        clamped[k] = bool((limited & ((c <= lo) | (c >= hi))).any())
        mujoco.mj_step(sc.model, data, nstep=nsub)
        mujoco.mj_objectVelocity(sc.model, data, mujoco.mjtObj.mjOBJ_SITE, site, vel, 0)
        velocity[k] = vel[3:5]
        if data.warning.number.any() or not np.isfinite(data.qvel).all():
            raise ScenarioError(
                f"{robot.path}: the physics failed during calibration at t = {data.time:.2f} s"
            )
    mismatch = np.hypot(*(velocity - prog.u).T)
    tau, rms_lag = fit_lag(prog.u, velocity, prog.startup)
    rms = float(np.sqrt(np.mean(mismatch[prog.startup :] ** 2)))
    modelled = tau >= LAG_MIN and rms_lag < 0.5 * rms
    if modelled:  # measure the rest against the drive model the robot will run
        mismatch = np.hypot(*(velocity - lag_response(prog.u, tau)).T)
    cal = _analyse(robot.name, prog, mismatch, clamped, limit)
    return dataclasses.replace(
        cal,
        lag=tau if modelled else 0.0,
        lag_fit=tau,
        rms_command=rms,
        rms_lag=rms_lag,
    )


def lag_response(u: np.ndarray, tau: float, dt: float = CONTROL_PERIOD) -> np.ndarray:
    """Velocity (K, 2) at the end of each period of a first-order lag ``tau`` from rest,
    its command ``u`` (K, 2) held over each period (the model of ``onboard/applied.py``)."""
    from scipy.signal import lfilter

    from .onboard.applied import lag_coefficients

    a, _ = lag_coefficients(tau, dt)
    if a == 0.0:
        return np.array(u, dtype=float)
    return lfilter([a], [1.0, a - 1.0], u, axis=0)


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
    from .assembly import team_config
    from .blocks import create
    from .scenario import load_scenario
    from .sim import robots

    s = load_scenario(scenario_name, {**(overrides or {}), "noise.xi_bar": cal.recommended_xi_bar})
    config = team_config(s, robots.get(robot, where="MODEL"), cal.command_limit)
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


@dataclass(frozen=True)
class Compensation:
    """How the fault estimator's compensation loop (eqs. 28-31) behaves on the robot."""

    G: float  # the gain tried (G = g I)
    phi_p99: float  # healthy ‖φ̂‖ on the robot, 99th percentile [m/s]
    phi_max: float
    ideal: float  # the bound Φ̄ of an ideal plant with the same gains (thresholds.estimator_gain)

    @property
    def rings(self) -> bool:
        """The loop amplifies the robot's lag: healthy ‖φ̂‖ beyond 1.5 Φ̄ of an ideal plant."""
        return self.phi_p99 > 1.5 * self.ideal

    @property
    def runs_away(self) -> bool:
        """On jumping commands (:func:`acceleration`): healthy ‖φ̂‖ beyond 2 Φ̄ of an ideal
        plant at its 99th percentile. Unlimited, the diffdrive's loop runs away (53 Φ̄; 4.5
        Φ̄ at 4 m/s², 1.7 Φ̄ at 2 m/s²), and the disk's and the hexbot's jump transients
        (2.2 Φ̄, 2.1 Φ̄; 1.4 Φ̄ at 8 m/s²) put φ̂ beyond Φ̄ whenever avoidance in a crowd
        flips a command by twice the speed: a healthy hexbot was excluded on that."""
        return self.phi_p99 > 2.0 * self.ideal


G_CANDIDATES = (1.0, 1.5, 2.0, 3.0, 5.0, 10.0)  # multiples of the scenario's G tried


def compensation(
    name: str,
    scenario_name: str = "paper_case",
    seconds: float = 25.0,
    seed: int = 0,
    overrides: dict | None = None,
    lag: float = 0.0,
) -> list[Compensation]:
    """Run the paper's fault estimator in closed loop on one robot (smooth commands, η at
    its bound) for the scenario's G (after ``overrides``) and larger ones, until the loop
    no longer rings.

    With a per-period gain h/G = 1 (the paper's G = 0.01 at h = 0.01 s) the loop is
    deadbeat on an integrator and marginal on any robot with lag: healthy ‖φ̂‖ then
    grows far beyond its ideal-plant bound and feeds the robot's commands. With ``lag`` the
    robot models its drive as the team will (``onboard/applied.py``): the estimator is
    driven by the modelled velocity, the drive by the command.
    """
    from .assembly import PAPER_G
    from .onboard.thresholds import estimator_gain
    from .scenario import load_scenario
    from .sim import robots, scene
    from .sim.plant import Plant

    s = load_scenario(scenario_name, overrides)
    robot = robots.get(name, where="MODEL")
    sc = scene.compose(robot, np.zeros((1, 2)), timestep=TIMESTEP)
    K = np.ascontiguousarray(s.gains.K, float)

    # the search starts from the scenario's G, or the paper's where it says "auto"
    g0 = PAPER_G if s.gains.G is None else float(np.asarray(s.gains.G)[0, 0])
    eta_bar = s.noise.eta_bar
    out = []
    for factor in G_CANDIDATES:
        g = g0 * factor
        data = Plant.initial_data(sc)
        drive = robot.adapter(sc, data, CONTROL_PERIOD)
        prog = programme(drive.command_limit)
        steps = min(len(prog.u) - prog.startup, round(seconds / CONTROL_PERIOD))
        u_all = prog.u[prog.startup : prog.startup + steps]
        norms = closed_loop(sc, data, drive, u_all, K, g, eta_bar, lag, seed=seed)
        settled = norms[round(1.0 / CONTROL_PERIOD) :]  # after the first second
        ideal = estimator_gain(K, g * np.eye(2), CONTROL_PERIOD, eta_bar, 0.0, lag=lag)
        result = Compensation(g, float(np.percentile(settled, 99)), float(settled.max()), ideal)
        out.append(result)
        if not result.rings:
            break
    return out


def closed_loop(
    sc: Any,
    data: Any,
    drive: Any,
    u_all: np.ndarray,
    K: np.ndarray,
    g: float,
    eta_bar: float,
    lag: float = 0.0,
    accel: float = math.inf,
    seed: int = 0,
) -> np.ndarray:
    """One robot driven by the nominal commands ``u_all`` (steps, 2) with the paper's fault
    estimator and compensation (eqs. 28-31) at G = ``g`` I in the loop, η at its bound; the
    drive modelled as the team will (``lag``; ``accel``: the nominal input's change held to
    a_max h per period, ``onboard/applied.py``). Returns ‖φ̂‖ of every period."""
    import mujoco

    from .onboard.applied import lag_coefficients, lag_input, limit_input
    from .onboard.fault_estimator import estimate_faults

    steps = len(u_all)
    nsub = round(CONTROL_PERIOD / TIMESTEP)
    rng = np.random.default_rng(seed)
    ang = rng.uniform(0, 2 * np.pi, steps)
    eta = eta_bar * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    site = int(sc.site[0])
    x_m = data.site_xpos[site][:2][None] + eta[:1]
    z, int_e = x_m.copy(), np.zeros((1, 2))
    phi, applied, u_bar = np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 2))
    free = np.zeros(1, bool)  # no contact holds the estimator here
    g_inv = np.eye(2) / g
    ids = drive.controlled()[0]
    norms = np.empty(steps)
    lag_a, lag_b = lag_coefficients(lag, CONTROL_PERIOD)
    v_hat, command = np.zeros((1, 2)), np.zeros((1, 2))
    rows, scratch = np.zeros(1, np.int64), np.zeros((1, 2))
    step = accel * CONTROL_PERIOD
    for k in range(steps):
        x_m = data.site_xpos[site][:2][None] + eta[k]
        u = u_all[k][None].copy()
        limit_input(u, scratch, scratch.copy(), math.inf, command, rows, step)
        if lag_a > 0.0:
            lag_input(u, v_hat, command, lag_a, lag_b)  # u: the modelled velocity
        else:
            command[:] = u
        estimate_faults(
            x_m,
            u,
            z,
            int_e,
            phi,
            applied,
            K,
            g_inv,
            CONTROL_PERIOD,
            drive.command_limit,
            1.0,
            free,
            u_bar,
        )
        norms[k] = np.linalg.norm(phi)
        data.ctrl[ids] = drive.command(command - applied)[0]  # ū (eq. 28)
        mujoco.mj_step(sc.model, data, nstep=nsub)
    return norms


ACCEL_CANDIDATES = (math.inf, 16.0, 8.0, 4.0, 2.0, 1.0, 0.5)  # a_max tried [m/s²], fastest first


def turns(limit: float, dt: float = CONTROL_PERIOD, hold: float = 2.0) -> np.ndarray:
    """Nominal commands that jump between velocities at 0.8 of the range: start, 90°
    switches, reversals, stops (what an avoidance switch or a far start asks of a drive)."""
    v = 0.8 * min(limit, 1e9) / math.sqrt(2)
    targets = [(v, 0), (0, v), (0, -v), (-v, -v), (v, v), (0, 0), (-v, 0), (v, -v), (0, 0)]
    k = round(hold / dt)
    return np.vstack([np.tile(np.asarray(t, float), (k, 1)) for t in targets])


def acceleration(
    name: str, G: float, lag: float = 0.0, eta_bar: float = 0.001, seed: int = 0
) -> list[tuple[float, Compensation]]:
    """The compensation loop at G on commands that jump (:func:`turns`), with the nominal
    input's change held to a_max per second for each of ``ACCEL_CANDIDATES`` until the loop
    no longer rings: a drive that cannot follow a jump (a differential drive swinging its
    offset point round) reads the jump as a fault, the compensation adds it to the command
    and the loop runs away (healthy ‖φ̂‖ 4.6 m/s measured on the diffdrive in a crowd)."""
    from .onboard.thresholds import estimator_gain
    from .sim import robots, scene
    from .sim.plant import Plant

    robot = robots.get(name, where="MODEL")
    sc = scene.compose(robot, np.zeros((1, 2)), timestep=TIMESTEP)
    K = 3.0 * np.eye(2)  # the paper's K
    ideal = estimator_gain(K, G * np.eye(2), CONTROL_PERIOD, eta_bar, 0.0, lag=lag)
    out = []
    for a in ACCEL_CANDIDATES:
        data = Plant.initial_data(sc)
        drive = robot.adapter(sc, data, CONTROL_PERIOD)
        u_all = turns(drive.command_limit)
        norms = closed_loop(sc, data, drive, u_all, K, G, eta_bar, lag, accel=a, seed=seed)
        result = Compensation(G, float(np.percentile(norms, 99)), float(norms.max()), ideal)
        out.append((a, result))
        if not result.runs_away:
            break
    return out


def acceleration_report(results: list[tuple[float, Compensation]]) -> tuple[str, bool]:
    """The line to print about jumping commands, and whether it is a warning."""
    first, (a, last) = results[0][1], results[-1]
    if not first.runs_away:
        return (
            f"jumping commands: healthy |phi_hat| p99 {first.phi_p99:.3g} m/s against "
            f"Phi_bar = {first.ideal:.3g} m/s with no acceleration limit (it does not run away)",
            False,
        )
    if last.runs_away:
        return (
            f"jumping commands run the compensation loop away (|phi_hat| p99 "
            f"{first.phi_p99:.3g} m/s) even at {a:g} m/s²: this drive cannot follow the "
            "team's commands",
            True,
        )
    return (
        f"jumping commands run the compensation loop away unlimited (|phi_hat| p99 "
        f"{first.phi_p99:.3g} m/s against Phi_bar = {first.ideal:.3g}); held to accel = {a:g} "
        f"m/s² it stays at {last.phi_p99:.3g} m/s: the robot limits its nominal input's "
        "change to that (onboard/applied.py)",
        False,
    )


def compensation_report(results: list[Compensation]) -> tuple[str, bool]:
    """The line to print about the compensation loop, and whether it is a warning."""
    first, last = results[0], results[-1]
    if not first.rings:
        return (
            f"compensation loop (G = {first.G:g} I): healthy |phi_hat| p99 "
            f"{first.phi_p99:.3g} m/s against its bound Phi_bar = {first.ideal:.3g} m/s "
            "(estimator_gain: ideal plant with the drive model; it does not ring)",
            False,
        )
    fix = (
        f"--set gains.G={last.G:g} keeps it at {last.phi_p99:.3g} m/s (ideal plant "
        f"{last.ideal:.3g})"
        if not last.rings
        else f"even G = {last.G:g} I does not calm it"
    )
    return (
        f"the compensation loop rings on this robot at G = {first.G:g} I: healthy |phi_hat| "
        f"reaches {first.phi_p99:.3g} m/s (p99; max {first.phi_max:.3g}) against "
        f"{first.ideal:.3g} m/s on an ideal plant, and the robot's commands carry it; {fix}",
        True,
    )


@dataclass(frozen=True)
class Drift:
    """A robot's drift y_k = x_k − ∫u_k in a mission, split as the threshold rules assume.

    ``drift_bound`` ē: the largest offset ‖D_k − S_k‖ left when the drift D_k(t) = y_k(t) −
    y_k(0) is followed by a slow part S_k that moves at most h ξ̄ per period (the greedy
    split: S_k steps towards D_k by at most h ξ̄). Compensation and actuator lag make the
    drift jitter and jump; those parts are bounded offsets, not drift (docs/thresholds.md).
    """

    scenario: str
    runs: int
    xi_bar: float
    startup: float  # ē over every robot, run and instant, the start-up included [m]
    drift_bound: float  # ē from ``settle`` s on [m]
    settle: float  # the start-up, the scenario's mission.transient [s]
    period_max: float  # largest per-period drift ‖w‖ / h [m/s], for comparison
    # ē of the robots that stayed healthy within REPLAN_WINDOW s after an exclusion (a run
    # with the scenario's stop faults, or a stop of robot 1): the re-plan's transient [m]
    replan: float | None = None
    replan_runs: int = 0
    excluded: int = 0  # exclusions seen in those runs


def split_drift(D: np.ndarray, step: float) -> np.ndarray:
    """‖D − S‖ (T,) for the greedy slow part S of drifts D (T, 2): S(0) = D(0) and S steps
    towards D by at most ``step`` per sample."""
    out = np.empty(len(D))
    s = D[0].copy()
    for t in range(len(D)):
        gap = D[t] - s
        norm = float(np.hypot(gap[0], gap[1]))
        if norm > step:
            s += gap * (step / norm)
        else:
            s[:] = D[t]
        out[t] = float(np.hypot(*(D[t] - s)))
    return out


def drift(
    name: str, scenario_name: str = "paper_case", overrides: dict | None = None, runs: int = 3
) -> Drift:
    """Run the scenario fault-free, noise at its bounds, with robot ``name`` (``runs`` seeds,
    every control period logged) and measure each robot's drift split (:class:`Drift`)."""
    from .loop import simulate
    from .scenario import load_scenario

    base = {
        **(overrides or {}),
        "team.robot_model": name,
        "faults": [],
        "noise.at_bound": True,
        "physics.matrix_log_rate": 0.1,
    }
    s0 = load_scenario(scenario_name, base)
    h = s0.physics.control_period
    base["physics.log_rate"] = 1.0 / h
    worst = after = per_period = 0.0
    xi_bar = 0.0
    for seed in range(1, runs + 1):
        s = load_scenario(scenario_name, {**base, "seed": seed})
        r = simulate(s)
        if not r.ok:
            raise ScenarioError(f"{s.source}: the run for the drift failed: {r.error}")
        xi_bar = float(r.summary["xi_bar"])
        off, d = _offsets(r.log, h, xi_bar)
        late = r.log["t"] >= s.mission.transient
        worst = max(worst, float(off.max()))
        after = max(after, float(off[late].max()) if late.any() else 0.0)
        per_period = max(per_period, float(np.linalg.norm(np.diff(d, axis=0), axis=2).max()) / h)
    # the re-plan: the scenario's stops (else robot 1 stopped at 60 % of the mission), the
    # drift of every robot that never had a fault, from each exclusion on
    stops: list[dict[str, Any]] = [
        {"robot": f.robot + 1, "kind": "stop", "t": f.t} for f in s0.faults if f.kind == "stop"
    ] or [{"robot": 1, "kind": "stop", "t": round(0.6 * s0.duration, 2)}]
    replan, excluded = 0.0, 0
    for seed in range(1, runs + 1):
        s = load_scenario(scenario_name, {**base, "faults": stops, "seed": seed})
        r = simulate(s)
        if not r.ok:
            raise ScenarioError(f"{s.source}: the run for the re-plan failed: {r.error}")
        t = r.log["t"]
        gone = r.events.of_kind("exclusion")
        faulty = {int(f["robot"]) - 1 for f in stops}
        healthy = np.array(sorted(set(range(r.log["x"].shape[1])) - faulty), dtype=int)
        if not gone or not len(healthy):
            continue
        excluded += len(gone)
        off, _ = _offsets(r.log, h, xi_bar)
        window = np.zeros(len(t), bool)
        for e in gone:
            window |= (t >= e["t"]) & (t <= e["t"] + REPLAN_WINDOW)
        if window.any():
            replan = max(replan, float(off[np.ix_(window, healthy)].max()))
    return Drift(
        scenario_name,
        runs,
        xi_bar,
        worst,
        after,
        s0.mission.transient,
        per_period,
        replan=replan if excluded else None,
        replan_runs=runs,
        excluded=excluded,
    )


def _offsets(log: dict, h: float, xi_bar: float) -> tuple[np.ndarray, np.ndarray]:
    """Every robot's drift D_k(t) = y_k(t) − y_k(0), y_k = x_k − ∫u_k (eq. 20), (T, N, 2),
    and its offset ‖D_k − S_k‖ (T, N) after the greedy split at h ξ̄ per period."""
    x, u = log["x"], log["u"]
    integral = np.concatenate([np.zeros((1, *u.shape[1:])), np.cumsum(h * u[:-1], axis=0)])
    y = x - integral
    d = y - y[0]
    off = np.stack([split_drift(d[:, k], h * xi_bar) for k in range(d.shape[1])], axis=1)
    return off, d


# --------------------------------------------------------------------------- writing


def write(path: Path, cal: Calibration) -> None:
    """Store the calibration: the ``[calibration]`` table of a robot file, or the
    ``<custom>`` numerics of an MJCF of the older contract (through MjSpec)."""
    if path.name.endswith(".toml"):
        _write_robot_file(path, cal.table())
    else:
        _write_mjcf(path, {"mismatch": cal.smooth_max, "xi_bar": cal.recommended_xi_bar})


def _calibration_header(path: Path, lines: list[str]) -> int | None:
    """The line of the robot file's ``[calibration]`` header (None: no calibration yet);
    a calibration written otherwise (inline or dotted keys) cannot be replaced line-wise."""
    start = next((i for i, ln in enumerate(lines) if ln.strip().startswith("[calibration]")), None)
    if start is None and "calibration" in tomllib.loads("\n".join(lines)):
        raise ScenarioError(
            f"{path}: calibration: written as an inline or dotted table; --write replaces a "
            "[calibration] table: move those keys into one (or delete them) and run again"
        )
    return start


def check_writable(path: Path) -> None:
    """Refuse ``--write`` before measuring when the robot file's calibration cannot be
    replaced (:func:`_calibration_header`); an MJCF is saved through MjSpec."""
    if path.name.endswith(".toml"):
        _calibration_header(path, path.read_text().splitlines())
    if not os.access(path, os.W_OK) or not os.access(path.parent, os.W_OK):
        raise ScenarioError(f"{path}: cannot write the calibration there (permission denied)")


def _write_robot_file(path: Path, values: dict[str, float]) -> None:
    """Replace (or add) the ``[calibration]`` table; every other line stays as it was."""
    lines = path.read_text().splitlines()
    start = _calibration_header(path, lines)
    body = [f"{k} = {v:.6g}" for k, v in values.items()]
    table = ["[calibration]  # python -m dftc_mujoco.calibrate --write", *body]
    if start is None:
        new = [*lines, "", *table]
    else:
        end = next(
            (i for i in range(start + 1, len(lines)) if lines[i].lstrip().startswith("[")),
            len(lines),
        )
        new = lines[:start] + table + ([""] if end < len(lines) else []) + lines[end:]
    text = "\n".join(new) + "\n"
    tomllib.loads(text)  # never write a file that does not read back
    write_text(path, text)


def _write_mjcf(path: Path, values: dict[str, float]) -> None:
    import mujoco

    spec = mujoco.MjSpec.from_file(str(path))
    for key, value in values.items():
        name = f"dftc_{key}"
        found = [n for n in spec.numerics if n.name == name]
        for extra in found[1:]:  # an earlier tool may have left duplicates
            spec.delete(extra)
        if found:
            found[0].data = [float(value)]
        else:
            spec.add_numeric(name=name, data=[float(value)])
    text = spec.to_xml()
    write_text(path, text)


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
    if cal.lag > 0:
        lines.insert(
            1,
            fit + ": the robot models it (lag), and every mismatch below is ‖ẋ − v̂‖ against "
            "that model",
        )
    else:
        lines.append(
            fit + f"; not modelled (below {LAG_MIN:g} s or not halving the mismatch): ẋ = u"
        )
    lines += [f"WARNING: {n}" for n in cal.notes]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    from . import cli
    from .run import parse_overrides
    from .sim import robots

    p = cli.parser(
        "dftc_mujoco.calibrate", "dftc-calibrate", "Measure a robot model's mismatch from ẋ = u."
    )
    p.add_argument(
        "model",
        help=f"a built-in model ({', '.join(robots.available())}), a robot file "
        "(NAME.robot.toml) or an MJCF path",
    )
    p.add_argument(
        "--write",
        action="store_true",
        help="store the results in the robot file's [calibration] table",
    )
    p.add_argument(
        "--scenario",
        default="paper_case",
        help="the mission for the detectability warning and the drift (default paper_case)",
    )
    cli.add_set_option(p, "that scenario (as with run)")
    p.add_argument(
        "--runs", type=int, default=3, help="fault-free runs of the scenario for the drift"
    )
    args = p.parse_args(argv)
    try:
        overrides = parse_overrides(args.overrides)  # bad input fails before measuring
        from .scenario import load_scenario

        load_scenario(args.scenario, overrides)
        path = robots.resolve(args.model, where="MODEL") if args.write else None
        if path is not None:
            check_writable(path)
        cal = measure(args.model)
        print(report(cal))
        line, warn = detectability(cal, args.scenario, args.model, overrides)
        print(f"WARNING: {line}" if warn else line)
        if cal.lag > 0:  # the missions below run the drive model the robot will run
            overrides.setdefault("fdir.drive_lag", cal.lag)
        loop_results = compensation(args.model, args.scenario, overrides=overrides, lag=cal.lag)
        line, warn = compensation_report(loop_results)
        print(f"WARNING: {line}" if warn else line)
        if loop_results[0].rings and "gains.G" not in overrides:
            overrides["gains.G"] = loop_results[-1].G
        overrides.setdefault("noise.xi_bar", cal.recommended_xi_bar)  # split for the new ξ̄
        cal = dataclasses.replace(cal, compensation_G=loop_results[-1].G)
        jumps = acceleration(args.model, loop_results[-1].G, lag=cal.lag)
        line, warn = acceleration_report(jumps)
        print(f"WARNING: {line}" if warn else line)
        if not jumps[-1][1].runs_away:
            cal = dataclasses.replace(cal, accel=jumps[-1][0])
        if path is not None:  # the drift runs then see the robot's new mismatch
            write(path, cal)
        try:
            d = drift(args.model, args.scenario, overrides, max(1, args.runs))
        except ScenarioError as exc:  # e.g. a robot too big for the scenario as it is
            d = None
            first = str(exc).splitlines()[0]
            print(
                f"WARNING: the drift was not measured: {args.scenario} cannot run with this "
                f"robot ({first}); give the scenario keys it needs with --set"
            )
        if d is not None:
            print(
                f"drift in {d.scenario} ({d.runs} fault-free runs, noise at its bounds, "
                f"{', '.join(f'{k} = {v}' for k, v in overrides.items()) or 'as it is'}): "
                f"per period up to {d.period_max:.3g} m/s; split for xi_bar = {d.xi_bar:g} m/s, "
                f"a bounded offset of {d.drift_bound * 1000:.2f} mm from {d.settle:g} s on "
                f"({d.startup * 1000:.2f} mm with the start-up)"
            )
            if d.replan is not None:
                print(
                    f"re-plan transient: {d.excluded} exclusions in {d.replan_runs} runs with a "
                    f"stop; the healthy robots' offset within {REPLAN_WINDOW:g} s of each "
                    f"exclusion reached {d.replan * 1000:.2f} mm (avoidance switches are in "
                    "every run above)"
                )
            else:
                print(
                    "WARNING: re-plan transient not measured: no exclusion happened in the "
                    "runs with a stop"
                )
        cal = dataclasses.replace(cal, drift=d)
        if path is not None:
            write(path, cal)
            robots.load(path)  # it must still load
            print(f"written to {path}")
    except ScenarioError as exc:
        cli.print_error(exc)
        return EXIT_INPUT
    except OSError as exc:
        print(f"error: cannot write the calibration: {exc}", file=sys.stderr)
        return EXIT_OUTPUT
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
