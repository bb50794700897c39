"""The closed loop: the only place where the plant and the onboard stacks meet.

One control period (DESIGN.md): faults switch on in the actuator model →
each robot measures its own position → the team's onboard stacks compute
their inputs → the robot adapter turns them into actuator commands → MuJoCo
advances by ``control_period`` → the recorder samples at the log rate.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from tqdm import tqdm

from . import mission
from .errors import SimulationError
from .onboard.team import Team, TeamConfig
from .record import Events, Log
from .scenario import Scenario
from .sim import faults as sim_faults
from .sim import robots, scene
from .sim.plant import Plant


@dataclass
class RunResult:
    """What a run leaves: the log, the events, the summary, and the error if it failed."""

    scenario: Scenario
    log: dict[str, np.ndarray]
    events: Events
    summary: dict[str, Any]
    error: SimulationError | None = None
    extras: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.error is None


CLEARANCE = 0.02  # least gap kept between a robot's hull and a cylinder or robot [m]


def effective_xi_bar(s: Scenario, robot: robots.RobotModel | None) -> float:
    """ξ̄ of the run: the scenario's if it sets one, else the robot model's measured one."""
    if s.noise.xi_bar is not None:
        return s.noise.xi_bar
    return robot.xi_bar if robot is not None else 0.0


def team_config(
    s: Scenario, robot: robots.RobotModel | None = None, command_limit: float = np.inf
) -> TeamConfig:
    """The onboard configuration a scenario gives every robot of model ``robot``.

    A robot too big for a safe distance d (cylinder radius + its footprint +
    2 cm > d) gets the larger value, so no hull ever reaches a cylinder or an
    excluded robot. ``command_limit`` is the per-axis planar command range.
    """
    obs = s.obstacles
    f = s.fdir
    reach = robot.footprint_radius if robot is not None else 0.0
    excluded_safe = max(f.excluded_safe_distance, 2 * reach + CLEARANCE)
    return TeamConfig(
        graph=s.team.graph,
        kc=s.gains.kc,
        ko=s.gains.ko,
        K=np.asarray(s.gains.K),
        G=np.asarray(s.gains.G),
        theta=s.gains.theta,
        dt=s.physics.control_period,
        eta_bar=s.noise.eta_bar,
        xi_bar=effective_xi_bar(s, robot),
        formation=s.mission.formation,
        obstacle_position=np.array([o.position for o in obs]).reshape(-1, 2),
        obstacle_safe=np.array([max(o.safe_distance, o.radius + reach + CLEARANCE) for o in obs]),
        obstacle_activation=np.array([o.activation_distance for o in obs]),
        detection_window=f.detection_window,
        dt_d_max=f.dt_d_max,
        initial_error_bound=f.initial_error_bound,
        replan_time=f.replan_time,
        excluded_safe=excluded_safe,
        excluded_activation=max(f.excluded_activation_distance, excluded_safe + 0.1),
        phi_low_pass=f.phi_low_pass,
        command_limit=command_limit,
        fdir=f.enabled,
        compensate=f.compensate,
    )


def simulate(
    s: Scenario,
    *,
    progress: bool = False,
    hook: Callable[[float, Plant], None] | None = None,
) -> RunResult:
    """Run scenario ``s`` on MuJoCo physics and return its records.

    ``hook(t, plant)``, if given, is called after every control period with
    the plant (for instrumentation or to perturb the physics).
    Physics trouble does not raise: the result carries the error and the log
    up to that instant (``result.ok`` is False).
    """
    wall0 = time.perf_counter()
    model = robots.get(s.team.robot_model, where=f"{s.source}: team.robot_model")
    sc = scene.build(s, model)
    rng = np.random.default_rng(s.seed)
    dt = s.physics.control_period
    xi_bar = effective_xi_bar(s, model)
    # the model's own mismatch already uses part of ξ̄ (eq. 2 bounds their sum)
    plant = Plant(sc, s.noise, dt, rng, xi_bar=max(xi_bar - model.mismatch, 0.0))
    adapter = model.adapter(sc, plant.data)
    actuator_faults = sim_faults.ActuatorFaults(sc.model, s.faults, sc.actuator, adapter)

    n = s.team.robots
    steps = round(s.duration / dt)
    log_every = max(1, round(1.0 / (s.physics.log_rate * dt)))
    obstacles = np.array([[*o.position, o.radius, o.safe_distance] for o in s.obstacles])
    log = Log(steps // log_every + 1, n, obstacles=obstacles.reshape(-1, 4))
    events = Events()
    if xi_bar < model.mismatch:
        events.add(
            0.0,
            "warning",
            message=(
                f"noise.xi_bar = {xi_bar:g} m/s is below the {model.name} model's measured "
                f"mismatch ({model.mismatch:g} m/s, python -m dftc_mujoco.calibrate {model.name}; "
                f"recommended {model.xi_bar:g}): thresholds may raise false alarms"
            ),
        )

    path = mission.centroid_table(s.mission.centroid, s.duration, dt)
    limited = sc.model.actuator_ctrllimited[sc.actuator].all()
    limit = adapter.command_limit if limited else np.inf
    team = Team(team_config(s, model, limit), plant.measure(), path.position[0])
    fault_start = np.full(n, np.inf)  # ground truth, for the margin only
    bias_only = np.ones(n, bool)
    for f in s.faults:
        fault_start[f.robot] = min(fault_start[f.robot], f.t)
        bias_only[f.robot] &= f.kind == "bias"
    margin = {"healthy": 0.0, "compensated": 0.0}
    settle = 5.0
    changes = sorted({f.t for f in s.faults} | {f.t + settle for f in s.faults})
    next_change = 0.0
    healthy = settled = np.zeros(n, bool)

    obs_pos = team.config.obstacle_position
    obs_gap = np.array([o.radius for o in s.obstacles]) + model.footprint_radius
    obs_safe = team.config.obstacle_safe
    min_gap = math.inf
    min_margin = math.inf
    reactive_prev = np.zeros(n, bool)
    reactive_on = np.zeros(n)
    reactive_spans: list[dict[str, Any]] = []
    nsub = s.physics.substeps
    error: SimulationError | None = None

    build_time = time.perf_counter() - wall0
    bar = tqdm(
        total=steps, disable=not progress, unit="step", desc=s.name, mininterval=0.5, leave=False
    )
    # NaN (excluded robots) and inf (unjudgeable ones) are expected in residual / threshold;
    # physics trouble is caught explicitly by the plant, not by numpy warnings
    errstate = np.errstate(invalid="ignore", divide="ignore")
    errstate.__enter__()
    try:
        for k in range(steps + 1):
            t = k * dt
            for f in actuator_faults.apply(t):
                events.add(t, "fault", robot=f.robot, fault=f.kind)
            x = plant.positions()
            x_m = plant.measure(x)
            c, c_dot = path.at(k)
            out = team.step(t, x_m, c, c_dot, sensed_bodies=x)
            ctrl = adapter.command(out.u_bar + plant.disturbance())
            for e in out.events:
                events.add(t, e.pop("kind"), **{k_: v for k_, v in e.items() if k_ != "t"})
            if s.fdir.enabled:
                ratio = out.residual / out.threshold  # NaN for excluded robots: fmax skips
                if t >= next_change:  # the masks change only at fault instants (+ settle)
                    healthy = fault_start > t
                    settled = bias_only & (fault_start + settle <= t)
                    later = [c for c in changes if c > t]
                    next_change = min(later) if later else math.inf
                if healthy.any():
                    margin["healthy"] = max(
                        margin["healthy"], float(np.fmax.reduce(ratio[:, healthy], axis=None))
                    )
                if settled.any():
                    margin["compensated"] = max(
                        margin["compensated"], float(np.fmax.reduce(ratio[:, settled], axis=None))
                    )

            if len(obs_pos):
                rel = x[:, None, :] - obs_pos[None]
                dist = np.sqrt(np.einsum("nok,nok->no", rel, rel))
                min_gap = min(min_gap, float((dist - obs_gap).min()))
                min_margin = min(min_margin, float((dist - obs_safe).min()))
            switched = out.reactive != reactive_prev
            if switched.any():
                for i in np.flatnonzero(switched):
                    if out.reactive[i]:
                        reactive_on[i] = t
                        events.add(
                            t,
                            "reactive_on",
                            robot=int(i),
                            obstacle=_obstacle_label(int(out.avoiding[i]), len(obs_pos)),
                        )
                    else:
                        reactive_spans.append({"robot": int(i), "t_on": reactive_on[i], "t_off": t})
                        events.add(t, "reactive_off", robot=int(i))
                reactive_prev = out.reactive.copy()

            if k % log_every == 0:
                act = out.active
                err = mission.task_map(x[act] - out.x_d[act])  # σ − σ_d = J (x − x_d)
                log.sample(
                    t=t,
                    x=x,
                    x_hat=out.x_hat,
                    u=out.u,
                    phi=actuator_faults.phi(t, ctrl),
                    phi_hat=out.phi_hat if s.fdir.enabled else np.nan,
                    residual=out.residual,
                    threshold=out.threshold if s.fdir.enabled else np.nan,
                    reactive=out.reactive,
                    active=act,
                    sigma_err=(np.sqrt(err[0] @ err[0]), np.sqrt(np.sum(err[1:] ** 2))),
                    x_d=out.x_d,
                    pose=plant.poses(),
                    c_d=c,
                    flagged=out.flagged,
                )
            if k == steps:
                break
            plant.step(ctrl, nsub)
            if hook is not None:
                hook(plant.time, plant)
            if k % 100 == 0:
                bar.update(min(100, steps - bar.n))
    except SimulationError as exc:
        error = exc
        events.add(plant.time, "simulation_error", message=str(exc))
    finally:
        errstate.__exit__(None, None, None)
        bar.close()
        actuator_faults.clear()

    for i in np.flatnonzero(reactive_prev):
        reactive_spans.append({"robot": int(i), "t_on": reactive_on[i], "t_off": None})
    wall = time.perf_counter() - wall0
    arrays = log.arrays()
    summary = _summary(
        s, xi_bar, arrays, events, reactive_spans, wall, min_gap, min_margin, error, plant.time
    )
    summary["build_time"] = build_time
    if s.fdir.enabled:
        summary["margin"] = margin["healthy"]
        summary["margin_compensated"] = (
            margin["compensated"] if bias_only[np.isfinite(fault_start)].any() else None
        )
        summary["fault_estimates"] = _fault_estimates(s, arrays, events, settle)
    return RunResult(s, arrays, events, summary, error)


def _fault_estimates(
    s: Scenario, log: dict[str, np.ndarray], events: Events, settle: float
) -> list[dict[str, Any]]:
    """Error of φ̂ against the injected φ per bias fault, from t_f + settle to the next event."""
    t = log["t"]
    marks = sorted(
        {e["t"] for e in events.items if e["kind"] in ("fault", "exclusion", "simulation_error")}
    )
    rows = []
    for f in s.faults:
        if f.kind != "bias":
            continue
        start = f.t + settle
        end = min([m for m in marks if m > f.t] + [t[-1] + 1e-9 if len(t) else start])
        win = (t >= start) & (t < end)
        if win.sum() < 2:
            continue
        err = log["phi_hat"][win, f.robot] - log["phi"][win, f.robot]
        rows.append(
            {
                "robot": f.robot + 1,
                "t": f.t,
                "window": [start, float(t[win][-1])],
                "mean_error": np.abs(err.mean(axis=0)).tolist(),
                "rms_error": np.sqrt((err**2).mean(axis=0)).tolist(),
            }
        )
    return rows


def _obstacle_label(index: int, n_cylinders: int) -> str:
    """'cylinder k' or 'robot k' (1-based) for what a robot's supervisor avoids."""
    if index < n_cylinders:
        return f"cylinder {index + 1}"
    return f"robot {index - n_cylinders + 1}"


