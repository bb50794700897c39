"""How a run executes its onboard period, never what the period computes.

The paper's blocks run either as one compiled call a period (the *compiled* path,
:mod:`.onboard.period`) or through the blocks' own methods (the *general* path,
:mod:`.onboard.general`). Both compute the same numbers bit for bit (tested); they differ
in speed and in what a first run costs: numba compiles the one-call period once per
machine (about 30 s on a 2-core machine, then kept in its cache), the general path's
smaller functions in about a third of that.

:class:`Execution` says which to use. The default, ``"auto"``, takes the compiled period
when its machine code is in numba's cache; on a cold cache a team of up to
:data:`GENERAL_UP_TO` robots runs the general path while a background process compiles
the one-call period for the runs that follow (:mod:`.warm`), and a larger team compiles
it before its first period. ``DFTC_PERIOD`` in the environment sets the default for
every run of a process (``auto``, ``compiled`` or ``general``).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

from .errors import InputError
from .numba_cache import is_cached
from .onboard.block import Block
from .onboard.period import team_period_flat
from .onboard.team import runs_compiled

Period = Literal["auto", "compiled", "general"]
PERIODS: tuple[Period, ...] = ("auto", "compiled", "general")
#: robots: up to this size a cold cache runs the general path rather than wait for the
#: compiler (at 64 robots the general path is still faster than the compilation it saves)
GENERAL_UP_TO = 64


def _from_environment() -> Period:
    value = os.environ.get("DFTC_PERIOD", "auto").strip().lower() or "auto"
    if value not in PERIODS:
        raise InputError(
            f"DFTC_PERIOD={value!r} in the environment: expected one of {', '.join(PERIODS)}"
        )
    return value


@dataclass(frozen=True)
class Execution:
    """How the onboard period runs (:mod:`dftc_mujoco.execution`).

    ``period``: ``"compiled"`` (one compiled call a period; compiled before the first
    period where numba's cache does not hold it yet), ``"general"`` (the blocks' own
    methods, the plain reference) or ``"auto"`` (the default, or ``DFTC_PERIOD``): the
    compiled period when it is cached, else the general path for a team of up to
    :data:`GENERAL_UP_TO` robots while the compiled period is compiled in the background.
    """

    period: Period = field(default_factory=_from_environment)

    def __post_init__(self) -> None:
        if self.period not in PERIODS:
            raise ValueError(
                f"Execution(period): expected one of {', '.join(PERIODS)}, got {self.period!r}"
            )

    def choose(self, robots: int, blocks: Mapping[str, Block]) -> tuple[bool, bool]:
        """(run the compiled period, compile it in the background for later runs) for a
        team of ``robots`` with these ``blocks`` (a plug-in block runs the general path in
        any case)."""
        if self.period == "general" or not runs_compiled(blocks):
            return False, False
        if self.period == "compiled" or robots > GENERAL_UP_TO:
            return True, False
        if is_cached(team_period_flat):
            return True, False
        return False, True
