"""What a driven robot observes and how a step is taken: the part every environment
shares (one home for the observation, the action's range and the reward)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..loop import Simulation, Snapshot
from ..scenario import Scenario, load_scenario

#: observation entries: the robot's own measurement (2), its estimate of every robot
#: (N × 2), its residual norm and threshold for every robot (N each), its flags (N), and the
#: messages of its in-neighbours, each an estimate of the team (d × N × 2)
FIELDS = ("measurement", "estimate", "residual", "threshold", "flags", "messages")
#: every entry is within ±BIG (a threshold that is +inf, a robot that cannot be judged, is BIG)
BIG = 1e6


def scenario_of(scenario: Any) -> Scenario:
    """A :class:`Scenario` from a name, a path or a Scenario."""
    if isinstance(scenario, Scenario):
        return scenario
    if isinstance(scenario, str | Path):
        return load_scenario(scenario)
    raise InputError(f"expected a scenario name, path or Scenario, got {type(scenario).__name__}")


class Seats:
    """A run in which the robots ``driven`` (0-based) take their commands from a policy."""

    def __init__(self, scenario: Any, driven: list[int]) -> None:
        self.scenario = scenario_of(scenario)
        n = self.scenario.team.robots
        bad = [r + 1 for r in driven if not 0 <= r < n]
        if bad or not driven:
            raise InputError(
                f"robots to drive: expected numbers in 1..{n}, got {[r + 1 for r in driven]}"
            )
        self.n, self.driven = n, list(driven)
        self.sim = Simulation(self.scenario)
        g = self.scenario.team.graph
        self.heard = {i: sorted(g.in_neighbours(i)) for i in driven}
        limit = float(self.sim.command_limit)
        self.limit = limit if np.isfinite(limit) else 2.0  # the drive's range, per axis
        self.snapshot: Snapshot | None = None

    def close(self) -> None:
        """Release the simulation."""
        self.sim.close()

    def sizes(self, i: int) -> dict[str, tuple[int, ...]]:
        """The shape of each observation entry of robot ``i``."""
        n = self.n
        return {
            "measurement": (2,),
            "estimate": (n, 2),
            "residual": (n,),
            "threshold": (n,),
            "flags": (n,),
            "messages": (len(self.heard[i]), n, 2),
        }

    def reset(self, seed: int | None = None) -> None:
        """Start the run again (``seed``: the scenario's seed otherwise)."""
        self.sim.reset(seed)
        for i in self.driven:
            self.sim.drive(i, None)
        self.snapshot = self.sim.snapshot()

    def step(self, actions: dict[int, np.ndarray]) -> None:
        """One control period with each driven robot commanded ``actions[i]`` (clipped to
        the drive's range, ±inf too); a NaN is a policy's bug, refused (ValueError)."""
        for i, a in actions.items():
            a = np.asarray(a, dtype=float).reshape(2)
            if np.isnan(a).any():  # it was driven at 0 m/s in silence
                raise ValueError(
                    f"the action for robot {i + 1} is {a.tolist()}: expected a planar velocity "
                    f"in m/s (clipped to ±{self.limit:g})"
                )
            self.sim.drive(i, np.clip(a, -self.limit, self.limit))
        self.snapshot = self.sim.step(1)

    @property
    def done(self) -> bool:
        """The run is over (its duration, or stopped)."""
        return self.sim.done

    def observe(self, i: int) -> dict[str, np.ndarray]:
        """What robot ``i`` knows after the last period (float32; excluded robots' entries 0)."""
        snap = self.snapshot
        assert snap is not None, "reset() first"
        team = self.sim.team
        y = np.zeros((len(self.heard[i]), self.n, 2))
        rows = {int(r): k for k, r in enumerate(team.members)}
        if i in rows:
            y_hat = team.observer.y_hat
            for a, j in enumerate(self.heard[i]):
                if j in rows:
                    y[a, team.members] = y_hat[rows[j]]
        out = {
            "measurement": snap.x_m[i],
            "estimate": snap.x_hat[i],
            "residual": snap.residual[i],
            "threshold": np.minimum(snap.threshold[i], BIG),
            "flags": snap.flag[i].astype(float),
            "messages": y,
        }
        return {
            k: np.clip(np.nan_to_num(np.asarray(v, float), nan=0.0), -BIG, BIG).astype(np.float32)
            for k, v in out.items()
        }

    def flat(self, i: int) -> np.ndarray:
        """Robot ``i``'s observation as one float32 vector, in :data:`FIELDS` order."""
        o = self.observe(i)
        return np.concatenate([o[k].ravel() for k in FIELDS])

    def reward(self, i: int) -> float:
        """Minus robot ``i``'s distance to its slot in the formation (0 once excluded)."""
        team = self.sim.team
        rows = np.flatnonzero(team.members == i)
        if not len(rows) or self.snapshot is None:
            return 0.0
        return -float(np.linalg.norm(self.snapshot.x[i] - team.x_d[rows[0]]))

    def info(self, i: int) -> dict[str, Any]:
        """The period's time, its events (robots numbered from 1) and ``dftc_command``: what
        the team's blocks commanded robot ``i`` (ū) in the period just stepped, which a policy
        may follow or correct in the next."""
        assert self.snapshot is not None
        return {
            "t": self.snapshot.t,
            "events": list(self.snapshot.events),
            "dftc_command": np.array(self.sim.team.u_bar[i], dtype=np.float32),
        }
