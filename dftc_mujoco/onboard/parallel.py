"""Compiling one pass twice, on one core and over every core, without the two colliding.

numba names a function's on-disk cache after its qualified name and first line, not after
its compile options: two dispatchers of one Python function, one with ``parallel=True``,
share one cache index, and a process can load the other's machine code (a one-core pass
where the team asked for both cores, 12.7 instead of 9.3 ms per period at N = 1000, or
code that crashed its caller). :func:`twin` gives the parallel dispatcher a function of
its own name with the very same code.
"""

from __future__ import annotations

import types
from collections.abc import Callable
from typing import Any


def twin(fn: Callable[..., Any], name: str) -> Callable[..., Any]:
    """A function with ``fn``'s code, globals and defaults under another ``name``."""
    assert isinstance(fn, types.FunctionType)
    out = types.FunctionType(fn.__code__, fn.__globals__, name, fn.__defaults__, fn.__closure__)
    out.__qualname__ = name
    out.__doc__ = fn.__doc__
    return out
