"""State records handed to compiled code field by field, the calls generated from them.

A block's state is a small ``NamedTuple`` of arrays and numbers (its *record*: the
observer's :class:`~.observer.ObserverRecord`, the fault estimator's
:class:`~.fault_estimator.EstimatorRecord`, ...), and a compiled kernel takes records. From
Python, numba would type a record argument element by element on every call (about 100 ns
a field), so :func:`flat_call` writes, at import, one compiled entry per kernel whose
parameters are the records' fields in order, and which rebuilds the records inside
compiled code (where building them costs nothing) and calls the kernel. The entry is
written from the records' own definitions (their ``_fields``): adding a field to a record
changes its block and the kernel that reads it, nothing here. :func:`fields` takes records
apart the same way on the Python side.

Each array is passed as itself: numba holds a reference to it for the call, so nothing
outlives what it points into, and a copied team copies its records with its arrays.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from itertools import chain
from typing import Any

from numba import njit


def fields(records: Sequence[tuple[Any, ...]]) -> tuple[Any, ...]:
    """The records' fields in order, as a :func:`flat_call` entry takes them."""
    return tuple(chain.from_iterable(records))


def flat_call(
    kernel: Callable[..., Any],
    records: Sequence[type],
    name: str,
    module: str,
    extra: Sequence[str] = (),
    nogil: bool = False,
) -> Any:
    """A compiled (and cached) entry ``name`` of ``module`` that takes the fields of
    ``records`` (``NamedTuple`` classes) in order, then the arguments ``extra``, and returns
    ``kernel(record_1, ..., record_n, *extra)``. ``nogil``: the entry holds no lock on Python
    while it runs (a kernel that several threads run at once)."""
    params: list[str] = []
    built: list[str] = []
    scope: dict[str, Any] = {"__name__": module, "_kernel": kernel}
    for k, record in enumerate(records):
        own = [f"r{k}_{field}" for field in record._fields]  # type: ignore[attr-defined]
        params += own
        scope[f"_R{k}"] = record
        built.append(f"_R{k}({', '.join(own)})")
    params += extra
    source = (
        f"def {name}({', '.join(params)}):\n    return _kernel({', '.join([*built, *extra])})\n"
    )
    # compiled as part of the module's own file: numba keeps the entry in its cache there
    exec(compile(source, sys.modules[module].__file__ or module, "exec"), scope)
    entry = scope[name]
    entry.__qualname__ = name
    return njit(cache=True, nogil=nogil)(entry)
