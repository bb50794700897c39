"""The closed loop: the only place where the plant and the onboard stacks meet.

:class:`Simulation` holds one run (MuJoCo model and data, the team, the log) and steps it,
each control period in one order: sense → decide → command → physics → monitor → log
(``step()`` period by period, ``run()`` to the end). It keeps only what cannot be derived
later (the raw log and the events); margins, clearances, reactive spans, fault estimates
and task errors are computed after the run (:mod:`dftc_mujoco.reporting.results`).
"""

from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
from tqdm.auto import tqdm

from ..core import mission
from ..core.events import Event, Kind
from ..core.record import Events, Log, matrix_every
from ..errors import DftcError, SimulationError
from ..onboard.block import Block, TeamConfig
from ..onboard.execution.team import Team
from ..onboard.thresholds import prefetch_decay_bounds
from ..reporting.results import RunResult, summarize
from ..runtime import numba_cache
from ..scenario import Scenario
from ..sim import fleet, mjcf, scene
from ..sim.faults import Fault
from ..sim.plant import NoiseStream, Plant
from ..sim.sensors import SensorFaults
from . import checks, network, premises, warm
from .assembly import (
    block_names,
    calibration_warnings,
    effective_xi_bar,
    governed_text,
    make_blocks,
    preflight,
    team_config,
    threshold_rule,
)
from .block_failure import block_error, setup_error
from .detection_domain import DetectionDomain
from .execution import Execution
from .physics_step import PhysicsStep, Sensed
from .snapshot import Snapshot

_CALM = contextlib.nullcontext()  # numpy's error state as it is (reusable)


def _check_seed(seed: object) -> None:
    """Refuse a seed that is not a whole number in 0..2**63 − 1 (None: keep the scenario's)."""
    if seed is not None and (
        isinstance(seed, bool)
        or not isinstance(seed, int | np.integer)
        or not 0 <= seed <= np.iinfo(np.int64).max
    ):
        raise ValueError(f"reset(seed): expected a whole number in 0..2**63 - 1, got {seed!r}")


