"""T_s: the instant from which every threshold ⁱμ_k(t) stays within a tolerance of its
steady value, the domain of eq. 46's guarantee (a fault before it may be flagged later
than Δt_d,max, or never); and a rule's thresholds read for it, checked (:class:`Looked`)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numba import njit

from ...errors import InputError
from ..block import BadOutput, Block
from .paper import ThresholdRecord, Thresholds, factored_at


@njit(cache=True)
def _within(mu, limit, finite):  # pragma: no cover - compiled
    """Whether mu ≤ limit wherever ``finite`` (a NaN is not), entry by entry, stopping at
    the first that is not (no temporaries: numpy's masks cost 3 ms per instant at N = 1000)."""
    for i in range(mu.shape[0]):
        for k in range(mu.shape[1]):
            if finite[i, k] and not mu[i, k] <= limit[i, k]:
                return False
    return True


@njit(cache=True)
def _within_factored(coef, bound, steady, finite, eta, scale, first, second):  # pragma: no cover
    """:func:`_within` for eq. 40 from its factors, with the same numbers: each ⁱμ_k(t) (the
    bound ``bound``) against its steady value (``steady``) × ``scale`` + 1e-12, entries as
    :func:`~.paper.factored_at` gives them. Off the diagonal ⁱμ_k = cᵢ b_k depends on cᵢ
    and k only, so column k is checked once for each distinct cᵢ among the robots i ≠ k
    (``first[u]``, else ``second[u]``: two robots with the u-th value, -1 where none),
    and once on the diagonal: O(M) per instant for a few in-degrees, not O(M²)."""
    for k in range(coef.shape[0]):
        for u in range(-1, first.shape[0]):
            i = k if u < 0 else (first[u] if first[u] != k else second[u])
            if i < 0:
                continue
            settled = factored_at(coef, steady, finite, eta, i, k)
            if (
                np.isfinite(settled)
                and not factored_at(coef, bound, finite, eta, i, k) <= settled * scale + 1e-12
            ):
                return False
    return True


def by_coefficient(coef: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two robots for each distinct cᵢ of eq. 40 (``first``, ``second``; -1 where only one
    robot has it), the rows :func:`_within_factored` reads."""
    values, first, counts = np.unique(coef, return_index=True, return_counts=True)
    second = np.full(len(values), -1)
    for u in np.flatnonzero(counts > 1):
        second[u] = np.flatnonzero(coef == values[u])[1]
    return first, second


def settle_time(
    mu: Callable[[float], np.ndarray],
    dt: float,
    horizon: float,
    tolerance: float = 0.1,
    factors: Callable[[float], ThresholdRecord | None] | None = None,
    start: float = 0.0,
) -> float:
    """T_s of the rule whose thresholds at t are ``mu(t)``, sampled on a geometric grid of
    at most 96 instants (``start`` plus multiples of the control period ``dt``) up to
    ``horizon`` [s]: the first instant from which every later one has every finite threshold
    within ``tolerance`` of its value at t = 1e9 s; inf if the last one has not (a rule
    restarted at ``start``, after an exclusion, settles anew). ``factors(t)``, where it gives a
    record: the same thresholds as eq. 40's factors (:meth:`.Thresholds.factors_at`), read
    instead of ``mu(t)``'s (M, M) arrays with the same numbers (at N = 1000, 96 arrays of
    8 MB written and read: 0.13 s of the set-up)."""
    steady = np.asarray(mu(1e9), dtype=float)
    finite = np.isfinite(steady)
    if not finite.any():
        return float("inf")
    scale = 1 + tolerance
    span = max(horizon - start, dt)
    grid = start + np.unique(np.round(np.geomspace(dt, span, 96) / dt) * dt)
    ref = factors(1e9) if factors is not None else None
    if factors is not None and ref is not None:
        first, second = by_coefficient(ref.coef)
        at, steady_bound = factors, ref.bound

        def within(t: float) -> bool:
            now = at(t)
            assert now is not None  # the same rule throughout
            args = (now.coef, now.bound, steady_bound, now.finite, now.eta)
            return bool(_within_factored(*args, scale, first, second))
    else:
        limit = steady * scale + 1e-12  # now: mu's array is valid until its next call

        def within(t: float) -> bool:
            return bool(_within(np.asarray(mu(t), dtype=float), limit, finite))

    settled = float("inf")
    for t in grid[::-1]:  # the last instant that is still outside, from the end
        if within(float(t)):
            settled = float(t)
        else:
            break
    return settled


def rule_settle_time(
    rule: Block,
    members: np.ndarray,
    dt: float,
    horizon: float,
    start: float = 0.0,
    running: bool = False,
) -> tuple[float, bool]:
    """T_s (:func:`settle_time`, 10 % of steady) of a team's thresholds block ``rule``, as
    started (or restarted, ``running``: during the run) at ``start``, its arrays checked
    (:class:`Looked`), read from eq. 40's factors where it is the paper's rule; and whether
    it can never flag anybody."""
    kind = type(rule)
    name = f"{kind.__module__}:{kind.__qualname__}"
    mu = Looked(rule.mu, members, name, rule if running else None)  # type: ignore[attr-defined]
    mu(start)  # the first array of the rule, checked too
    factors = rule.factors_at if isinstance(rule, Thresholds) else None  # eq. 40, unwritten
    return settle_time(mu, dt, horizon, 0.1, factors, start), mu.never_flags


class Looked:
    """A thresholds rule's ``mu(t)`` as read for its settle time, checked: an (M, M) array of
    numbers (InputError, one line, otherwise); in the first two arrays read (its start, t = 0
    or a restart, and :func:`settle_time`'s steady one, O(M²) each) every entry ≥ 0, +inf
    where a pair cannot be judged: a threshold bounds a residual's norm, and a negative or
    NaN one flags everybody or nobody. ``never_flags``: both were +inf everywhere. With
    ``block`` (a rule read during the run, restarted after an exclusion) what it cannot use
    is that block's :class:`~..block.BadOutput`, as the period says it, not bad input."""

    def __init__(
        self,
        mu: Callable[[float], object],
        members: np.ndarray,
        name: str,
        block: Block | None = None,
    ) -> None:
        self.rule, self.members, self.name, self.block = mu, members, name, block
        self.looked = 0
        self.never_flags = True

    def __call__(self, t: float) -> np.ndarray:
        got, m = self.rule(t), len(self.members)
        try:
            out = np.asarray(got, dtype=float)
        except (TypeError, ValueError):
            out = None
        if out is None or out.shape != (m, m):
            what = f"shape {out.shape}" if out is not None else type(got).__name__
            if self.block is not None:  # during the run: as the period says it (block.shaped)
                raise BadOutput(self.block, f"returned from mu(t) {what}, expected {(m, m)},")
            raise InputError(
                f"onboard.thresholds: {self.name}.mu(t) returned {what}; expected an array of "
                f"numbers of shape ({m}, {m}): row i robot i's thresholds, column k robot k's"
            )
        if self.looked < 2:
            self.looked += 1
            if self.block is not None:  # during the run: as the period says it
                refuse_bad_entry(out, self.members, self.block)
            elif bad := bad_entry(out, self.members):
                raise InputError(
                    f"onboard.thresholds: {self.name}.mu({t:g}) returned {bad}; expected a "
                    "number ≥ 0 (a threshold bounds a residual's norm), or +inf where the pair "
                    "cannot be judged"
                )
            self.never_flags &= not np.isfinite(out).any()
        return out


def refuse_bad_entry(mu: np.ndarray, members: np.ndarray, block: Block) -> None:
    """``block``'s :class:`~..block.BadOutput` for the first threshold of ``mu`` (M, M) that is
    negative or NaN (:func:`bad_entry`); nothing if there is none."""
    bad = bad_entry(mu, members)
    if bad:
        raise BadOutput(block, f"returned from mu(t) {bad}, expected a number ≥ 0 or +inf,")


def bad_entry(mu: np.ndarray, members: np.ndarray) -> str | None:
    """The first threshold of ``mu`` (M, M) that is negative or NaN, in words ("nan as robot
    3's threshold on robot 2", robots by their number in the original team), or None."""
    bad = np.argwhere(~(mu >= 0))
    if not len(bad):
        return None
    i, k = (int(members[j]) + 1 for j in bad[0])
    return f"{mu[tuple(bad[0])]:g} as robot {i}'s threshold on robot {k}"
