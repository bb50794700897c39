"""Rule ``"l1"`` (eq. L1 of ``docs/thresholds.md``).

With ‖η_k‖ ≤ η̄ and the drift y_k(t) − y_k(0) = S_k(t) + E_k(t) of y_k = x_k − ∫u_k split
into a slow part (‖ΔS_k‖ ≤ h ξ̄ per period) and a bounded offset (‖E_k‖ ≤ ē: actuator lag,
compensation),
ⁱμ_k(t) = |c_t − d_t| ε̄ + |d_t| η̄ + η̄(δ_ik + TV_ik(t)) + ē(δ_ik + O_ik(t)) + h ξ̄ S_ik(t).
It needs only the columns A_k^j e_k (:func:`.envelope.column_envelope`) and scales to any N."""

from __future__ import annotations

import numpy as np

from ...core.graph import Graph
from .envelope import Envelope, Start, _Enveloped, column_envelope


class L1(_Enveloped):
    """The ℓ1 rule (``[onboard] thresholds = "l1"``): scales to large teams.

    A bound when each robot's measurement noise is within η̄ and the drift of
    y_k = x_k − ∫u_k is a slow part (within h ξ̄ per period) plus an offset within
    ``drift_bound`` = ē [m] (default: the team's ``drift_bound``, else 0):
    ⁱμ_k(t) = (initial term) + η̄(δ_ik + TV_ik(t)) + ē(δ_ik + O_ik(t)) + h ξ̄ S_ik(t)
    (``docs/thresholds.md``, eq. L1). At the start the initial term is
    |c_t − d_t| ε̄ + |d_t| η̄ (ε̄ = ``initial_error_bound``); after an exclusion it
    restarts from the residuals' bound (:meth:`drop`). Needs k_o h (d_max + 1) ≤ 1.
    """

    initial_error = "robot"

    def _structured(self, n: int, y0: float) -> Start:
        return Start(np.full(n, y0), self.eta_bar, True)

    def _residual_extra(self) -> float:
        return self.eta_bar

    def _envelope(self, graph: Graph, start: Start) -> Envelope:
        mu = (self.eta_bar, self.drift, self.h * self.xi_bar)
        return column_envelope(graph, self.ko, self.h, start, mu, "l1")
