"""The detector: what each robot judges its teammates by, before the decision (eq. 39).

The paper's detector reads the observer's residual (eq. 35) against the thresholds
(eqs. 40-41, or a rule of docs/thresholds.md): robot i's score on robot k is ‖ⁱr_k‖ and
its bound ⁱμ_k. A plug-in detector (``[onboard] detector = "module:Class"``) receives the
same ingredients and the observer itself (its estimates ``y_hat``, the messages each link
delivered, ``links``, and their senders ``allowed.src`` and receivers ``link_dst()``), and
returns its own score and bound per pair; the decision raises robot i's flag on k when the
score stays above the bound for a detection window. Robot i's row may use only its own
measurement and what its in-neighbours sent (``check_locality`` tests it).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .block import Block


class Detector(Block):
    """The paper's detector: the residual's norm against the thresholds."""

    kind = "detector"

    def judge(
        self, r_norm: np.ndarray, mu: np.ndarray, observer: Any, x_m: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Scores and bounds (M, M) each robot i holds on each robot k, from the residual
        norms ``r_norm`` (eq. 35), the thresholds ``mu``, the ``observer`` (its messages)
        and the members' own measurements ``x_m`` (M, n). The paper's: (‖ⁱr_k‖, ⁱμ_k)."""
        return r_norm, mu

    @staticmethod
    def inbox(observer: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The messages each robot holds now: (senders (E,), receivers (E,), the ŷ each
        carries (E, M, n)), one per link of the graph (over a network: the last message
        each link delivered, :mod:`.radio`)."""
        y = observer.y_hat
        m, n = y.shape[0], y.shape[2]
        if observer.networked:
            return observer.allowed.src, observer.link_dst(), observer.links.reshape(-1, m, n)
        msg = observer.messages
        dst = np.repeat(np.arange(len(msg.first_edge) - 1), np.diff(msg.first_edge))
        return msg.src, dst, y[msg.src]
