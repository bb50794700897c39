"""The team's arrays on the original robot axis: after an exclusion the blocks hold the
M members' rows only, while records and outputs keep one row (and column) per robot of
the original team, the robots that left filled with NaN or False."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["expand", "place"]


def expand(
    a: np.ndarray, members: np.ndarray, n: int, square: bool = False, fill: Any = np.nan
) -> np.ndarray:
    """Place a members-indexed array on the original robot axis (both first axes if ``square``)."""
    if len(members) == n:
        return a  # the whole team: no copy (callers copy what they keep)
    lead = (n, n) if square else (n,)
    out = np.empty((*lead, *a.shape[len(lead) :]), dtype=bool if fill is False else float)
    place(out, a, members, square, fill)
    return out


def place(
    out: np.ndarray, a: np.ndarray, members: np.ndarray, square: bool = False, fill: Any = np.nan
) -> None:
    """Write a members-indexed array into ``out`` on the original robot axis (both first axes
    if ``square``), ``fill`` for the robots that are not members."""
    if len(members) == len(out):  # the whole team: a copy
        out[...] = a
        return
    out[...] = fill
    if square:
        out[members[:, None], members[None, :]] = a
    else:
        out[members] = a
