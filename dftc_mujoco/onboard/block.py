"""What every onboard block shares: the team's configuration and the block interface.

A block is one concept of the paper's Fig. 1 (observer, controller,
supervisor, fault estimator, thresholds, decision) for the whole team at once:
its arrays carry a leading axis over the team's members, and row i is robot
i's onboard computation. Row i may use only what robot i knows: its own
measurement, inputs and state, the messages of its in-neighbours, what its
own sensors see and the mission every robot is given
(:func:`dftc_mujoco.onboard.execution.locality.check` tests a block set for it).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from ..core.graph import Graph
from ..core.mission import Formation


def _compiled_by_default() -> bool:
    """Whether a team composes the compiled period by default: unless ``DFTC_PERIOD`` says
    ``general`` (:mod:`dftc_mujoco.closed_loop.execution` reads the same variable for a run)."""
    return os.environ.get("DFTC_PERIOD", "").strip().lower() != "general"


@dataclass(frozen=True)
class TeamConfig:
    """Everything the onboard stacks are configured with (no simulator state)."""

    graph: Graph
    kc: float
    ko: float
    K: np.ndarray
    G: np.ndarray
    theta: float
    dt: float  # control period
    eta_bar: float
    xi_bar: float
    formation: Formation
    obstacle_position: np.ndarray  # (O, 2) what the robots' sensors report
    obstacle_safe: np.ndarray  # (O,) d of eq. 17
    obstacle_activation: np.ndarray  # (O,)
    detection_window: float = 0.2
    dt_d_max: float | str = 5.0  # or "auto": eq. 46 (onboard/thresholds/delays.py)
    # [s] how long the run lasts: "auto" seeks eq. 46's delays no further (a Δt_d,max
    # longer than the run changes nothing in it: no exclusion can follow a flag)
    run_length: float = np.inf
    isolation: str = "pairwise"  # "exclusive", "exclusive_history" (eq. 39, decision.py)
    reference_fault: float = 0.1  # [m/s] constant fault size "auto" sizes Δt_d,max for
    initial_error_bound: float = 1.0  # ε̄ [m] in the rule's own meaning (closed_loop/premises.py)
    replan_time: float = 4.0
    excluded_safe: float = 0.35  # d around a robot that was excluded (it is still a body)
    excluded_activation: float = 0.45
    phi_low_pass: float = 0.0
    command_limit: float = np.inf  # per-axis planar command range of the robots [m/s]
    # per-axis range of the applied nominal input uᵢ (onboard/applied.py) [m/s]: the command
    # range less the compensation's headroom; inf keeps the nominal input (fdir.input)
    input_limit: float = np.inf
    accel: float = np.inf  # [m/s²] the drive's acceleration, applied to u (onboard/applied.py)
    # a ramped start: until start_time [s], u changes by at most start_accel [m/s²]
    start_accel: float = np.inf
    start_time: float = 0.0
    # teammates avoided by the supervisor within this safe distance [m] (0: not avoided)
    teammate_safe: float = 0.0
    teammate_activation: float = 0.0
    # robots that may be faulty at once (fdir.max_faults, recovery.py); 0: "auto", a minority
    # of the members at that instant, ⌊(M − 1)/2⌋
    max_faults: int = 1
    self_exclusion: bool = False  # a robot's own flag counts towards its exclusion (eq. 43)
    postpone_on_contact: bool = True  # a bumper contact postpones t_r (onboard/recovery.py)
    # an exclusion needs the robot's own estimate out of Φ̄ at t_r, for longer than a healthy
    # robot's own response (onboard/estimate_alarm.py)
    confirm_by_estimate: bool = True
    response_time: float = 0.0  # [s] the drive's time to follow a command jump (calibration)
    phi_bar: float = np.inf  # Φ̄ [m/s]: a healthy robot's ‖φ̂‖ bound (inf: none known)
    # after an exclusion (graph.without): "adopt" (the survivors take over the excluded
    # robot's links), "relay" (its radio forwards them) or "none" (they go with it)
    rewire: str = "none"
    # [s] first-order lag of the drive the robots model (onboard/applied.py): one for all,
    # or each robot's (N,) in a mixed team
    lag: float | np.ndarray = 0.0
    # compose the paper's blocks in one compiled period when possible (DFTC_PERIOD=general in
    # the environment: never, the blocks' own methods; dftc_mujoco.closed_loop.execution)
    compiled: bool = field(default_factory=_compiled_by_default)
    # the compiled period's pass over the N × N state runs in this many threads
    # (execution/sharing.py) from shared_from members on (dftc_mujoco.closed_loop.execution)
    threads: int = 1
    shared_from: int = 150
    fdir: bool = True  # False: nominal DFTC only (no compensation, no decisions)
    compensate: bool = True  # False: φ̂ estimated but not applied (ū = u)
    drift_bound: float = 0.0  # ē [m]: bounded offset of a robot's drift (from calibration)
    # the network (dftc_mujoco.closed_loop.network): the observers step in rounds of this
    # many control periods, on the last message each link delivered; False/1: the paper's
    # ideal network
    networked: bool = False
    round_periods: int = 1
    # a silent robot's listeners flag it when they see it this far from its slot [m] (0: never)
    # within this reach [m] (onboard/sighting.py)
    sighting_tolerance: float = 0.0
    sighting_range: float = np.inf
    seed: int = 0  # the scenario's seed: each block's own random stream derives from it

    @property
    def observer_period(self) -> float:
        """h_o [s]: the observers' step, a round of ``round_periods`` control periods."""
        return self.dt * self.round_periods if self.round_periods > 1 else self.dt


