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


def team_config(s: Scenario) -> TeamConfig:
    """The onboard configuration a scenario gives every robot."""
    obs = s.obstacles
    return TeamConfig(
        graph=s.team.graph,
        kc=s.gains.kc,
        ko=s.gains.ko,
        theta=s.gains.theta,
        dt=s.physics.control_period,
        obstacle_position=np.array([o.position for o in obs]).reshape(-1, 2),
        obstacle_safe=np.array([o.safe_distance for o in obs]),
        obstacle_activation=np.array([o.activation_distance for o in obs]),
    )


def simulate(
    s: Scenario,
    *,
    progress: bool = False,
    noise_at_bound: bool = False,
    hook: Callable[[float, Plant], None] | None = None,
) -> RunResult:
    """Run scenario ``s`` on MuJoCo physics and return its records.

    ``noise_at_bound`` draws η and ξ with norms exactly at η̄ and ξ̄.
    ``hook(t, plant)``, if given, is called after every control period with
    the plant (for instrumentation or to perturb the physics).
    Physics trouble does not raise: the result carries the error and the log
    up to that instant (``result.ok`` is False).
    """
    wall0 = time.perf_counter()
    model = robots.get(s.team.robot_model, where=f"{s.source}: team.robot_model")
    sc = scene.build(s, model)
    adapter = model.adapter()
    rng = np.random.default_rng(s.seed)
    dt = s.physics.control_period
    plant = Plant(sc, s.noise, dt, rng, noise_at_bound=noise_at_bound)
    actuator_faults = sim_faults.ActuatorFaults(sc.model, s.faults, sc.actuator, adapter)

    n = s.team.robots
    steps = round(s.duration / dt)
    log_every = max(1, round(1.0 / (s.physics.log_rate * dt)))
    log = Log(steps // log_every + 1, n)
    events = Events()

    path = mission.centroid_table(s.mission.centroid, s.duration, dt)
    offsets = mission.formation_offsets(s.mission.formation, n)
    x_d = path.position[0] + offsets
    team = Team(team_config(s), plant.measure(), prior=x_d)

    obs_pos = team.config.obstacle_position
    obs_gap = np.array([o.radius for o in s.obstacles]) + model.footprint_radius
    obs_safe = team.config.obstacle_safe
    min_gap = math.inf
    min_margin = math.inf
    reactive_prev = np.zeros(n, bool)
    reactive_on = np.zeros(n)
    reactive_spans: list[dict[str, Any]] = []
    active = np.ones(n, bool)
    nsub = s.physics.substeps
    error: SimulationError | None = None

    build_time = time.perf_counter() - wall0
    bar = tqdm(
        total=steps, disable=not progress, unit="step", desc=s.name, mininterval=0.5, leave=False
    )
    try:
        for k in range(steps + 1):
            t = k * dt
            for f in actuator_faults.apply(t):
                events.add(t, "fault", robot=f.robot, fault=f.kind)
            x = plant.positions()
            x_m = plant.measure()
            c, c_dot = path.at(k)
            x_d = c + offsets
            out = team.step(x_m, x_d, np.broadcast_to(c_dot, x_d.shape))
            ctrl = adapter.command(out.u_bar)

            if len(obs_pos):
                dist = np.linalg.norm(x[:, None, :] - obs_pos[None], axis=2)
                min_gap = min(min_gap, float((dist - obs_gap).min()))
                min_margin = min(min_margin, float((dist - obs_safe).min()))
            switched = out.reactive != reactive_prev
            if switched.any():
                for i in np.flatnonzero(switched):
                    if out.reactive[i]:
                        reactive_on[i] = t
                        events.add(t, "reactive_on", robot=int(i))
                    else:
                        reactive_spans.append({"robot": int(i), "t_on": reactive_on[i], "t_off": t})
                        events.add(t, "reactive_off", robot=int(i))
                reactive_prev = out.reactive.copy()

            if k % log_every == 0:
                err = mission.task_map(x) - mission.task_map(x_d)
                log.sample(
                    t=t,
                    x=x,
                    x_hat=out.x_hat,
                    u=out.u,
                    phi=actuator_faults.phi(t, ctrl),
                    residual=np.linalg.norm(out.residual, axis=2),
                    reactive=out.reactive,
                    active=active,
                    sigma_err=(np.linalg.norm(err[0]), np.linalg.norm(err[1:])),
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
        bar.close()
        actuator_faults.clear()

    for i in np.flatnonzero(reactive_prev):
        reactive_spans.append({"robot": int(i), "t_on": reactive_on[i], "t_off": None})
    wall = time.perf_counter() - wall0
    arrays = log.arrays()
    summary = _summary(
        s, arrays, events, reactive_spans, wall, min_gap, min_margin, error, plant.time
    )
    summary["build_time"] = build_time
    return RunResult(s, arrays, events, summary, error)


def _rms(a: np.ndarray) -> float | None:
    a = a[np.isfinite(a)]
    return float(np.sqrt(np.mean(a**2))) if len(a) else None


def _finite_or_none(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def _summary(
    s: Scenario,
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
        "min_obstacle_clearance": _finite_or_none(min_gap),
        "min_safe_distance_margin": _finite_or_none(min_margin),
    }