class Simulation:
    """One run of a scenario on MuJoCo physics, steppable.

    ``blocks`` replaces onboard blocks by instances (``{"controller":
    MyController(gain=2.0)}``); the others come from the scenario's
    ``[onboard]`` table (a ``module:Class`` name is imported from sys.path,
    the scenario file's folder or the folders ``search``). ``hook(t, plant)``,
    if given, is called after every control period with the plant (for
    instrumentation or to perturb the physics). Use it as a context manager, or call :meth:`close`::

        with Simulation(load_scenario("paper_case")) as sim:
            snap = sim.step(100)      # 1 s
            result = sim.run()        # the rest
            result.save("renders/mine")

    ``model`` and ``data`` are the MuJoCo ``MjModel`` and ``MjData`` (``scene.spec``: its MjSpec).
    Physics trouble does not raise: the run stops, ``result.ok`` is False and
    the log up to that instant is kept.
    """

    faults: fleet.ActuatorFaults | fleet.MixedFaults  # the robots' actuator faults
    scene_xml = mjcf.simulation_xml  # the scene as MJCF text (dm_control loads it)

    def __init__(
        self,
        scenario: Scenario,
        *,
        blocks: Mapping[str, Block] | None = None,
        hook: Callable[[float, Plant], None] | None = None,
        search: Sequence[str | Path] = (),
        execution: Execution | None = None,
    ) -> None:
        wall0 = time.perf_counter()
        self._clock = numba_cache.clock()
        compiling0 = self._clock.total()
        if not isinstance(scenario, Scenario):  # an AttributeError from deep inside before
            raise TypeError(
                f"Simulation(scenario): expected a Scenario (load_scenario(...)), got "
                f"{type(scenario).__name__}"
            )
        if hook is not None and not callable(hook):  # it raised in the first period before
            raise TypeError(f"Simulation(hook): expected hook(t, plant) or None, got {hook!r}")
        checks.check_memory(scenario)  # before anything big is allocated
        self.scenario = scenario
        self.hook = hook
        self.execution = execution if execution is not None else Execution()
        #: seconds numba spent compiling during this simulation's life (not in its wall time)
        self.compile_time = 0.0
        #: the compiled period is being compiled by a background process for later runs
        self.warming: warm.Warming | None = None
        self._search = [Path(p) for p in search]
        self._asked_speed = scenario.mission.centroid.speed  # the path governor may lower it
        self._given = dict(blocks or {})
        # each robot's model; files are recorded by their absolute paths
        self.scenario, self.fleet = scenario, team = fleet.for_scenario(scenario)
        self.scenario = scenario = threshold_rule(scenario, team.envelope)  # "auto": a rule
        self.block_names = block_names(scenario, self._given)
        self.robot = team.envelope  # the team's bounds (one model: that model)
        if self.block_names["thresholds"] == "paper":  # its set-up needs κ/λ (eq. 41):
            prefetch_decay_bounds(scenario.team.graph, scenario.gains.ko)  # beside the scene
        self.scene = scene.build(scenario, team if team.mixed else self.robot)
        self._build_time = self._without_compiling(wall0, compiling0)
        self.plant: Plant | None = None
        self.reset()

    # ------------------------------------------------------------------ life cycle

    @property
    def model(self) -> mujoco.MjModel:
        """The MuJoCo model (arena, robots, cylinders)."""
        return self.scene.model

    @property
    def data(self) -> mujoco.MjData:
        """The MuJoCo data of the current run."""
        if self.plant is None:
            raise RuntimeError("the simulation is closed; call reset() to start a new run")
        return self.plant.data

    def __enter__(self) -> Simulation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _open(self, what: str) -> None:
        """RuntimeError when the simulation was closed."""
        if self.plant is None:
            raise RuntimeError(
                f"{what}: this Simulation was closed; reset() starts it again, or create a new one"
            )

    def close(self) -> None:
        """Restore the model's healthy actuators and drop the run's data."""
        if self.plant is not None:
            self.faults.clear()
            self.plant = None

    def reset(self, seed: int | None = None) -> None:
        """Start the run again from t = 0 (with another ``seed`` if given: a whole number
        ≥ 0)."""
        _check_seed(seed)
        wall0 = time.perf_counter()
        compiling0 = self._clock.total()
        if seed is not None:
            self.scenario = self.scenario.with_overrides(seed=seed)
        s, model = self.scenario, self.robot
        if self.plant is not None:
            self.faults.clear()
        sc = self.scene
        self.rng = np.random.default_rng(s.seed)
        self.dt = dt = s.physics.control_period
        self.xi_bar = xi_bar = effective_xi_bar(s, model)
        # the model's own mismatch already uses part of ξ̄ (eq. 2 bounds their sum)
        self.plant = plant = Plant(
            sc, s.noise, dt, self.rng, xi_bar=max(xi_bar - model.mismatch, 0.0)
        )
        # the robots' drives and their actuator faults (a mixed team: each model's own)
        self.adapter, self.faults = fleet.actuation(self.fleet, sc, plant.data, dt, s.faults)
        self.sensors = SensorFaults(s.faults, s.team.robots)
        n = self.n = s.team.robots
        self.steps = round(s.duration / dt)
        self.log_every = max(1, round(1.0 / (s.physics.log_rate * dt)))
        obstacles = np.array([[*o.position, o.radius, o.safe_distance] for o in s.obstacles])
        rows = self.steps // self.log_every + 2  # + the last period of an ended mission
        self.log = Log(
            rows,
            n,
            matrix_every=matrix_every(n, rows, self.log_every, dt, s.physics.matrix_log_rate),
            obstacles=obstacles.reshape(-1, 4),
        )
        self.events = Events()
        self.domain = DetectionDomain(self.events, self.steps * dt)  # eq. 46's
        for message in calibration_warnings(s, model, xi_bar):
            self.events.add(0.0, Kind.WARNING, message=message)
        for note in sc.notes:
            self.events.add(0.0, Kind.WARNING, message=note)
        self.path = mission.centroid_table(s.mission.centroid, s.duration, dt)
        self.command_limit = limit = self.adapter.command_limit
        blocks = make_blocks(s, self._given, self._search)
        # the first period's measurement starts the observers and the fault estimators
        self.noise = NoiseStream(plant)
        x0 = plant.positions()
        x_m0 = x0 + self.noise.peek()[0]
        slots = self.path.position[0] + mission.formation_offsets(s.mission.formation, n)
        meaning = premises.rule_meaning(
            blocks["thresholds"], self.block_names["thresholds"], str(s.source)
        )
        self.start_bound, refusal = premises.initial_error_bound(
            s.fdir.initial_error_bound, x0, slots, s.noise.eta_bar, meaning, str(s.source)
        )
        config = team_config(s, model, limit, self.start_bound.value, self.fleet.models)
        s, config = self._governed(s, config)
        rule = self.block_names["thresholds"]
        path = self.path.position
        for message in preflight(
            s, model, self.fleet.models, limit, config, xi_bar, refusal, path, dt, rule
        ):
            self.events.add(0.0, Kind.WARNING, message=message)
        ex = self.execution
        config = replace(
            config, compiled=self._compiled_period(blocks), threads=ex.thread_count(),
            shared_from=ex.shared_from,
        )  # fmt: skip
        try:
            self.team = Team(config, x_m0, self.path.position[0], blocks)
            # eq. 46's domain: faults from the rule's settle time on (docs/thresholds.md)
            self.settle_time = self.team.settle_time(s.duration)
        except DftcError:
            raise
        except Exception as exc:  # a (plug-in) block raised before the run: say which
            said = setup_error(exc, str(s.source))
            if said is None:
                raise
            raise said from exc
        self._team_warnings(s)
        self.monitor = premises.Monitor.for_team(
            self.team, self.block_names["thresholds"], self.command_limit, self.start_bound,
            x0, self.data.xpos[self.scene.body, 2], self.events,
        )  # fmt: skip
        self._network(s, dt)
        self.k = 0  # next control period
        self.error: SimulationError | None = None
        self.stopped: str | None = None  # why the run was stopped early (request_stop)
        self.left: str | None = None  # a robot left the arena: the mission is over
        self._seen = 0  # events already handed out by step()
        # what a period senses, the commands and the physics step (drive(): from outside)
        self._physics = PhysicsStep(
            plant, self.team.u_bar, self.adapter, self.faults, s.physics.substeps
        )
        self._x, self._x_m = self._physics.sensed.x, self._physics.sensed.x_m
        self._shown = _read_only(self._x), _read_only(self._x_m)  # made once: views
        self._x[:], self._x_m[:] = x0, x_m0  # what a snapshot before the first step shows
        self._build = self._build_time + self._without_compiling(wall0, compiling0)
        self._wall = self._build
        self._build_time = 0.0

    def _governed(self, s: Scenario, config: TeamConfig) -> tuple[Scenario, TeamConfig]:
        """The path governor: a path speed that leaves the drives no room in their applied
        range is flown slower (said in a warning); the scenario and the team's configuration
        as they then are."""
        limit = self.command_limit
        flown = mission.governed_speed(s.mission.centroid.speed, config.input_limit, limit)
        if flown is None or not s.mission.centroid.governor:
            return s, config
        text = governed_text(s, self.robot.name, config.input_limit, flown)
        self.events.add(0.0, Kind.WARNING, message=text)
        self.scenario = s = s.with_overrides(speed=flown)
        self.path = mission.centroid_table(s.mission.centroid, s.duration, self.dt)
        return s, team_config(s, self.robot, limit, self.start_bound.value, self.fleet.models)

    def _team_warnings(self, s: Scenario) -> None:
        """Warn of an unmet detection horizon and of thresholds that never flag."""
        if "warning" in self.team.dt_d_max_info:
            self.events.add(0.0, Kind.WARNING, message=self.team.dt_d_max_info["warning"])
        if self.team.never_flags and s.fdir.enabled:
            self.events.add(
                0.0,
                Kind.WARNING,
                message=(
                    f"onboard.thresholds: {self.block_names['thresholds']} gives +inf for every "
                    "pair at t = 0 and when steady: no robot can be flagged, a fault is never "
                    "detected"
                ),
            )
        self.team.dt_d_max_info["settle_time"] = (
            self.settle_time if np.isfinite(self.settle_time) else None
        )

    def _network(self, s: Scenario, dt: float) -> None:
        """The medium between the radios (None: an ideal network), its links in the log."""
        # the medium between the radios (None: the ideal network, which needs no model)
        self.channel: network.Channel | None = None
        if not s.network.ideal:
            self.channel = network.Channel(
                s.network, s.team.graph, dt, np.random.default_rng([s.seed, 23])
            )
            e = len(self.channel.edges)  # the links' age and losses, for the figure and video
            self.log.add_field("link_age", (e,), np.float32, np.nan)
            self.log.add_field("link_lost", (e,), np.int32, 0)
            self.log.static["links"] = self.channel.edges + 1
            self.log.static["link_bounds"] = np.array(self.channel.bounds())
            self._ages = np.zeros(e)

    def _without_compiling(self, wall0: float, compiling0: float) -> float:
        """Seconds since ``wall0`` less numba's compilation since then (added to
        :attr:`compile_time`): what a run reports as its own time is simulation only."""
        spent = self._clock.total() - compiling0
        self.compile_time += spent
        return time.perf_counter() - wall0 - spent

    def _compiled_period(self, blocks: Mapping[str, Block]) -> bool:
        """Whether the team runs the compiled period (:class:`~.execution.Execution`); on a
        cold cache a small team runs the general path and a background process compiles the
        compiled period for the runs that follow (:mod:`.warm`)."""
        compiled, later = self.execution.choose(self.scenario.team.robots, blocks)
        if later and self.warming is None:
            self.warming = warm.start(self.scenario, self._search)
        return compiled

    @property
    def t(self) -> float:
        """Time of the next control period [s]."""
        return self.k * self.dt

    @property
    def done(self) -> bool:
        """The run reached its duration, stopped on physics trouble, ended early (the team
        fell apart) or was stopped by :meth:`request_stop`."""
        return (
            self.k > self.steps
            or self.error is not None
            or self.team.ended is not None
            or self.stopped is not None
            or self.left is not None
        )

    def drive(self, robot: int, velocity: np.ndarray | Sequence[float] | None) -> None:
        """Command robot ``robot`` (0-based) from outside the team from the next period on:
        its drive is told ``velocity`` (planar, m/s) instead of the team's ū (the plant's
        disturbance ξ still adds to it); None gives it back to the team. Its onboard blocks
        run on as before, so what they see is a robot that does not follow its own commands
        (the environments of :mod:`dftc_mujoco.envs` drive robots this way)."""
        self._physics.drive(robot, velocity)

    def request_stop(self, reason: str) -> None:
        """Stop stepping before the next control period (safe from a signal handler):
        the records so far stay, and the summary's status is "interrupted"."""
        self.stopped = reason

    # ------------------------------------------------------------------ stepping

    def step(self, periods: int = 1) -> Snapshot:
        """Advance ``periods`` (a whole number ≥ 1) control periods; the state after them."""
        self._open("step()")
        if isinstance(periods, bool) or not isinstance(periods, int | np.integer) or periods < 1:
            raise ValueError(f"step(periods): expected a whole number ≥ 1, got {periods!r}")
        if self.done:
            raise RuntimeError("the run is over (duration reached or stopped); call reset()")
        self._advance(min(self.k + int(periods), self.steps + 1), None)
        return self.snapshot()

    def run(self, progress: bool | None = None) -> RunResult:
        """Run to the end (from wherever stepping left off) and return the records;
        ``progress``: show a progress bar (None: on a terminal or in a notebook)."""
        self._open("run()")
        if progress is None:
            progress = sys.stderr.isatty() or "ipykernel" in sys.modules
        if not self.done:
            self._advance(self.steps + 1, progress)
        return self.result()

    def advance(self, periods: int = 1) -> None:
        """Advance ``periods`` control periods like :meth:`step`, without copying the state
        into a snapshot (an environment reads what it needs: :attr:`positions`,
        :attr:`measurements`, ``team``, :meth:`new_events`)."""
        self._open("advance()")
        if self.done:
            raise RuntimeError("the run is over (duration reached or stopped); call reset()")
        self._advance(min(self.k + int(periods), self.steps + 1), None)

    @property
    def finished(self) -> bool:
        """The run reached its duration."""
        return self.k > self.steps

    @property
    def positions(self) -> np.ndarray:
        """(N, 2) the robots' true positions after the last period (read only)."""
        return self._shown[0]

    @property
    def measurements(self) -> np.ndarray:
        """(N, 2) each robot's own measured position after the last period (read only)."""
        return self._shown[1]

    def new_events(self) -> list[Event]:
        """The events since the last call (or snapshot), robots numbered from 1."""
        ev = self.events.items[self._seen :]
        self._seen = len(self.events.items)
        return [e.copy() for e in ev]

    def snapshot(self) -> Snapshot:
        """The state after the last control period (copies)."""
        t = (self.k - 1) * self.dt
        return Snapshot.of(t, self._x, self._x_m, self.team.outputs(), self.new_events())

    def _advance(self, k_end: int, progress: bool | None) -> None:
        """Control periods ``self.k`` .. ``k_end - 1``, each in one order: sense → decide →
        command → physics → monitor → log (the module's docstring)."""
        dt, steps, log_every = self.dt, self.steps, self.log_every
        plant, team, faults, noise = self.plant, self.team, self.faults, self.noise
        assert plant is not None  # reset() made it; close() ends stepping
        hook, monitor, log, channel = self.hook, self.monitor, self.log, self.channel
        position, velocity = self.path.position, self.path.velocity
        physics = self._physics
        seen = physics.sensed
        x, x_m = seen.x, seen.x_m
        k0 = k = self.k
        bar = (  # built only where shown: an environment's step would pay for it each period
            tqdm(total=k_end - k0, unit="period", desc=self.scenario.name, mininterval=0.5,
                 leave=False) if progress else None
        )  # fmt: skip
        wall0, compiling0 = time.perf_counter(), self._clock.total()
        failed: BaseException | None = None  # the physics step's error, raised after the period
        # NaN (excluded robots) and inf (unjudgeable ones) are expected in the general path's
        # numpy (the compiled one warns of nothing); physics trouble is the plant's to catch
        quiet = _CALM if team.compiled else np.errstate(invalid="ignore", divide="ignore")
        try:
            with quiet:
                for k in range(k0, k_end):
                    if self.stopped is not None:  # request_stop(): end before this period
                        break
                    t = k * dt
                    # sense: the faults that begin now, the truth, each robot's measurement
                    onsets = self._faults_due(t) if t >= faults.due else ()
                    eta, xi = noise.next()
                    physics.sense(eta)
                    if t >= self.sensors.due:  # faults of the position sensors, on x_m (eq. 4)
                        self._sensor_faults(t, x_m)
                    if channel is not None:
                        self._radio(t, k, channel)
                    # decide: the team's period up to its commands (ⁱx̂ where a row shows it)
                    estimates = k % log_every == 0 and log.row_nn >= 0
                    team.estimates = estimates or k == steps or k == k_end - 1
                    j = min(k, len(position) - 1)
                    self._decide(t, position[j], velocity[j], seen)
                    # the run's end, decided once: its last period, a team that fell apart,
                    # a robot off the floor (seen at a logged period)
                    logged = k % log_every == 0 or team.ended is not None or k == steps
                    left = logged and physics.far > checks.ARENA_HALF
                    last = k == steps or team.ended is not None or left
                    try:  # command, then physics (a shared pass goes on beside them)
                        ctrl = physics.commands(xi)
                        failed = None if last else physics.step(ctrl)
                    except BaseException:
                        team.join()
                        raise
                    self._finish(t)
                    # monitor: the premises against the truth sensed at the period's start
                    if channel is not None:
                        self._network_premises(t, k, channel)
                    monitor.period(
                        t, x, eta, team.u, team.u_bar, team.phi_hat, seen.height, seen.level,
                        seen.depth,
                    )  # fmt: skip
                    if team.events:
                        self._take_team_events(t)
                    for f in onsets:  # after the team's step: an exclusion now restarts the rule
                        self.domain.after_period(
                            t, f.robot + 1, team.settles_at, team.restarted_at,
                            team.recovery.dt_d_max,
                        )  # fmt: skip
                    if logged:  # log: a row of the period, as sensed and decided
                        self._sample(t, x, physics.cmd, position[j], seen.pose)
                    if last:
                        if left:
                            self._left_arena(t, x)
                        k += 1
                        break
                    if failed is not None:
                        raise failed
                    if hook is not None:
                        hook(plant.time, plant)
                    if bar is not None and k % 100 == 0:
                        bar.update(min(100, k_end - k0 - bar.n))
                else:
                    k = k_end
        except SimulationError as exc:
            self.error = exc
            if team.events:  # what the team did before the period failed (an exclusion at t_r)
                self._take_team_events(k * dt)
            when = plant.time if exc is failed else k * dt  # the physics' own time, if its
            k += 1
            self.events.add(when, Kind.SIMULATION_ERROR, message=str(exc))
        finally:
            if team.events:  # an interrupt in the middle of a period
                self._take_team_events(k * dt)
            self.k = k
            if bar is not None:
                bar.close()
            self._wall += self._without_compiling(wall0, compiling0)

    def _faults_due(self, t: float) -> Sequence[Fault]:
        """The actuator faults that begin (their events, and eq. 46's domain told) and end
        at ``t``; returns those that begin."""
        onsets = self.faults.apply(t)
        for f in onsets:
            # the speed it was told last: a stop's size at onset (eq. 46)
            told = float(np.hypot(*self.team.drive.command[f.robot]))
            self.events.add(t, Kind.FAULT, robot=f.robot + 1, fault=f.kind, command=round(told, 6))
            self.monitor.watched[f.robot] = False  # the fault is to be detected
            self.domain.onset(t, f.robot + 1, self.team.recovery.dt_d_max)
        for f in self.faults.just_ended:
            self.events.add(t, Kind.FAULT_ENDED, robot=f.robot + 1, fault=f.kind)
        return onsets

    def _decide(self, t: float, c: np.ndarray, c_dot: np.ndarray, seen: Sensed) -> None:
        """The team's period up to its commands (:meth:`.onboard.team.Team.start`): each
        robot from its own measurement, the range sensors' reading of every robot and its
        own bumper; a block's exception stops the run, its records kept."""
        try:
            self.team.start(t, seen.x_m, c, c_dot, seen.x, seen.touching)
        except (SimulationError, KeyboardInterrupt):
            raise
        except Exception as exc:  # a (plug-in) block raised: stop, keep records
            raise block_error(exc, t) from exc

    def _finish(self, t: float) -> None:
        """The rest of the team's period (:meth:`.onboard.team.Team.finish`): a shared pass
        joined, the flags and switches turned into events."""
        try:
            self.team.finish(t)
        except (SimulationError, KeyboardInterrupt):
            raise
        except Exception as exc:
            raise block_error(exc, t) from exc

    def _network_premises(self, t: float, k: int, channel: network.Channel) -> None:
        """Over a network, after the team's period: its broadcasts sent, and the premises of
        the links (missing messages, the links that delivered, silent robots judged by sight)."""
        team, monitor = self.team, self.monitor
        channel.send(k, team.rounds.content, self._physics.sensed.x)
        if team.missed:  # since the last round
            monitor.network(t, team.missed)
        if team.rounds.now:  # the links that delivered, jointly
            monitor.joint_graph(t, channel.joint_components(team.rounds.index, team.members))
        seen = team.sighting
        if seen is not None and seen.judged.any():
            x = self._physics.sensed.x
            monitor.slot(t, seen.judged, x, seen.slots, seen.tolerance)

    def _sensor_faults(self, t: float, x_m: np.ndarray) -> None:
        """Add the sensor faults' offsets to ``x_m``; their start and end are events."""
        began, over = self.sensors.apply(t, x_m)
        for f in began:
            self.events.add(t, Kind.FAULT, robot=f.robot + 1, fault=f.kind, command=None)
            self.monitor.watched[f.robot] = False  # the fault is to be detected
        for f in over:
            self.events.add(t, Kind.FAULT_ENDED, robot=f.robot + 1, fault=f.kind)

    def _radio(self, t: float, k: int, channel: network.Channel) -> None:
        """Before period ``k``'s step: radio faults that start now, and the messages that
        arrive (a corrupted one breaks the network premise)."""
        if t >= channel.next_fault:
            for f in channel.faults_due(t):
                self.events.add(
                    t,
                    Kind.RADIO_FAULT,
                    fault=f.kind,
                    robot=f.robot + 1 if f.robot >= 0 else None,
                    link=[f.link[0] + 1, f.link[1] + 1] if f.kind == "link_down" else None,
                    value=f.value if f.kind == "corrupt" else None,
                )
        links, rounds, offset = channel.receive(k)
        self.team.receive(links, rounds, offset)
        if offset.any():
            self.monitor.network(t, int(np.count_nonzero(offset)))

    def _take_team_events(self, t: float) -> None:
        """Move the team's events into the run's, each flag labelled with the premises its
        robot violated within its residuals' memory (``premises.memory``), and tell the monitor
        of exclusions."""
        monitor = self.monitor
        for e in self.team.events:
            kind = e["kind"]
            if kind == Kind.DETECTION:
                e["premises"] = monitor.violated(e["robot"] - 1, t)
            elif kind == Kind.SYSTEMIC_ANOMALY:  # what the flagged robots violated then
                e["premises"] = sorted({p for r in e["robots"] for p in monitor.violated(r - 1, t)})
            elif kind == Kind.EXCLUSION:
                monitor.watched[e["robot"] - 1] = False
            elif kind == Kind.GRAPH_NOT_STRONGLY_CONNECTED:
                monitor.graph_changed(t, False)
            self.events.add(e["t"], kind, **{k: v for k, v in e.items() if k not in ("t", "kind")})
            if kind == Kind.EXCLUSION:  # the thresholds restarted: windows of eq. 46 it cuts
                self.domain.excluded(e["t"], e["robot"], self.team.settles_at)
        self.team.events.clear()

    def _left_arena(self, t: float, x: np.ndarray) -> None:
        """End the mission: a robot is off the floor (``checks.ARENA_HALF``)."""
        i = int(np.abs(x).max(axis=1).argmax())
        self.left = f"robot {i + 1} left the arena (at {np.round(x[i], 1).tolist()} m)"
        self.events.add(t, Kind.MISSION_ENDED, reason=self.left, robots=[i + 1])

    def _sample(
        self, t: float, x: np.ndarray, cmd: np.ndarray, c: np.ndarray, pose: np.ndarray
    ) -> None:
        """One log row: raw values only (everything else is derived after the run), the
        robots' ``pose`` as sensed at the period's start."""
        log = self.log
        row, d = log.size, log.data
        log.sample(t, x, c, cmd, self.command_limit)  # v_cmd: within the drives' range
        d["pose"][row] = pose
        self.team.write_row(d, row, self.scenario.fdir.enabled, log.row_nn)
        if self.channel is not None:
            self.channel.ages(round(t / self.dt), self._ages)
            d["link_age"][row] = self._ages
            d["link_lost"][row] = self.channel.lost
        log.size += 1

    # ------------------------------------------------------------------ results

    @property
    def simulated_time(self) -> float:
        """The time the physics reached: a whole number of MuJoCo steps. ``data.time`` sums
        the timestep once per step and drifts from that by ~1e-9 s after 10^5 steps."""
        h = self.model.opt.timestep
        return 0.0 if self.plant is None else round(self.plant.time / h) * h

    def result(self) -> RunResult:
        """The records of the run so far (the log, the events and the summary)."""
        self.monitor.finish(self.simulated_time)
        self.events.items.sort(key=lambda e: e["t"])  # spans are added when they end
        arrays = self.log.arrays()
        arrays["phi"] = self.faults.phi_series(arrays["t"], arrays["v_cmd"])
        arrays["sigma_err"] = mission.task_errors(arrays["x"], arrays["x_d"], arrays["active"])
        summary = summarize(
            self.scenario,
            arrays,
            self.events,
            xi_bar=self.xi_bar,
            footprint=self.robot.footprint_radius,
            obstacle_safe=self.team.config.obstacle_safe,
            wall=self._wall,
            error=self.error,
            sim_time=self.simulated_time,
            finished=self.k > self.steps,
            ended=self.team.ended or self.left,
            stopped=self.stopped,
        )
        summary["premises"] = self.monitor.table()
        # what the channel did per link (the ideal network: every message in the next period)
        summary["network"] = self.channel.summary() if self.channel is not None else {"ideal": True}
        summary["build_time"] = self._build
        summary["dt_d_max"] = self.team.dt_d_max_info
        summary["compile_time"] = self.compile_time
        flown = self.scenario.mission.centroid.speed
        summary["mission_speed"] = {"asked": self._asked_speed, "flown": flown}
        summary["onboard"] = {"path": self.team.path, "blocks": dict(self.block_names)}
        if self.warming is not None:
            summary["onboard"]["compiling_in_background"] = True
        return RunResult(self.scenario, arrays, self.events, summary, self.error)


def simulate(
    s: Scenario,
    *,
    progress: bool = False,
    hook: Callable[[float, Plant], None] | None = None,
    blocks: Mapping[str, Block] | None = None,
    search: Sequence[str | Path] = (),
    execution: Execution | None = None,
) -> RunResult:
    """Run scenario ``s`` to the end and return its records (a thin wrapper of :class:`Simulation`).

    Physics trouble does not raise: the result carries the error and the log
    up to that instant (``result.ok`` is False).
    """
    with Simulation(s, blocks=blocks, hook=hook, search=search, execution=execution) as sim:
        return sim.run(progress=progress)


__all__ = ["RunResult", "Simulation", "Snapshot", "effective_xi_bar", "simulate", "team_config"]


def _read_only(a: np.ndarray) -> np.ndarray:
    """A view of ``a`` that cannot be written."""
    view = a.view()
    view.flags.writeable = False
    return view
