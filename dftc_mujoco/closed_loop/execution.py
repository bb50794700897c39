"""How a run executes its onboard period, never what the period computes.

The paper's blocks run either as one compiled call a period (the *compiled* path,
:mod:`.onboard.period`) or through the blocks' own methods (the *general* path,
:mod:`.onboard.general`). Both compute the same numbers bit for bit (tested); they differ
in speed and in what a first run costs: numba compiles the one-call period once per
machine (about 30 s on a 2-core machine, then kept in its cache), the general path's
smaller functions in about a third of that.

:class:`Execution` says which to use, and in how many threads a large team's pass over
its N × N state runs (:mod:`.onboard.sharing`). The default period, ``"auto"``, takes the
compiled period when its machine code is in numba's cache; on a cold cache a team of up to
:data:`GENERAL_UP_TO` robots runs the general path while a background process compiles
the one-call period for the runs that follow (:mod:`.warm`), and a larger team compiles
it before its first period. ``DFTC_PERIOD`` in the environment sets the default for
every run of a process (``auto``, ``compiled`` or ``general``). The options reach the team
through its configuration (:class:`~.onboard.block.TeamConfig`): nothing else switches
how a period runs.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

import numba

from ..errors import InputError
from ..onboard.block import Block
from ..onboard.execution.period import team_period_call
from ..onboard.execution.team import runs_compiled
from ..runtime.numba_cache import is_cached

Period = Literal["auto", "compiled", "general"]
PERIODS: tuple[Period, ...] = ("auto", "compiled", "general")
#: robots: up to this size a cold cache runs the general path rather than wait for the
#: compiler (at 64 robots the general path is still faster than the compilation it saves)
GENERAL_UP_TO = 64
#: robots: from this many members on, a team with more than one thread shares its pass
#: between them (below it, handing the rows to a thread costs more than it saves)
SHARED_FROM = 150


def _from_environment() -> Period:
    value = os.environ.get("DFTC_PERIOD", "auto").strip().lower() or "auto"
    if value not in PERIODS:
        raise InputError(
            f"DFTC_PERIOD={value!r} in the environment: expected one of {', '.join(PERIODS)}"
        )
    return value


@dataclass(frozen=True)
class Execution:
    """How the onboard period runs (:mod:`dftc_mujoco.closed_loop.execution`).

    ``period``: ``"compiled"`` (one compiled call a period; compiled before the first
    period where numba's cache does not hold it yet), ``"general"`` (the blocks' own
    methods, the plain reference) or ``"auto"`` (the default, or ``DFTC_PERIOD``): the
    compiled period when it is cached, else the general path for a team of up to
    :data:`GENERAL_UP_TO` robots while the compiled period is compiled in the background.

    ``threads``: how many threads a compiled team of ``shared_from`` members or more runs
    its pass over the N × N state in, the calling thread included (helpers take it while
    the caller sends the commands and steps the physics); ``None``: numba's thread count
    (the cores, or ``NUMBA_NUM_THREADS``); 1: none. A campaign's workers run with one
    thread each where they share the cores.
    """

    period: Period = field(default_factory=_from_environment)
    threads: int | None = None
    shared_from: int = SHARED_FROM

    def __post_init__(self) -> None:
        if self.period not in PERIODS:
            raise ValueError(
                f"Execution(period): expected one of {', '.join(PERIODS)}, got {self.period!r}"
            )
        for name in ("threads", "shared_from"):
            value = getattr(self, name)
            if value is None and name == "threads":
                continue
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"Execution({name}): expected a whole number ≥ 1, got {value!r}")

    def thread_count(self) -> int:
        """The threads a shared pass runs in (``threads``, or numba's count)."""
        return self.threads if self.threads is not None else max(1, numba.get_num_threads())

    def choose(self, robots: int, blocks: Mapping[str, Block]) -> tuple[bool, bool]:
        """(run the compiled period, compile it in the background for later runs) for a
        team of ``robots`` with these ``blocks`` (a plug-in block runs the general path in
        any case)."""
        if self.period == "general" or not runs_compiled(blocks):
            return False, False
        if self.period == "compiled" or robots > GENERAL_UP_TO:
            return True, False
        if is_cached(team_period_call):
            return True, False
        return False, True