class Block:
    """Base of the onboard blocks (the six of Fig. 1 and the detector).

    A block is created with its own keyword parameters (``[onboard.params.X]``
    in a scenario), then :meth:`reset` gives it the team (at the start of every
    run) and :meth:`drop` tells it a robot left the team (an exclusion,
    eq. 43). Subclass one of :mod:`dftc_mujoco.blocks.paper` and override its
    documented methods to try your own.
    """

    kind: str = ""  # which plug-in point this block fills
    #: the time [s] of the control period being stepped (set by the team before each period)
    t: float = 0.0
    #: the block's own random stream, from the scenario's seed and the block's kind (set by
    #: the team at the start of a run): reproducible, and independent of the other blocks'
    rng: np.random.Generator | None = None

    def reset(self, config: TeamConfig, x_m0: np.ndarray, prior: np.ndarray) -> None:
        """Start a run: ``config`` of the team, members' first measurements ``x_m0`` (N, n)
        and the planned slots ``prior`` (N, n) every robot is given."""

    def drop(self, p: int, graph: Graph, t: float) -> None:
        """The member at team position ``p`` was excluded at ``t``; ``graph`` is the new one."""

    def __repr__(self) -> str:
        return f"{type(self).__module__}.{type(self).__qualname__}()"


class BadOutput(ValueError):
    """What a block's method returned cannot be used (the general path checks each output,
    :mod:`.general`): of another shape than the period needs (numpy would broadcast it into
    nonsense and the run go on as if nothing were wrong), or not finite where it must be
    (MuJoCo would stop the run later, at the actuators, blaming no block). ``block`` is the
    block that returned it."""

    def __init__(self, block: Block, text: str) -> None:
        super().__init__(text)
        self.block = block


def shaped(value: object, shape: tuple[int, ...], block: Block, method: str) -> np.ndarray:
    """``value`` as an array of ``shape`` (BadOutput otherwise)."""
    out = value if type(value) is np.ndarray else np.asarray(value)
    if out.shape != shape:
        raise BadOutput(block, f"returned from {method} shape {out.shape}, expected {shape},")
    return out


def blame_not_finite(outputs: list[tuple[np.ndarray, Block, str]]) -> None:
    """BadOutput for the first of ``outputs`` ((value, block, method), in the order the
    period computed them) that holds a value that is not finite; nothing if none does."""
    for value, block, method in outputs:
        bad = np.argwhere(~np.isfinite(value))
        if len(bad):
            where = tuple(int(j) for j in bad[0])
            said = f"{value[where]} at index {where}, expected a finite number,"
            raise BadOutput(block, f"returned from {method} {said}")
