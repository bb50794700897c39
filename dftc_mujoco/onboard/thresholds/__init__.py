"""The thresholds ⁱμ_k(t) of residual-based detection, one module per rule.

=================  =====================================================================
module             concept
=================  =====================================================================
:mod:`.paper`      eq. 40, the paper's rule (``"paper"``) and the thresholds block
:mod:`.decay`      κ, λ of eq. 41 for every monitored robot
:mod:`.l1`         rule ``"l1"`` (eq. L1 of ``docs/thresholds.md``)
:mod:`.drive`      rule ``"drive"`` (eq. D)
:mod:`.block_row`  rule ``"block_row"`` (eq. B) and its row sweep
:mod:`.envelope`   what l1, drive and block_row share: the column sweep, the envelope,
                   the start and the restart after an exclusion
:mod:`.kernels`    the compiled recursions on the observer matrices (B_k applied once)
:mod:`.compensation`  Φ̄ and the compensation's drift offset (eqs. 28-31)
:mod:`.delays`     Δt_d of eq. 46 for ``fdir.dt_d_max = "auto"``
:mod:`.settling`   T_s, from when on every threshold is near its steady value
=================  =====================================================================

The registry of rule names is ``dftc_mujoco.blocks.BUILTIN``. The decision of eq. 39 is
:mod:`dftc_mujoco.onboard.decision`; the exclusion protocol (eqs. 42-43) is
:mod:`dftc_mujoco.onboard.recovery`.
"""

from .block_row import BLOCK_ROW_MAX, BlockRow, row_envelope
from .compensation import compensation_offset, estimator_gain
from .decay import decay_bound, decay_bound_of, decay_bounds, observer_matrix, prefetch_decay_bounds
from .delays import predicted_delays
from .drive import Drive
from .envelope import Envelope, Start, check_nonnegative, column_envelope, grounded_solve
from .l1 import L1
from .paper import Thresholds

__all__ = [
    "BLOCK_ROW_MAX",
    "L1",
    "BlockRow",
    "Drive",
    "Envelope",
    "Start",
    "Thresholds",
    "check_nonnegative",
    "column_envelope",
    "compensation_offset",
    "decay_bound",
    "decay_bound_of",
    "decay_bounds",
    "estimator_gain",
    "grounded_solve",
    "observer_matrix",
    "predicted_delays",
    "prefetch_decay_bounds",
    "row_envelope",
]
