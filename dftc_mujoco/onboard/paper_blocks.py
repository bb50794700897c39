"""Which blocks a team runs: the paper's, by plug-in point, and a user's in their place."""

from __future__ import annotations

from collections.abc import Mapping

from .block import Block
from .controller import Controller
from .decision import Decision
from .detector import Detector
from .fault_estimator import FaultEstimator
from .observer import Observer
from .supervisor import Supervisor
from .thresholds import Thresholds

#: the paper's block classes, by plug-in point
PAPER_BLOCKS: dict[str, type[Block]] = {
    "observer": Observer,
    "controller": Controller,
    "supervisor": Supervisor,
    "fault_estimator": FaultEstimator,
    "thresholds": Thresholds,
    "decision": Decision,
    "detector": Detector,  # last: the other blocks' random streams keep their slots
}


def choose_blocks(blocks: Mapping[str, Block] | None) -> dict[str, Block]:
    """Every block of the period: the given ones (each an instance of its paper block's
    class or of a class derived from it), the paper's for the others."""
    unknown = set(blocks or {}) - set(PAPER_BLOCKS)
    if unknown:
        raise ValueError(f"unknown blocks {sorted(unknown)}; expected {list(PAPER_BLOCKS)}")
    given = dict(blocks or {})
    for k, b in given.items():  # a block that is falsy is still the user's block
        if not isinstance(b, PAPER_BLOCKS[k]):
            raise ValueError(
                f"blocks[{k!r}]: expected an instance of a class derived from "
                f"{PAPER_BLOCKS[k].__name__}, got {type(b).__name__}"
            )
    return {k: given[k] if k in given else cls() for k, cls in PAPER_BLOCKS.items()}
