"""A neighbour-only detector beside the paper's (a plug-in through ``[onboard] detector``).

Robot i watches each in-neighbour j by what j says of itself: the column ʲŷ_j of j's
messages, j's estimate of y_j = x_j − ∫u_j. A healthy robot's y_j moves only by its drift
(‖ẋ_j − u_j‖ ≤ ξ̄, eq. 2), a robot with an actuator fault at the fault's speed, and j's own
observer follows its own measurement closely. Robot i flags j when ʲŷ_j moved more than
ξ̄ T + 2 η̄ + ``margin`` over the last T = ``window`` seconds. It needs no model of the
team (no P, no κ/λ) and answers fast, but it judges in-neighbours only: a robot that
nobody hears directly is judged by nobody, and it isolates only robots with listeners.
Its own row keeps the paper's judgement of itself. A rule with no proof: the drift of
ʲŷ_j also carries the consensus's pull on j's own column, which ``margin`` absorbs.

    python -m dftc_mujoco.run paper_case --set onboard.detector=mylab.neighbours:NeighbourMonitor
    (run from examples/, or with examples/ on PYTHONPATH)
"""

from __future__ import annotations

from collections import deque

import numpy as np

from dftc_mujoco.blocks import paper


class NeighbourMonitor(paper.Detector):
    """Flags an in-neighbour whose own estimate ʲŷ_j moves faster than its drift allows."""

    def __init__(self, window: float = 0.5, margin: float = 0.02, after: float = 5.0) -> None:
        self.window, self.margin, self.after = float(window), float(margin), float(after)

    def reset(self, config: paper.TeamConfig, x_m0: np.ndarray, prior: np.ndarray) -> None:
        self.bound = config.xi_bar * self.window + 2 * config.eta_bar + self.margin
        self.history: deque[tuple[float, np.ndarray]] = deque()

    def drop(self, p: int, graph, t: float) -> None:
        self.history.clear()  # the links changed: start again

    def judge(self, r_norm, mu, observer, x_m):
        src, dst, msgs = self.inbox(observer)
        own = msgs[np.arange(len(src)), src].copy()  # ʲŷ_j as robot dst holds it
        self.history.append((self.t, own))
        while len(self.history) > 1 and self.history[1][0] <= self.t - self.window:
            self.history.popleft()
        m = len(r_norm)
        score = np.zeros((m, m))
        bound = np.full((m, m), self.bound)
        t0, past = self.history[0]
        if self.t >= self.after and t0 <= self.t - self.window + 1e-9:
            score[dst, src] = np.hypot(*(own - past).T)
        mine = np.arange(m)
        score[mine, mine] = r_norm[mine, mine]  # its own row: the paper's judgement of itself
        bound[mine, mine] = np.asarray(mu)[mine, mine]
        return score, bound
