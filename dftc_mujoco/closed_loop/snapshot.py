"""What a run shows after a control period (:meth:`.loop.Simulation.step`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.events import Event


@dataclass(frozen=True)
class Snapshot:
    """The state of a run after a control period (robots on the original axis, from 0).

    ``x`` true positions, ``x_m`` own measurements, ``x_hat`` (N, N, 2) ⁱx̂
    (row i: robot i's estimate of every robot), ``u`` nominal and ``u_bar``
    compensated inputs, ``phi_hat`` fault estimates, ``residual`` and
    ``threshold`` (N, N) ‖ⁱr_k‖ and ⁱμ_k, ``flag`` (N, N) robot i flags k,
    ``flagged`` (N,) some teammate flags k, ``reactive`` and ``active`` (N,).
    Entries of excluded robots are NaN / False. ``events`` happened since the
    previous snapshot (robots numbered from 1, as in ``summary.json``).
    """

    t: float
    x: np.ndarray
    x_m: np.ndarray
    x_hat: np.ndarray
    u: np.ndarray
    u_bar: np.ndarray
    phi_hat: np.ndarray
    residual: np.ndarray
    threshold: np.ndarray
    flag: np.ndarray
    flagged: np.ndarray
    reactive: np.ndarray
    active: np.ndarray
    events: list[Event] = field(default_factory=list)

    @classmethod
    def of(
        cls,
        t: float,
        x: np.ndarray,
        x_m: np.ndarray,
        outputs: dict[str, np.ndarray],
        events: list[Event],
    ) -> Snapshot:
        """A snapshot at ``t`` of true positions ``x``, measurements ``x_m`` and the team's
        ``outputs`` (``Team.outputs``), every array copied."""
        copied = {k: np.array(outputs[k], copy=True) for k in _TEAM}
        return cls(t=t, x=x.copy(), x_m=x_m.copy(), events=[e.copy() for e in events], **copied)


#: the snapshot's fields the team's outputs give
_TEAM = ("x_hat", "u", "u_bar", "phi_hat", "residual", "threshold", "flag", "flagged",
         "reactive", "active")  # fmt: skip
