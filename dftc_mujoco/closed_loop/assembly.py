"""Assembly: a scenario and a robot model turned into the team's configuration and blocks.

What every robot is given before the run (``TeamConfig``): the gains, the noise bounds the
robot model's calibration implies, the drive's applied range, acceleration and lag, the
distances at which cylinders, excluded robots and teammates are avoided, the fault
hypothesis; and the six onboard blocks, the scenario's or the caller's. The loop
(:mod:`dftc_mujoco.closed_loop.loop`) asks this module and nothing else.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .. import blocks as blocks_mod
from ..core.mission import slot_spacing
from ..errors import ScenarioError
from ..onboard.block import Block
from ..onboard.execution.team import TeamConfig
from ..onboard.fault_estimator import ANTI_WINDUP_BAND
from ..onboard.thresholds import estimator_gain
from ..scenario import Scenario
from ..sim import robots
from . import network
from .checks import CLEARANCE

PAPER_G = 0.01  # eq. 30's G = 0.01 I, the paper's value
TEAMMATE_MARGIN = 0.1  # [m] least gap between a robot's safe and activation distances


def seamless_margin(theta: float, input_limit: float) -> float:
    """Activation − safe distance for a robot or excluded robot seen by the range sensor.

    Eq. 18 meets u_g,i at the switch (docs/notes.md, 12) only where θ (d − ‖xᵢ − x_o‖) can equal
    r̂ᵀu_g,i, i.e. from d + ‖u‖/θ on: a robot closing in at the input range ‖u‖ ≤ √2 ×
    ``input_limit`` (per axis) that first senses the obstacle nearer than that switches with a
    jump of ‖u‖ − θ (activation − d), and a queue of robots behind each other turns such
    jumps into a limit cycle whose compensation rings (battery run 1735: 0.5 m/s jumps at
    10 Hz, a healthy robot excluded). At least :data:`TEAMMATE_MARGIN`.
    """
    if not np.isfinite(input_limit) or theta <= 0:
        return TEAMMATE_MARGIN
    return max(TEAMMATE_MARGIN, float(np.sqrt(2.0) * input_limit / theta))


def effective_xi_bar(s: Scenario, robot: robots.RobotModel | None) -> float:
    """ξ̄ of the run: the scenario's if it sets one, else the robot model's measured one."""
    if s.noise.xi_bar is not None:
        return s.noise.xi_bar
    return robot.xi_bar if robot is not None else 0.0


#: ξ̄ of the paper's robots [m/s]: eq. 40's thresholds are drawn for a mismatch this small
PAPER_XI_BAR = 0.005


#: the paper's team: "auto" keeps eq. 40 for teams up to this size
PAPER_TEAM = 4

#: beyond this size "auto" keeps eq. 40 again: the drive and l1 rules set up an N × N
#: threshold array from every column's envelope, which at N = 1000 on the benchmark's ring
#: with chords took 13.5 s against eq. 40's 0.65 s, and a period 5.9 ms against 2.0 ms
#: (``docs/performance.md``); at N = 400 the three cost about the same
DENSE_RULES_UP_TO = 400


def threshold_rule(s: Scenario, robot: robots.RobotModel | None) -> Scenario:
    """The scenario with ``onboard.thresholds = "auto"`` made a rule: the paper's eq. 40 for
    a team of the paper's size (:data:`PAPER_TEAM` robots at most) that moves within the
    paper's ξ̄ (0.005 m/s) on an ideal network; otherwise the ``drive`` rule where the
    drive's lag is known (calibrated, or ``fdir.drive_lag``: its Φ̄ then bounds ‖φ̂‖ at
    every period), else ``l1``; ``l1`` over a network (eq. 40 is not derived for the
    observers' rounds). Eq. 40 grows with κ/λ, which grows with the team: from 8 robots on
    it missed stops that the other rules flag (``docs/thresholds.md``). A team of more than
    :data:`DENSE_RULES_UP_TO` robots within the paper's ξ̄ keeps eq. 40 too, the one rule
    whose set-up and period stay cheap there."""
    if s.onboard.thresholds != "auto":
        return s
    paper_like = not PAPER_TEAM < s.team.robots <= DENSE_RULES_UP_TO
    if not s.network.ideal:
        rule = "l1"
    elif paper_like and effective_xi_bar(s, robot) <= PAPER_XI_BAR * (1 + 1e-9):
        rule = "paper"
    elif _lag_known(s, robot):
        rule = "drive"
    else:
        rule = "l1"
    return dataclasses.replace(s, onboard=dataclasses.replace(s.onboard, thresholds=rule))


def _lag_known(s: Scenario, robot: robots.RobotModel | None) -> bool:
    """Whether the robots' drive lag is known: given (``fdir.drive_lag``) or calibrated."""
    if s.fdir.drive_lag != "robot":
        return float(s.fdir.drive_lag) > 0
    return robot is not None and (robot.lag > 0 or robot.fast_lag > 0)


def effective_G(s: Scenario, robot: robots.RobotModel | None) -> np.ndarray:
    """G of eq. 30 for the run: the scenario's, or with ``gains.G = "auto"`` the robot model's
    calibrated ``compensation_G`` (the smallest G x I whose compensation loop does not ring
    on it, ``python -m dftc_mujoco.calibrate``), the paper's 0.01 I without one."""
    if s.gains.G is not None:
        return np.asarray(s.gains.G, float)
    g = robot.calibration.get("compensation_G") if robot is not None else None
    return float(g or PAPER_G) * np.eye(2)


def compensation_bound(
    s: Scenario,
    robot: robots.RobotModel | None,
    models: tuple[robots.RobotModel, ...] = (),
    G: np.ndarray | None = None,
) -> float:
    """Φ̄: the bound on a healthy robot's ‖φ̂‖ (the fault estimator's ℓ1 gain from η̄ and ξ̄,
    with the drive's lag, the largest of the team's ``models``' lags; at the run's G, or at
    ``G``); inf without FDIR or compensation, or where the estimator's loop is unstable
    (refused elsewhere)."""
    if not (s.fdir.enabled and s.fdir.compensate):
        return np.inf
    try:
        return estimator_gain(
            np.asarray(s.gains.K),
            effective_G(s, robot) if G is None else G,
            s.physics.control_period,
            s.noise.eta_bar,
            effective_xi_bar(s, robot),
            lag=drive_lag(s, robot, models),
        )
    except ScenarioError:  # an unstable estimator loop is refused elsewhere
        return np.inf


def input_limit(command_limit: float, phi_bar: float, nominal: bool) -> float:
    """Per-axis range of the applied nominal input (``onboard/applied.py``).

    The command range less the compensation's headroom and the anti-windup's band: a
    healthy robot's ‖φ̂‖ stays within Φ̄ (``phi_bar``, :func:`compensation_bound`; inf: no
    compensation), so ū = u − φ̂ stays out of the band below the range the drive delivers,
    where the estimator's integral would be frozen (the premise 'saturation' then holds by
    design); at least half the range is kept for the mission. ``nominal`` (``fdir.input =
    "nominal"``) returns inf (no saturation).
    """
    if nominal or not np.isfinite(command_limit):
        return np.inf
    return max(command_limit - compensation_headroom(phi_bar), 0.5 * command_limit)


def compensation_headroom(phi_bar: float) -> float:
    """[m/s] What the compensation keeps free below a drive's per-axis range: a healthy
    robot's bound Φ̄ and the anti-windup's band (0 where Φ̄ is unknown)."""
    return phi_bar + ANTI_WINDUP_BAND if np.isfinite(phi_bar) else 0.0


def team_config(
    s: Scenario,
    robot: robots.RobotModel | None = None,
    command_limit: float = np.inf,
    initial_error_bound: float | None = None,
    models: tuple[robots.RobotModel, ...] = (),
) -> TeamConfig:
    """The onboard configuration a scenario gives every robot of model ``robot`` (the
    team's envelope; ``models``, one per robot, where each robot's own drive lag counts).

    A robot too big for a safe distance d (cylinder radius + its footprint +
    2 cm > d) gets the larger value, so no hull ever reaches a cylinder or an
    excluded robot, and its activation distance is raised by as much (the
    scenario's margin between the two is kept). ``command_limit`` is the per-axis
    planar command range; ``initial_error_bound`` ε̄ as derived for the run
    (:func:`dftc_mujoco.closed_loop.premises.initial_error_bound`; default: the scenario's, 1 m
    where it says "auto").
    """
    obs = s.obstacles
    f = s.fdir
    reach = robot.footprint_radius if robot is not None else 0.0
    safe = np.array([max(o.safe_distance, o.radius + reach + CLEARANCE) for o in obs])
    activation = np.array(
        [
            o.activation_distance + max(d - o.safe_distance, 0.0)
            for o, d in zip(obs, safe, strict=True)
        ]
    )
    excluded_safe = max(f.excluded_safe_distance, 2 * reach + CLEARANCE)
    sup = s.supervisor
    mate_safe = 0.0
    if sup.avoid_teammates:
        hull = reach if robot is not None else 0.1  # without a model: the built-in disk's
        auto = 2 * hull + CLEARANCE  # two hulls apart by the clearance
        mate_safe = auto if sup.teammate_distance == "auto" else float(sup.teammate_distance)
    phi_bar = compensation_bound(s, robot, models)
    applied = input_limit(command_limit, phi_bar, s.fdir.input == "nominal")
    seamless = seamless_margin(s.gains.theta, applied)
    return TeamConfig(
        graph=s.team.graph,
        kc=s.gains.kc,
        ko=s.gains.ko,
        K=np.asarray(s.gains.K),
        G=effective_G(s, robot),
        theta=s.gains.theta,
        dt=s.physics.control_period,
        eta_bar=s.noise.eta_bar,
        xi_bar=effective_xi_bar(s, robot),
        formation=s.mission.formation,
        obstacle_position=np.array([o.position for o in obs]).reshape(-1, 2),
        obstacle_safe=safe,
        obstacle_activation=activation,
        detection_window=f.detection_window,
        dt_d_max=f.dt_d_max,
        run_length=s.duration,
        isolation=f.isolation,
        reference_fault=f.reference_fault or s.mission.centroid.speed,
        initial_error_bound=(
            initial_error_bound
            if initial_error_bound is not None
            else (1.0 if f.initial_error_bound == "auto" else float(f.initial_error_bound))
        ),
        replan_time=f.replan_time,
        excluded_safe=excluded_safe,
        excluded_activation=max(f.excluded_activation_distance, excluded_safe + seamless),
        phi_low_pass=f.phi_low_pass,
        command_limit=command_limit,
        input_limit=applied,
        fdir=f.enabled,
        compensate=f.compensate,
        drift_bound=robot.drift_bound if robot is not None else 0.0,
        lag=drive_lag(s, robot, models),
        accel=drive_accel(s, robot),
        start_accel=START_ACCEL if s.fdir.start_ramp else np.inf,
        start_time=s.mission.centroid.ramp_time if s.fdir.start_ramp else 0.0,
        max_faults=max_faults(s),
        teammate_safe=mate_safe,
        teammate_activation=mate_safe + seamless if mate_safe > 0 else 0.0,
        self_exclusion=f.self_exclusion,
        postpone_on_contact=f.postpone_on_contact,
        confirm_by_estimate=f.confirm_by_estimate,
        response_time=robot.response_time if robot is not None else 0.0,
        phi_bar=phi_bar,
        rewire=rewire_mode(s),
        networked=not s.network.ideal,
        sighting_tolerance=sighting_tolerance(s),
        sighting_range=np.inf if s.network.sighting_range is None else s.network.sighting_range,
        seed=s.seed,
        round_periods=network.timing(s.network, s.physics.control_period).round,
    )


def sighting_tolerance(s: Scenario) -> float:
    """How far from its slot a silent robot's listeners tolerate it [m]: the scenario's
    ``network.sighting_tolerance``, or half the smallest distance between two slots ("auto":
    a robot that far is nearer another robot's slot than its own)."""
    tol = s.network.sighting_tolerance
    if tol != "auto":
        return float(tol)
    spacing = slot_spacing(s.mission.formation, s.team.graph.n)
    return spacing / 2 if np.isfinite(spacing) else 0.0


def max_faults(s: Scenario) -> int:
    """The fault hypothesis: the scenario's ``fdir.max_faults``, or 0 for "auto" (a minority
    of the team's members at each instant, :func:`~.onboard.recovery.admitted`): more robots
    flagged at once than that is a systemic anomaly, not faults."""
    if s.fdir.max_faults != "auto":
        return int(s.fdir.max_faults)
    return 0


#: [m/s²] the applied input's change at most, during the path's ramp from rest (a ramped
#: start), for a robot that avoids nothing (an avoiding robot brakes at its drive's own
#: acceleration): with the drives' calibrated accelerations (16 m/s² on the disk) the first
#: commands jumped, and the disk's 10 ms lag against them drifted beyond ē for 0.08 s (the
#: premise 'mismatch'); at 2 m/s² a differential drive started facing away from its first
#: command still broke the drive rule's Φ̄ while it turned (8 of 62 untuned runs); at 1 m/s²
#: one of the eight still did, for one period
START_ACCEL = 1.0


def drive_accel(s: Scenario, robot: robots.RobotModel | None) -> float:
    """a_max each robot holds its nominal input's change to: the scenario's
    ``fdir.drive_accel`` (0: none), or the robot file's calibrated one ("robot")."""
    if s.fdir.drive_accel != "robot":
        return float(s.fdir.drive_accel) or np.inf
    return robot.accel if robot is not None else np.inf


def drive_lag(
    s: Scenario,
    robot: robots.RobotModel | None,
    models: tuple[robots.RobotModel, ...] = (),
) -> float | np.ndarray:
    """τ of the drive lag the robots model: the scenario's ``fdir.drive_lag``, or the robot
    file's calibrated one ("robot"; 0 for a robot without one); in a team of ``models``
    (one per robot) whose lags differ, each robot's own (N,). The drive rule, whose Φ̄
    bounds ‖φ̂‖ at every period, models the best-fitting lag where the paper's rules take
    ẋ = u (``fast_lag``): unmodelled, the drive's response to every change of command
    reaches φ̂ as a mismatch beyond ξ̄."""
    if s.fdir.drive_lag != "robot":
        return float(s.fdir.drive_lag)
    if robot is None:
        return 0.0
    each = [_own_lag(s, m) for m in models]
    return np.array(each) if len(set(each)) > 1 else _own_lag(s, robot)


def _own_lag(s: Scenario, robot: robots.RobotModel) -> float:
    """The lag a robot of model ``robot`` models (``fdir.drive_lag = "robot"``)."""
    if robot.lag == 0.0 and s.onboard.thresholds == "drive":
        return robot.fast_lag
    return robot.lag


def block_names(s: Scenario, given: Mapping[str, Any] | None) -> dict[str, str]:
    """The name of each block a run uses: the scenario's, or for a given instance its
    built-in name (``"paper"``, ...) when it is one, else ``module:Class``."""
    _known(given)
    names = {k: getattr(s.onboard, k) for k in blocks_mod.BLOCKS}
    for k, b in (given or {}).items():
        cls = type(b)
        builtin = [n for n in blocks_mod.BUILTIN[k] if blocks_mod.load_class(k, n) is cls]
        names[k] = builtin[0] if builtin else f"{cls.__module__}:{cls.__qualname__}"
    return names


def _known(given: Mapping[str, Any] | None) -> None:
    """Refuse a given block under a name that is not a block's."""
    unknown = sorted(set(given or {}) - set(blocks_mod.BLOCKS))
    if unknown:
        raise ScenarioError(
            f"blocks: unknown block {unknown[0]!r}; expected one of {', '.join(blocks_mod.BLOCKS)}"
        )


def make_blocks(
    s: Scenario, given: Mapping[str, Block] | None = None, search: Sequence[Path] = ()
) -> dict[str, Block]:
    """Instances of the six blocks: ``given`` ones as they are, the rest from the scenario.

    A block named ``module:Class`` is imported from sys.path, else from the
    scenario file's folder, else from the folders ``search``.
    """
    given = dict(given or {})
    _known(given)
    out: dict[str, Block] = {}
    for k in blocks_mod.BLOCKS:
        if k in given:
            why = blocks_mod.not_a_block(k, given[k], f"blocks[{k!r}]")
            if why:
                raise ScenarioError(f"blocks: {why}")
            out[k] = given[k]
            continue
        name = getattr(s.onboard, k)
        out[k] = blocks_mod.create(
            k,
            name,
            s.onboard.params.get(k, {}),
            search=[d for d in (s.directory, *search) if d is not None],
            where=f"{s.source}: onboard.{k}",
        )
    return out


#: False skips the run-time premise checks (benchmarks/bench_premises.py measures their cost)


def rewire_mode(s: Scenario) -> str:
    """How the survivors' graph is re-wired after an exclusion (``fdir.rewire``): "adopt"
    (the default on the ideal network), "relay" (``fdir.excluded_relay = true``) or "none"
    (the default over a ``[network]``, whose radios carry only the scenario's links)."""
    f = s.fdir
    if f.excluded_relay:
        return "relay"
    if f.rewire == "auto":
        return "adopt" if s.network.ideal else "none"
    return f.rewire


def calibration_warnings(s: Scenario, model: robots.RobotModel, xi_bar: float) -> list[str]:
    """What the robot's calibration says of the scenario's noise and gains, one line each:
    a robot never calibrated, a ξ̄ below its measured mismatch, a robot that moves at a
    steady share of its commands, a G below its calibrated compensation gain (its
    compensation loop rings)."""
    out = []
    if s.noise.xi_bar is None and "xi_bar" not in model.calibration:
        out.append(
            f"the {model.name} model is not calibrated: xi_bar = {xi_bar:g} m/s is the "
            "paper's value, not a measurement of this robot (python -m "
            f"dftc_mujoco.calibrate {model.path} --write)"
        )
    if xi_bar < model.mismatch:
        out.append(
            f"noise.xi_bar = {xi_bar:g} m/s is below the {model.name} model's measured "
            f"mismatch ({model.mismatch:g} m/s, python -m dftc_mujoco.calibrate "
            f"{model.path}; recommended {model.xi_bar:g}): thresholds may raise "
            "false alarms"
        )
    share = model.calibration.get("tracking")
    if share is not None and not robots.TRACKING[0] <= share <= robots.TRACKING[1]:
        out.append(
            f"the {model.name} robots move at {share:.0%} of their commands "
            "(calibration.tracking): their drive model does not match their wheels, ξ̄ is "
            "spent on that shortfall and a fault of the mission's size may go unseen; "
            f"python -m dftc_mujoco.calibrate {model.path} says whether its "
            "wheels turn as asked (then look at how they meet the floor) or not (then at its "
            "servos)"
        )
    need_g = model.calibration.get("compensation_G")
    g = float(np.linalg.eigvalsh(effective_G(s, model)).min())
    if s.fdir.enabled and s.fdir.compensate and need_g and g < need_g:
        out.append(
            f"gains.G = {g:g} I is below the {model.name} model's calibrated compensation_G = "
            f"{need_g:g}: its compensation loop rings (healthy robots' phi_hat and commands "
            f'swing, thresholds raise false alarms); set gains.G = "auto" or at least {need_g:g}'
        )
    return out


#: multiples of the run's G tried for a drive whose range the compensation's headroom takes
G_WIDER = (2.0, 5.0, 10.0, 20.0, 50.0)


def wider_G(bound: Callable[[float], float], limit: float) -> tuple[float, float] | None:
    """The smallest multiple m of G in :data:`G_WIDER` whose Φ̄ = ``bound(m)`` leaves a drive
    of per-axis range ``limit`` room beside the compensation's headroom, and that Φ̄; None
    where none does (the run's warning and calibrate's choice of G share it)."""
    for m in G_WIDER:
        phi = bound(m)
        if compensation_headroom(phi) < limit:
            return m, phi
    return None


def _narrow_range(
    s: Scenario, model: robots.RobotModel, models: tuple[robots.RobotModel, ...], limit: float,
    phi_bar: float,
) -> str | None:  # fmt: skip
    """The warning for a drive whose whole command range the compensation's headroom (Φ̄ and
    the anti-windup's band, :func:`input_limit`) takes: nothing keeps a healthy robot's
    compensated command ū out of the band by design. It gives the smallest larger G
    (:data:`G_WIDER`) whose Φ̄ leaves the drive room, or says that none does."""
    if s.fdir.input == "nominal" or not (np.isfinite(limit) and np.isfinite(phi_bar)):
        return None
    headroom = compensation_headroom(phi_bar)
    if headroom < limit:
        return None
    G = effective_G(s, model)
    fits = wider_G(lambda m: compensation_bound(s, model, models, m * G), limit)
    if fits:
        m, phi = fits
        scalar = np.allclose(G, G[0, 0] * np.eye(len(G)))
        given = f"gains.G={m * G[0, 0]:.3g}" if scalar else f"gains.G {m:g} times larger"
        fix = (
            f"a larger G lowers Φ̄ (the fault estimate then settles more slowly): "
            f"--set {given} gives Φ̄ = {phi:.3g} m/s"
        )
    else:
        fix = (
            f"no G up to {G_WIDER[-1]:g} times the run's brings Φ̄ inside the range: the "
            f"robot's mismatch ξ̄ = {effective_xi_bar(s, model):.3g} m/s and the band take it "
            "(a drive with a wider range, or one that follows its commands closer)"
        )
    return (
        f"the {model.name} robots' command range of ±{limit:.3g} m/s per axis is no wider than "
        f"the compensation's headroom ({headroom:.3g} m/s: a healthy robot's bound Φ̄ = "
        f"{phi_bar:.3g} m/s and the anti-windup's {ANTI_WINDUP_BAND * 100:g} cm/s band): "
        "nothing keeps a healthy robot's compensated command ū out of the band by design; "
        "the run checks the threshold rules' premise 'saturation', and flags raised while "
        f"it is broken carry no guarantee; {fix}"
    )


def governed_text(s: Scenario, name: str, applied: float, flown: float) -> str:
    """The warning of a path flown slower than asked (:func:`~.mission.governed_speed`)."""
    return (
        f"mission.centroid.speed = {s.mission.centroid.speed:g} m/s leaves the {name} robots no "
        f"room in their applied range of ±{applied:.3g} m/s per axis (the command "
        "range less the compensation's headroom): the path is flown at "
        f"{flown:.3g} m/s, so that their commands stay inside it (summary: mission_speed)"
    )


def preflight(
    s: Scenario,
    model: robots.RobotModel,
    models: Sequence[robots.RobotModel],
    limit: float,
    config: TeamConfig,
    xi_bar: float,
    refusal: str | None,
    path: np.ndarray,
    dt: float,
    rule: str,
) -> list[str]:
    """Every check of scenario ``s`` against its robots (``model``: the team's envelope,
    ``models``: each robot's own) before the run: one :class:`~.errors.InputError` of every
    refusal (``refusal``: the start bound's, if any); returns the warnings. ``path`` is the
    desired centroid every control period ``dt``, ``rule`` the threshold rule's name."""
    from . import checks, premises

    every = max(1, round(0.1 / dt))  # the path every 0.1 s is enough to check it
    found = checks.preflight(
        s,
        model,
        limit,
        config.obstacle_safe,
        config.obstacle_activation,
        path[::every],
        every * dt,
        input_limit=config.input_limit,
        xi_bar=xi_bar,
        G=effective_G(s, model),
        footprints=np.array([m.footprint_radius for m in models]),
    )
    if refusal:
        found.refusals.append(refusal)
    narrow = _narrow_range(s, model, tuple(models), limit, config.phi_bar)
    found.warnings += [narrow] if narrow else []
    found.refusals += premises.rule_refusals(
        rule, s.fdir.compensate, s.fdir.phi_low_pass, str(s.source)
    )
    radio_refused, radio_warned = network.refusals(s, rule, str(s.source))
    found.refusals += radio_refused
    found.warnings += radio_warned
    found.raise_refusals()
    return found.warnings
