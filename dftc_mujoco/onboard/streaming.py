"""Stores that bypass the caches, for a large array a period writes once and reads only at
the next period.

ⁱŷ of the next period (eq. 19) is written row by row into its own buffer and read only a
period later. Once the period's N × N arrays no longer fit in the last-level cache, an
ordinary store first reads each line of that buffer from memory (to own it) and later
writes it back: twice the traffic of the store itself. A streaming ("non-temporal") store
writes the line without reading it. Below that size the buffer stays in the cache for the
next period, which a streaming store would throw out, so the team streams only beyond it
(:func:`streams`). The numbers stored are the same either way.

:func:`stream_store` is the store, :func:`store_fence` orders the streamed stores before
whatever the thread does next (another thread may read the buffer once the pass is over).
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

#: [bytes] the last-level cache assumed where the system does not say
DEFAULT_CACHE = 32 << 20

#: the element types a streamed store writes (float32: ``benchmarks/bench_pass.py``'s state)
_FLOATS = (types.float64, types.float32)


@intrinsic
def stream_store(typingctx, array, index, value):
    """``array[index] = value`` (a 1-d float64 or float32 array; the value rounded to the
    array's type as an ordinary store would), with a store that bypasses the caches."""
    if not (isinstance(array, types.Array) and array.ndim == 1 and array.dtype in _FLOATS):
        return None
    if not isinstance(index, types.Integer):
        return None
    sig = types.void(array, index, value)

    def codegen(context, builder, signature, args):
        arr_t, idx_t, val_t = signature.args
        arr = context.make_array(arr_t)(context, builder, args[0])
        idx = context.cast(builder, args[1], idx_t, types.intp)
        val = context.cast(builder, args[2], val_t, arr_t.dtype)
        ptr = cgutils.get_item_pointer(context, builder, arr_t, arr, [idx], wraparound=False)
        store = builder.store(val, ptr)
        store.set_metadata("nontemporal", builder.module.add_metadata([ir.IntType(32)(1)]))
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def store_fence(typingctx):
    """A full memory fence: the streamed stores before it are seen before anything after."""

    def codegen(context, builder, signature, args):
        builder.fence("seq_cst")
        return context.get_dummy_value()

    return types.void(), codegen


@functools.cache
def last_level_cache() -> int:
    """[bytes] the largest cache the system reports for CPU 0 (Linux sysfs), else
    :data:`DEFAULT_CACHE`."""
    sizes = []
    for f in Path("/sys/devices/system/cpu/cpu0/cache").glob("index*/size"):
        try:
            text = f.read_text().strip()
        except OSError:
            continue
        scale = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30}.get(text[-1:], 1)
        digits = text.rstrip("KMG")
        if digits.isdigit():
            sizes.append(int(digits) * scale)
    if not sizes and hasattr(os, "sysconf"):
        try:
            sizes.append(int(os.sysconf("SC_LEVEL3_CACHE_SIZE")))
        except (ValueError, OSError):
            pass
    return max(sizes) if sizes and max(sizes) > 0 else DEFAULT_CACHE


def streams(nbytes: int) -> bool:
    """Whether a period whose N × N arrays take ``nbytes`` should stream its ŷ of the next
    period: beyond half the last-level cache (a pass alone on one core, with a 32 MiB cache:
    streaming made it 33 % slower at N = 500, where these arrays take 12 MB, and 12 %
    faster at N = 700, 24 MB, and N = 1000, 48 MB)."""
    return nbytes > last_level_cache() // 2
