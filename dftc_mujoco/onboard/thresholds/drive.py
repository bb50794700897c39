"""Rule ``"drive"`` (eq. D of ``docs/thresholds.md``).

Robot k's measured y_m,k − y_m,k(0) = G φ̂_k exactly (the fault estimator's algebra), a pure
offset of size ‖G‖ Φ̄ while ‖φ̂_k‖ ≤ Φ̄ (:func:`.compensation.estimator_gain`):
ⁱμ_k(t) = |c_t − d_t| (ε̄ + η̄) + ‖G‖ Φ̄ (δ_ik + O_ik(t)).
It needs the compensation on and unfiltered (``premises.rule_refusals``)."""

from __future__ import annotations

import numpy as np

from ...core.graph import Graph
from ..block import TeamConfig
from .compensation import estimator_gain
from .envelope import Envelope, Start, _Enveloped, column_envelope


class Drive(_Enveloped):
    """The drive rule (``[onboard] thresholds = "drive"``): the tightest rule here.

    A bound whenever every healthy robot's fault estimate stays within ``phi_bar``
    [m/s] (and its anti-windup does not act): robot k's measured y_m,k moves only as
    G φ̂_k does, an offset of size F = ‖G‖₂ Φ̄, so
    ⁱμ_k(t) = (initial term) + F (δ_ik + O_ik(t)) (eq. D); at the start the initial
    term is |c_t − d_t| (ε̄ + η̄), after an exclusion it restarts from the residuals'
    bound (:meth:`drop`). By default Φ̄ is the ℓ1 gain of the fault estimator's closed
    loop on an ideal plant, from η (bound η̄) and from a velocity mismatch (bound ξ̄)
    to φ̂; on a real robot its own mismatch adds to it (``docs/thresholds.md``).
    Needs k_o h (d_max + 1) ≤ 1.
    """

    initial_error = "robot"
    covers_compensation = False  # Φ̄ is its own premise

    def __init__(self, phi_bar: float | None = None) -> None:
        super().__init__()
        self.phi_bar_param = phi_bar

    def _setup(self, config: TeamConfig) -> None:
        if self.phi_bar_param is not None:
            self.phi_bar = float(self.phi_bar_param)
        elif np.isfinite(config.phi_bar):  # the assembly's Φ̄, from these very inputs
            self.phi_bar = float(config.phi_bar)
        else:  # a configuration built by hand
            self.phi_bar = estimator_gain(
                config.K, config.G, config.dt, config.eta_bar, config.xi_bar, lag=config.lag
            )
        self.offset = float(np.linalg.norm(self.G, 2)) * self.phi_bar

    def _structured(self, n: int, y0: float) -> Start:
        return Start(np.full(n, y0 + self.eta_bar), 0.0, True)  # ε = (1 − e_k)(a − η)ᵀ

    def _envelope(self, graph: Graph, start: Start) -> Envelope:
        f = self.offset
        return column_envelope(graph, self.ko, self.h, start, (0.0, f, 0.0), "drive")
