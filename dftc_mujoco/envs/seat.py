"""What a driven robot observes and how a step is taken: the part every environment
shares (one home for the episodes, the observation, the action, the reward and the labels).

An episode is one run of the scenario. Its random draws — the scenario's seed (the noise)
and, with ``vary``, its faults, start layout or any scenario key, in the vocabulary of a
campaign's ``[vary]`` table (:mod:`dftc_mujoco.campaign.spec`) — come from the seed the
environment is reset with, or, reset without one, from the stream of episodes the last
seed began (Gymnasium's convention): two resets with the same seed give the same episode,
two unseeded ones two different episodes.

The observation is what the robot knows, scaled to the order of 1 (:data:`FIELDS`: name,
size, meaning, scale). The reward is minus the robot's distance from its slot, in units of
the formation's spacing. The episode *terminates* when the driven robot is excluded by its
teammates, the team is reduced to one robot, or the physics fails; it is *truncated* at the
scenario's duration.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit

from ..closed_loop.loop import Simulation
from ..core.mission import slot_spacing
from ..errors import InputError
from ..onboard.thresholds.paper import dense_thresholds, factored_at
from ..scenario import Scenario, load_scenario

#: the observation's entries in order: (name, size, meaning, scale). ``N`` is the team size,
#: ``d`` the driven robot's in-neighbours in the scenario's graph (zeros once one has left)
FIELDS: tuple[tuple[str, str, str, str], ...] = (
    ("time", "1", "the mission time", "÷ the scenario's duration"),
    ("slot", "2", "the robot's desired slot, from the formation's centre", "÷ the slots' spacing"),
    ("slot_error", "2", "its measured position minus its slot", "÷ the slots' spacing"),
    ("command", "2", "the team's command for it (ū, eq. 28) last period", "÷ the command range"),
    ("fault_estimate", "2", "its own fault estimate φ̂ (eq. 30)", "÷ the command range"),
    ("neighbours", "2d", "its in-neighbours' estimated positions, from its own", "÷ the spacing"),
    ("residual", "N", "‖ⁱr_k‖ / ⁱμ_k for every robot k, at most 4", "÷ 4"),
    ("flags", "N", "the robots it flags", "0 or 1"),
    ("active", "N", "the robots still in the team", "0 or 1"),
)
#: the driven robot's action: its planar velocity [m/s], or a correction of the team's command
ACTIONS = ("velocity", "correction")
#: a residual ratio beyond this says no more (the observation's ``residual``)
RATIO_CAP = 4.0
#: [vary] keys an episode may not draw: they change the team, hence the observation's size
FIXED = ("robots", "graph_family")
#: every entry of an observation is within ±BIG (a robot lost kilometres away says no more)
BIG = 1000.0


def scenario_of(scenario: Any) -> Scenario:
    """A :class:`Scenario` from a name, a path or a Scenario."""
    if isinstance(scenario, Scenario):
        return scenario
    if isinstance(scenario, str | Path):
        return load_scenario(scenario)
    raise InputError(f"expected a scenario name, path or Scenario, got {type(scenario).__name__}")


class Seats:
    """Runs of a scenario in which the robots ``driven`` (0-based) take their commands from
    a policy (``action``: "velocity", or "correction" added to the team's own command);
    ``vary`` draws each episode's faults, starts or scenario keys (a campaign's ``[vary]``
    table, every key but the team's size and graph)."""

    def __init__(
        self,
        scenario: Any,
        driven: list[int],
        vary: Mapping[str, Any] | None = None,
        action: str = "velocity",
    ) -> None:
        base = scenario_of(scenario)
        n = base.team.robots
        bad = [r + 1 for r in driven if not 0 <= r < n]
        if bad or not driven:
            raise InputError(
                f"robots to drive: expected numbers in 1..{n}, got {[r + 1 for r in driven]}"
            )
        if action not in ACTIONS:
            raise InputError(f"action: expected one of {', '.join(ACTIONS)}, got {action!r}")
        self.base, self.n, self.driven, self.action = base, n, list(driven), action
        self.episodes = _episodes(base, vary) if vary else None
        self.scenario = base
        g = base.team.graph
        self.heard = {i: sorted(g.in_neighbours(i)) for i in driven}
        self.spacing = slot_spacing(base.mission.formation, n)
        if not np.isfinite(self.spacing):
            self.spacing = 1.0
        self.sim = Simulation(base)
        limit = float(self.sim.command_limit)
        self.limit = limit if np.isfinite(limit) else 2.0  # the drive's range, per axis
        self._obs = {i: np.zeros(self.size(i), np.float32) for i in driven}
        self._heard = {i: np.array(self.heard[i], dtype=np.int64) for i in driven}
        self._rows: np.ndarray | None = None  # each robot's member position (-1: excluded)
        self._rewarded: dict[int, tuple[int, float]] = {}  # robot -> (period, its reward)
        self._members = 0

    def close(self) -> None:
        """Release the simulation."""
        self.sim.close()

    # ------------------------------------------------------------------ episodes

    def size(self, i: int) -> int:
        """The length of robot ``i``'s observation."""
        return 1 + 2 + 2 + 2 + 2 + 2 * len(self.heard[i]) + 3 * self.n

    def reset(self, seed: int) -> None:
        """Start the episode whose draws ``seed`` (a whole number ≥ 0) fixes."""
        if self.episodes is None:
            self.sim.reset(seed)
        else:  # this episode's faults, starts, keys: drawn as a campaign draws a run
            import dataclasses

            from ..campaign import spec as spec_mod

            episode = dataclasses.replace(self.episodes, seed=seed)
            self.scenario = spec_mod.scenario_for(episode, spec_mod.draw(episode, 0))
            self.sim.close()
            self.sim = Simulation(self.scenario)
        for i in self.driven:
            self.sim.drive(i, None)
        self._rows = None
        self._rewarded.clear()
        self._labels = [(f.robot, f.kind, f.t, f.end) for f in self.scenario.faults]
        # the labels change only where a fault begins or ends: kept between those instants
        self._edges = sorted({e for f in self._labels for e in f[2:] if math.isfinite(e)})
        self._labelled: tuple[float, float, np.ndarray, list[str]] = (0.0, -1.0, np.zeros(0), [])

    def step(self, actions: Mapping[int, np.ndarray]) -> None:
        """One control period with each driven robot commanded ``actions[i]`` (clipped to
        the drive's range, ±inf too); a NaN is a policy's bug, refused (ValueError)."""
        u_bar, lim = self.sim.team.u_bar, self.limit
        for i, a in actions.items():
            try:
                if type(a) is np.ndarray and a.shape == (2,) and a.dtype.kind == "f":
                    v0, v1 = a.tolist()  # a policy's own array
                else:
                    v0, v1 = (float(c) for c in np.asarray(a, dtype=float).reshape(2))
            except (TypeError, ValueError):
                raise ValueError(
                    f"the action for robot {i + 1} is {a!r}: expected a planar velocity of 2 "
                    "numbers in m/s"
                ) from None
            if v0 != v0 or v1 != v1:  # NaN: it was driven at 0 m/s in silence
                raise ValueError(
                    f"the action for robot {i + 1} is {[v0, v1]}: expected a planar velocity "
                    f"in m/s (clipped to ±{lim:g})"
                )
            if self.action == "correction":  # on top of what its own blocks command
                v0, v1 = v0 + u_bar[i, 0], v1 + u_bar[i, 1]
            self.sim.drive(i, (min(max(v0, -lim), lim), min(max(v1, -lim), lim)))
        self.sim.advance(1)

    @property
    def truncated(self) -> bool:
        """The episode reached the scenario's duration."""
        return self.sim.finished

    def terminated(self, i: int) -> bool:
        """Robot ``i``'s episode is over before the duration: it was excluded, the team was
        reduced to one robot, or the physics failed."""
        sim = self.sim
        return bool(
            not sim.team.active[i]
            or sim.team.ended is not None
            or sim.error is not None
            or sim.left is not None
        )

    # ------------------------------------------------------------------ what a robot knows

    def observe(self, i: int) -> np.ndarray:
        """Robot ``i``'s observation (:data:`FIELDS`), float32, after the last period (the
        array is the environment's own: copy it to keep it)."""
        sim, team = self.sim, self.sim.team
        m = len(team.members)
        if self._rows is None or self._members != m:
            self._members = m  # member positions change at an exclusion only
            self._rows = np.full(self.n, -1, dtype=np.int64)
            self._rows[team.members] = np.arange(m)
        th = team.threshold_factors  # eq. 40's factors where the compiled period read them
        if th is None:
            th = dense_thresholds(np.ascontiguousarray(team.mu, dtype=float))
        reward = _observe(
            self._obs[i],
            sim.t / self.scenario.duration,
            self._rows,
            i,
            self._heard[i],
            sim.measurements,
            team.x_d,
            team.u_bar,
            team.phi_hat,
            team.x_hat,
            np.asarray(team.r_norm),
            th.dense,
            th.coef,
            th.bound,
            th.finite,
            th.eta,
            np.asarray(team.flag),
            team.active,
            self.spacing,
            self.limit,
            sim.positions,
        )
        self._rewarded[i] = (sim.k, reward)
        return self._obs[i]

    def reward(self, i: int) -> float:
        """Minus robot ``i``'s true distance from its slot, in slots' spacings (0 once it is
        excluded)."""
        k, reward = self._rewarded.get(i, (-1, 0.0))
        if k != self.sim.k:  # written with the observation: observed after this period
            self.observe(i)
            k, reward = self._rewarded[i]
        return reward

    def info(self, i: int) -> dict[str, Any]:
        """The period's time, its events (robots numbered from 1), ``dftc_command`` (what the
        team's blocks commanded robot ``i`` in the period just stepped, which a policy may
        follow or correct in the next) and the faults in force now: ``faulty`` (N,) bool
        and ``fault_kind`` (N,) str ("" for none), robots on the original axis."""
        sim = self.sim
        t = sim.t - sim.dt if sim.k else 0.0
        lo, hi, faulty, kinds = self._labelled
        if not lo <= t < hi:
            k = bisect.bisect_right(self._edges, t)
            lo = self._edges[k - 1] if k else -math.inf
            hi = self._edges[k] if k < len(self._edges) else math.inf
            self._labelled = (lo, hi, *self._label(t))
            faulty, kinds = self._labelled[2:]
        return {
            "t": t,
            "events": sim.new_events(),
            "dftc_command": np.array(sim.team.u_bar[i], dtype=np.float32),
            "faulty": faulty.copy(),
            "fault_kind": list(kinds),
        }

    def _label(self, t: float) -> tuple[np.ndarray, list[str]]:
        """The faults in force at ``t``: ``faulty`` (N,) and ``fault_kind`` (N,)."""
        faulty = np.zeros(self.n, bool)
        kinds = [""] * self.n
        for robot, kind, start, end in self._labels:
            if start <= t < end:
                faulty[robot] = True
                kinds[robot] = kind if not kinds[robot] else f"{kinds[robot]}+{kind}"
        return faulty, kinds


@njit(cache=True)
def _observe(
    out, time, rows, i, heard, x_m, x_d, u_bar, phi_hat, x_hat, r_norm, dense, coef, bound,
    finite, eta, flag, active, spacing, limit, x,
):  # fmt: skip  # pragma: no cover - compiled
    """:data:`FIELDS` of robot ``i`` into ``out`` (float32): ``rows`` maps a robot to its
    member position (-1: excluded), ``heard`` its in-neighbours; the team's arrays as
    :class:`~dftc_mujoco.onboard.execution.team.Team` keeps them (members' axis, or the robots' for
    ``u_bar``, ``phi_hat``, ``active``); the thresholds ⁱμ_k as the compiled period reads
    them (:class:`~dftc_mujoco.onboard.thresholds.paper.ThresholdRecord`: ``dense``, or
    eq. 40's factors). Excluded robots and a robot's lost neighbours read 0; every entry
    is clipped to ±:data:`BIG`. Returns the reward: minus the robot's true distance (``x``
    (N, 2): the true positions) from its slot, in spacings (0 once it is excluded)."""
    n = rows.shape[0]
    reward = 0.0
    for k in range(out.shape[0]):
        out[k] = 0.0
    out[0] = time
    p = rows[i]
    if p >= 0:
        m = x_d.shape[0]
        for d in range(2):
            centre = 0.0
            for q in range(m):
                centre += x_d[q, d]
            out[1 + d] = (x_d[p, d] - centre / m) / spacing  # its slot from the centre
            out[3 + d] = (x_m[i, d] - x_d[p, d]) / spacing  # its error to it
            out[5 + d] = u_bar[i, d] / limit
            out[7 + d] = phi_hat[i, d] / limit
        k = 9
        for j in heard:
            q = rows[j]
            if q >= 0:
                for d in range(2):
                    out[k + d] = (x_hat[p, q, d] - x_m[i, d]) / spacing
            k += 2
        for robot in range(n):
            q = rows[robot]
            if q < 0:
                continue
            mu = dense[p, q] if dense.shape[0] else factored_at(coef, bound, finite, eta, p, q)
            ratio = r_norm[p, q] / mu if mu > 0 else 0.0
            if not ratio >= 0.0:  # NaN
                ratio = 0.0
            out[k + robot] = min(ratio, RATIO_CAP) / RATIO_CAP
            out[k + n + robot] = 1.0 if flag[p, q] else 0.0
        k += 2 * n
        for robot in range(n):
            out[k + robot] = 1.0 if active[robot] else 0.0
        reward = -math.hypot(x[i, 0] - x_d[p, 0], x[i, 1] - x_d[p, 1]) / spacing
    for k in range(out.shape[0]):
        out[k] = min(max(out[k], -BIG), BIG)
    return reward


def _episodes(base: Scenario, vary: Mapping[str, Any]) -> Any:
    """The campaign spec an episode's draws come from (``vary``: a campaign's ``[vary]``
    table, refused in one line where it would change the team)."""
    from ..campaign import spec as spec_mod

    fixed = [k for k in FIXED if k in vary]
    if fixed:
        raise InputError(
            f"vary.{fixed[0]}: an episode cannot change the team (its observation's size); "
            "make one environment per team"
        )
    return spec_mod.episodes(base, vary)
