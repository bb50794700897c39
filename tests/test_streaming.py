"""Stores past the caches (onboard/streaming.py): the same numbers, and only for a team
whose period's arrays outgrow the last-level cache."""

from __future__ import annotations

import numpy as np
from numba import njit

from dftc_mujoco.onboard import streaming
from dftc_mujoco.onboard.streaming import last_level_cache, store_fence, stream_store, streams


@njit
def _advance(y, r, out, stream):
    for i in range(y.shape[0]):
        yi, ri, oi = y[i], r[i], out[i]
        if stream:
            for a in range(yi.shape[0]):
                stream_store(oi, a, yi[a] + 0.02 * ri[a])
        else:
            for a in range(yi.shape[0]):
                oi[a] = yi[a] + 0.02 * ri[a]
    store_fence()


def test_a_streamed_store_writes_the_same_numbers():
    rng = np.random.default_rng(0)
    for shape in ((3, 5), (40, 2 * 40), (300, 2 * 300 + 1)):  # odd rows: unaligned ends
        y, r = rng.standard_normal(shape), rng.standard_normal(shape)
        plain, streamed = np.full(shape, np.nan), np.full(shape, np.nan)
        _advance(y, r, plain, False)
        _advance(y, r, streamed, True)
        assert np.array_equal(plain, streamed) and np.array_equal(plain, y + 0.02 * r)
        # float32 state (benchmarks/bench_pass.py): rounded as an ordinary store rounds
        plain32, streamed32 = np.full(shape, np.nan, np.float32), np.full(shape, 0, np.float32)
        _advance(y, r, plain32, False)
        _advance(y, r, streamed32, True)
        assert np.array_equal(plain32, streamed32)
        assert np.array_equal(plain32, (y + 0.02 * r).astype(np.float32))


def test_only_arrays_beyond_the_cache_stream(monkeypatch):
    assert last_level_cache() >= 1 << 16  # this machine reports one (sysfs), else 32 MiB
    monkeypatch.setattr(streaming, "last_level_cache", lambda: 32 << 20)
    n = 2 * 8 * 3  # ŷ, ŷ⁺ and ∫ⁱû_g: 3 arrays of M × M × 2 floats
    assert not streams(n * 500**2)  # 12 MB: the next period finds them in the cache
    assert streams(n * 1000**2)  # 48 MB
