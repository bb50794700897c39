"""The parts of a scenario: one frozen dataclass per table of the file (the mission's own types
live in :mod:`dftc_mujoco.core.mission`)."""

from __future__ import annotations

import copy
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..core.graph import Graph
from ..runtime.tomlcheck import _ro


class _ReadOnlyMap(Mapping[str, Any]):
    """A read-only (and picklable) mapping."""

    __slots__ = ("_data",)

    def __init__(self, data: Mapping[str, Any] | None = None):
        self._data = dict(data or {})

    def __getitem__(self, key: str) -> Any:
        return self._data[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __repr__(self) -> str:
        return repr(self._data)

    def __reduce__(self) -> tuple[Any, ...]:
        return (_ReadOnlyMap, (self._data,))

    def __hash__(self) -> int:  # equal mappings have equal keys (values may be lists)
        return hash(frozenset(self._data))


@dataclass(frozen=True)
class Physics:
    """Integration settings: MuJoCo timestep, control period and log rate."""

    timestep: float = 0.002
    control_period: float = 0.01
    log_rate: float = 50.0
    robot_contacts: bool = True
    # rate of the N × N fields (estimates, residuals, thresholds) [Hz], or "auto": the
    # log rate while they fit in MATRIX_LOG_BUDGET bytes, less for large teams
    matrix_log_rate: float | str = "auto"

    @property
    def substeps(self) -> int:
        """MuJoCo steps per control period."""
        return round(self.control_period / self.timestep)


@dataclass(frozen=True, eq=False)
class Team:
    """The robots, their model, initial positions and communication graph."""

    robots: int
    robot_model: str | tuple[str, ...]  # one model, or one per robot (a mixed team)
    initial_positions: np.ndarray  # (N, 2)
    graph: Graph
    graph_family: str = "explicit"  # or ring_chords, random, knn when generated

    @property
    def models(self) -> tuple[str, ...]:
        """Each robot's model name or file (N,)."""
        if isinstance(self.robot_model, str):
            return (self.robot_model,) * self.robots
        return tuple(self.robot_model)


@dataclass(frozen=True, eq=False)
class Gains:
    """Controller, observer, fault-estimator and avoidance gains (eqs. 15, 19, 29, 30, 18)."""

    kc: float
    ko: float
    K: np.ndarray  # (2, 2), symmetric positive definite
    G: np.ndarray | None  # (2, 2), symmetric positive definite; None ("auto"): the robot's
    theta: float


@dataclass(frozen=True)
class Noise:
    """Bounds of measurement noise (eq. 4) and disturbance (eq. 2)."""

    eta_bar: float
    xi_bar: float | None  # None: the robot model's measured mismatch
    xi_time_constant: float = 0.5
    at_bound: bool = False  # draw η and ξ with norms exactly at η̄ and ξ̄


@dataclass(frozen=True, eq=False)
class Obstacle:
    """A vertical cylinder; ``safe_distance`` is d of eq. 17 (robot centre to cylinder axis)."""

    position: np.ndarray  # (2,)
    radius: float
    safe_distance: float
    activation_distance: float
    height: float = 0.3


@dataclass(frozen=True, eq=False)
class Fault:
    """A fault of ``robot`` (0-based) starting at ``t``: of its actuators (``"bias"``,
    ``"stop"``) or of its position sensor (:data:`SENSOR_FAULTS`).

    ``value`` and ``time_constant`` describe a bias; a stop fault keeps them at
    zero (a file may give them for a stop fault only as zeros).
    ``"loss_of_effectiveness"``: the actuators deliver ``value[0]`` (0–1) of their command;
    ``"intermittent"``: a stop during the first ``duty`` (0–1) of every ``period`` [s];
    ``"drift"``: a bias growing as ``value`` × (t − t_f) (``value`` in m/s²); ``"stuck"``: the
    actuators keep the commands they had at ``t``. A
    sensor fault adds to the robot's measured position ``value`` [m] (``"sensor_bias"``) or
    ``value`` × (t − t_f) (``"sensor_drift"``, ``value`` in m/s). Every fault lasts until
    ``end`` (inf: to the end of the run).
    """

    robot: int
    kind: str  # "bias", "stop", "sensor_bias" or "sensor_drift"
    t: float
    value: np.ndarray = field(default_factory=lambda: _ro([0.0, 0.0]))
    time_constant: float = 0.0
    end: float = float("inf")
    period: float = 0.0  # intermittent
    duty: float = 0.0


#: the faults of a robot's position sensor (acting on its measurement, eq. 4)
SENSOR_FAULTS = ("sensor_bias", "sensor_drift")
ACTUATOR_FAULTS = ("bias", "stop", "loss_of_effectiveness", "intermittent", "drift", "stuck")


#: the kinds of radio fault ``[[faults]]`` may name (actuator faults: "bias", "stop")
RADIO_FAULTS = ("silent", "link_down", "corrupt")


@dataclass(frozen=True)
class RadioFault:
    """A fault of the network, not of the actuators, from ``t`` on: robot ``robot``'s radio
    falls ``"silent"`` (it sends nothing), the link ``link`` = (from, to) (0-based) goes
    ``"link_down"``, or robot ``robot`` sends ``"corrupt"`` estimates (``value`` [m] added
    to every entry of each message it sends)."""

    kind: str
    t: float
    robot: int = -1  # silent, corrupt
    link: tuple[int, int] = (-1, -1)  # link_down
    value: float = 0.0  # corrupt


@dataclass(frozen=True)
class Network:
    """The medium between the robots' radios (the ``[network]`` table; :mod:`..network`).

    Every default is today's ideal network: each message sent at the end of a period
    arrives at the start of the next, none is lost, every link of the graph exists. A
    message is delayed by ``latency`` [s] (or by a random delay of mean ``latency`` up to
    ``latency_max``), sent ``rate`` times a second (None: every period), lost with
    probability ``loss`` (``loss_model`` "bernoulli", or "gilbert_elliott" with the bursts
    ``p_bad`` (good → bad), ``p_good`` (bad → good) and ``loss_bad`` in the bad state), but
    never more than ``max_consecutive_losses`` in a row on a link (the declared bound b;
    None: no bound). ``link_loss`` sets the loss probability of single links
    (``[[network.links]]``, the rest keep ``loss``). ``range`` [m] limits a link to robots
    that close (None: no limit); a link that left the range comes back within
    ``range − range_hysteresis``. ``link_latency`` sets a fixed latency [s] on single
    links (``[[network.links]]``; the rest keep ``latency``). A silent robot's listeners
    flag it when they see it farther than ``sighting_tolerance`` [m] from its slot ("auto":
    half the smallest distance between two slots) within ``sighting_range`` [m] of them
    (None: no limit; 0: no sightings; onboard/sighting.py).
    """

    latency: float = 0.0
    latency_max: float | None = None  # None: the latency is fixed
    rate: float | None = None
    loss: float = 0.0
    loss_model: str = "bernoulli"
    p_bad: float = 0.0
    p_good: float = 1.0
    loss_bad: float = 1.0
    max_consecutive_losses: int | None = None
    range: float | None = None
    range_hysteresis: float = 0.0
    faults: tuple[RadioFault, ...] = ()
    # per-link loss probabilities ((from, to), 0-based) replacing ``loss`` on those links
    link_loss: tuple[tuple[tuple[int, int], float], ...] = ()
    link_latency: tuple[tuple[tuple[int, int], float], ...] = ()  # [s] per link, fixed
    sighting_tolerance: float | str = "auto"
    sighting_range: float | None = None
    # [s] the window over which the links that delivered must keep the graph strongly
    # connected (premise "connectivity"; None: the 2 rounds after which a link is silent)
    connectivity_window: float | None = None

    @property
    def ideal(self) -> bool:
        """True when every message arrives in the next period, none is lost or corrupted,
        and every link exists: the paper's network (rounds of one period)."""
        return (
            self.latency == 0.0
            and not self.latency_max
            and self.rate is None
            and self.loss == 0.0
            and (self.loss_model == "bernoulli" or self.p_bad == 0.0)
            and self.range is None
            and not self.faults
            and not any(p > 0 for _, p in self.link_loss)
            and not any(d > 0 for _, d in self.link_latency)
        )

    @property
    def lossy(self) -> bool:
        """Some message may be lost by the channel itself (radio faults aside)."""
        return (
            self.loss > 0.0
            or (self.loss_model == "gilbert_elliott" and self.p_bad > 0.0)
            or any(p > 0 for _, p in self.link_loss)
        )


@dataclass(frozen=True)
class Fdir:
    """Fault detection, isolation and recovery settings (eqs. 39-43).

    ``enabled = false`` runs the nominal DFTC only (no compensation, no
    decisions), to compare against.
    """

    detection_window: float = 0.2
    dt_d_max: float | str = 5.0  # Δt_d,max [s], or "auto": from the analysis (eq. 46)
    # ε̄ [m], or "auto": derived from the start positions and the planned slots
    # (closed_loop/premises.py)
    initial_error_bound: float | str = "auto"
    replan_time: float = 4.0
    excluded_safe_distance: float = 0.35
    excluded_activation_distance: float = 0.45
    phi_low_pass: float = 0.0
    enabled: bool = True
    compensate: bool = True  # false: φ̂ is estimated and logged but not applied
    isolation: str = "pairwise"  # "exclusive": eq. 39's 2nd clause now; "exclusive_history": ever
    reference_fault: float = 0.0  # [m/s] the fault Δt_d,max = "auto" is sized for (0: path speed)
    # the input that enters y_m, Δu and the fault estimator: "applied" (the nominal input
    # after the robot's own command limits, Remark 4.1) or "nominal" (as computed, eq. 8)
    input: str = "applied"
    # τ [s] of the first-order drive lag each robot models (onboard/applied.py), or "robot":
    # the robot file's calibrated [calibration] lag (0 when it has none: ẋ = u)
    drive_lag: float | str = "robot"
    # a_max [m/s²] each robot holds its nominal input's change to (onboard/applied.py), or
    # "robot": the robot file's calibrated [calibration] accel (none when it has none); 0: none
    drive_accel: float | str = "robot"
    # a ramped start: during the path's ramp from rest, each robot's input changes by at
    # most assembly.START_ACCEL (the drives' lag against a jump breaks the premise 'mismatch')
    start_ramp: bool = True
    # how many robots may be faulty at once, or "auto": ⌊(N − 1)/2⌋ (onboard/recovery.py)
    max_faults: int | str = "auto"
    self_exclusion: bool = False  # a robot's own flag counts towards its exclusion (eq. 43)
    postpone_on_contact: bool = True  # a bumper contact postpones the exclusion instant t_r
    # exclude a flagged robot only if its own fault estimate left its healthy bound Φ̄ (or its
    # command the drive's range) for a decision window since its first flag
    # (onboard/estimate_alarm.py)
    confirm_by_estimate: bool = True
    excluded_relay: bool = False  # an excluded robot keeps relaying its neighbours' messages
    # after an exclusion: "adopt" (each robot that heard the excluded one hears the robots
    # it heard, directly), "relay" (the excluded robot's radio forwards them), "none" (its
    # links go with it), or "auto": adopt on the ideal network, none over a [network]
    rewire: str = "auto"


@dataclass(frozen=True)
class Supervision:
    """The supervisor's reactive behaviours beside the cylinders (the ``[supervisor]`` table).

    ``avoid_teammates``: each robot avoids the teammates its range sensor sees, in the null
    space like an obstacle (eqs. 17-18), so the residuals are unaffected; false keeps the
    paper's exact behaviour. ``teammate_distance``: the safe distance between two robots'
    control points [m], or "auto": twice the robot's footprint plus 2 cm.
    """

    avoid_teammates: bool = True
    teammate_distance: float | str = "auto"


@dataclass(frozen=True)
class Onboard:
    """The onboard blocks of the paper's Fig. 1 (the ``[onboard]`` table).

    Each block is ``"paper"`` (the built-in implementation) or an import path
    ``"module:Class"`` (see :mod:`dftc_mujoco.blocks`); ``thresholds`` is ``"auto"`` by
    default, the rule whose premises the team's robots meet (``assembly.threshold_rule``).
    ``params`` maps a block name to the keyword arguments its class is created with
    (``[onboard.params.<block>]``); both levels are read-only.
    """

    observer: str = "paper"
    controller: str = "paper"
    supervisor: str = "paper"
    fault_estimator: str = "paper"
    thresholds: str = "auto"
    detector: str = "paper"
    decision: str = "paper"
    params: Mapping[str, Mapping[str, Any]] = field(default_factory=_ReadOnlyMap)

    def __post_init__(self) -> None:
        if isinstance(self.params, Mapping):  # anything else is reported by validation
            frozen = {
                block: _ReadOnlyMap(copy.deepcopy(dict(kw))) if isinstance(kw, Mapping) else kw
                for block, kw in self.params.items()
            }
            object.__setattr__(self, "params", _ReadOnlyMap(frozen))