def _rms(a: np.ndarray) -> float | None:
    a = a[np.isfinite(a)]
    return float(np.sqrt(np.mean(a**2))) if len(a) else None


def _finite_or_none(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def _summary(
    s: Scenario,
    xi_bar_used: float,
    log: dict[str, np.ndarray],
    events: Events,
    reactive: list[dict[str, Any]],
    wall: float,
    min_gap: float,
    min_margin: float,
    error: SimulationError | None,
    sim_time: float,
) -> dict[str, Any]:
    """The ``summary.json`` contract (robots numbered from 1)."""
    t = log["t"]
    window = t >= s.mission.transient
    err = log["sigma_err"]
    last = err[-1] if len(err) else (math.nan, math.nan)
    simulated = float(t[-1]) if len(t) else 0.0
    return {
        "scenario": s.name,
        "seed": s.seed,
        "duration": s.duration,
        "robots": s.team.robots,
        "robot_model": s.team.robot_model,
        "status": "ok" if error is None else "failed",
        "error": None if error is None else str(error),
        "simulated_time": round(sim_time, 9) if error else simulated,
        "wall_time": wall,
        "real_time_factor": (sim_time / wall) if wall > 0 else None,
        "faults": [
            {"robot": e["robot"] + 1, "kind": e["fault"], "t": e["t"]}
            for e in events.of_kind("fault")
        ],
        "reactive": [
            {
                "robot": r["robot"] + 1,
                "t_on": round(float(r["t_on"]), 6),
                "t_off": None if r["t_off"] is None else round(float(r["t_off"]), 6),
            }
            for r in sorted(reactive, key=lambda r: (r["t_on"], r["robot"]))
        ],
        "detections": [
            {"by": e["by"] + 1, "robot": e["robot"] + 1, "t": e["t"]}
            for e in events.of_kind("detection")
        ],
        "exclusions": [{"robot": e["robot"] + 1, "t": e["t"]} for e in events.of_kind("exclusion")],
        "errors": {
            "window": [s.mission.transient, simulated],
            "centroid_rms": _rms(err[window, 0]),
            "formation_rms": _rms(err[window, 1]),
            "final_centroid": _finite_or_none(last[0]),
            "final_formation": _finite_or_none(last[1]),
        },
        "xi_bar": xi_bar_used,
        "xi_bar_source": "scenario" if s.noise.xi_bar is not None else "robot model",
        "warnings": [e["message"] for e in events.of_kind("warning")]
        + [
            f"t = {e['t']:g} s: after an exclusion the graph of robots "
            f"{', '.join(str(r + 1) for r in e['robots'])} is not strongly connected; "
            "some estimates and thresholds are no longer bounded"
            for e in events.of_kind("graph_not_strongly_connected")
        ],
        "min_obstacle_clearance": _finite_or_none(min_gap),
        "min_safe_distance_margin": _finite_or_none(min_margin),
    }
