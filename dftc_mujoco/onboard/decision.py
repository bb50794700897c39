"""The decision of eq. 39 with the time window of Remark 5.2.

:class:`Decision` (block) raises robot i's flag on robot k when ‖ⁱr_k‖ > ⁱμ_k has held for
``window`` seconds, and lowers it after as long below; with ``isolation = "exclusive"``
(eq. 39's second clause) a robot flags k only while no other robot is above its threshold.
The rule is the compiled :func:`decide`, which the compiled period calls too."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange

from ..graph import Graph
from .block import Block, TeamConfig
from .parallel import twin

#: ``fdir.isolation`` -> the mode of :func:`decide`
ISOLATION = {"pairwise": 0, "exclusive": 1, "exclusive_history": 2}


def _decide(
    r_norm, mu, above, below, flag, dt, window, mode, isolated, raised, blocks
):  # pragma: no cover - compiled
    """Robot i flags k once ‖ⁱr_k‖ > ⁱμ_k has held ``window`` s; lowers it after as long below.

    Updates the timers ``above``, ``below`` and ``flag`` (M, M) in place (eq. 39 with
    Remark 5.2's window); ``raised`` (M, M) marks the flags raised now. Returns how many
    were raised. ``mode`` (:data:`ISOLATION`): 0, pairwise, robot i judges each k on its
    own; 1, exclusive, robot i counts ‖ⁱr_k‖ > ⁱμ_k only while all its other residuals are
    at or below their thresholds (eq. 39's second clause, instant by instant); 2,
    exclusive with history, eq. 39 as the paper states it: also only if robot i has flagged
    no other robot since the last restart. ``isolated[i]`` (M,) is the robot robot i
    flagged first since then (−1: none), kept for mode 2. Robots are taken in ``blocks``
    contiguous groups (each robot's row is its own decision).
    """
    count = 0
    m = r_norm.shape[0]
    for b in prange(blocks):
        for i in range(b * m // blocks, (b + 1) * m // blocks):
            n_over = 0
            if mode > 0:
                for k in range(r_norm.shape[1]):
                    if r_norm[i, k] > mu[i, k]:
                        n_over += 1
            for k in range(r_norm.shape[1]):
                raised[i, k] = False
                blocked = (mode > 0 and n_over > 1) or (
                    mode == 2 and isolated[i] >= 0 and isolated[i] != k
                )
                if r_norm[i, k] > mu[i, k] and not blocked:
                    above[i, k] += dt
                    below[i, k] = 0.0
                    if not flag[i, k] and above[i, k] >= window - 1e-9:
                        flag[i, k] = True
                        raised[i, k] = True
                        count += 1
                        if isolated[i] < 0:
                            isolated[i] = k
                else:
                    above[i, k] = 0.0
                    below[i, k] += dt
                    if flag[i, k] and below[i, k] >= window - 1e-9:
                        flag[i, k] = False
    return count


# eq. 39 on one core, or split over the cores (the compiled period's choice, :mod:`.period`)
decide_in_groups = njit(cache=True)(_decide)
decide_parallel = njit(cache=True, parallel=True)(twin(_decide, "_decide_parallel"))


@njit(cache=True)
def decide(r_norm, mu, above, below, flag, dt, window, mode, isolated, raised):  # pragma: no cover
    """Eq. 39 for every robot on one core (:func:`_decide`)."""
    return decide_in_groups(r_norm, mu, above, below, flag, dt, window, mode, isolated, raised, 1)


class DecisionRecord(NamedTuple):
    """What the compiled period (:mod:`.period`) reads and writes of the decision."""

    mu: np.ndarray  # (M, M) this period's thresholds ⁱμ_k
    above: np.ndarray  # (M, M) time above, below the threshold [s]
    below: np.ndarray
    flag: np.ndarray  # (M, M) robot i flags robot k
    dt: float
    window: float
    exclusive: int  # the isolation mode (ISOLATION)
    isolated: np.ndarray  # (M,) the robot each isolates, or -1
    raised: np.ndarray  # (M, M) the flags raised this period


class Decision(Block):
    """Debounced flags: robot i flags k after ``window`` s above ⁱμ_k (eq. 39, Remark 5.2).

    ``window`` defaults to the scenario's ``fdir.detection_window`` and
    ``isolation`` to ``fdir.isolation``: ``"pairwise"`` (robot i judges each k on
    its own), ``"exclusive"`` (eq. 39's second clause read instant by instant: robot i
    isolates k only while its other residuals stay below their thresholds) or
    ``"exclusive_history"`` (eq. 39 as the paper states it: and only if robot i has
    flagged no other robot since the last exclusion). Override
    :meth:`update` to try another decision rule; row i may use only robot i's
    own residuals and thresholds.
    """

    kind = "decision"

    def __init__(self, window: float | None = None, isolation: str | None = None) -> None:
        self.window_param = window
        self.isolation_param = isolation

    def reset(self, config: TeamConfig, x_m0: np.ndarray, prior: np.ndarray) -> None:
        """All timers at zero, nobody flagged."""
        self.dt = config.observer_period  # it decides at every round of the observers
        self.window = config.detection_window if self.window_param is None else self.window_param
        isolation = config.isolation if self.isolation_param is None else self.isolation_param
        if isolation not in ISOLATION:
            raise ValueError(f"isolation must be one of {', '.join(ISOLATION)}, got {isolation!r}")
        self.exclusive = ISOLATION[isolation]
        n = len(x_m0)
        self.isolated = np.full(n, -1, dtype=np.int64)
        # np.full writes every page now: np.zeros leaves them to the first read, and the
        # decision of eq. 39 then paid page faults every period (31-35 ms at N = 1000)
        self.above = np.full((n, n), 0.0)
        self.below = np.full((n, n), 0.0)
        self.flag = np.full((n, n), False)
        self._raised = np.full((n, n), False)

    @classmethod
    def standalone(cls, n: int, window: float, dt: float) -> Decision:
        """A decision block for ``n`` robots outside any team."""
        d = cls(window)
        d.dt, d.window, d.exclusive = dt, window, 0
        d.isolated = np.full(n, -1, dtype=np.int64)
        d.above, d.below = np.full((n, n), 0.0), np.full((n, n), 0.0)
        d.flag, d._raised = np.full((n, n), False), np.full((n, n), False)
        return d

    def update(self, r_norm: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """Feed ‖ⁱr_k‖ and ⁱμ_k (M, M); return the flags raised at this instant (M, M) bool."""
        decide(np.ascontiguousarray(r_norm, float), *self.record(np.ascontiguousarray(mu, float)))
        return self._raised

    def record(self, mu: np.ndarray) -> DecisionRecord:
        """The state the compiled period updates, with this period's thresholds ``mu``."""
        return DecisionRecord(
            mu,
            self.above,
            self.below,
            self.flag,
            self.dt,
            self.window,
            self.exclusive,
            self.isolated,
            self._raised,
        )

    @property
    def raised(self) -> np.ndarray:
        """(M, M) the flags raised at the last update."""
        return self._raised

    def drop(self, p: int, graph: Graph, t: float) -> None:
        """Forget robot at position ``p`` (vectors resized after an exclusion); the isolation
        history starts again (the fault it recorded has been handled)."""
        for name in ("above", "below", "flag", "_raised"):
            a = getattr(self, name)
            setattr(self, name, np.delete(np.delete(a, p, axis=0), p, axis=1))
        self.isolated = np.full(len(self.flag), -1, dtype=np.int64)


@njit(cache=True)
def flagged_by_teammates(flag, out):  # pragma: no cover - compiled
    """out[k] = some robot i ≠ k flags robot k (``flag`` read row by row, in memory order:
    column by column was 12× slower at N = 1000)."""
    for k in range(flag.shape[1]):
        out[k] = False
    for i in range(flag.shape[0]):
        for k in range(flag.shape[1]):
            if flag[i, k] and i != k:
                out[k] = True
