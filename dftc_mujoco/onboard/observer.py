"""Distributed consensus observer in y-form (eqs. 19-21) and its residual (eq. 35).

Every robot i keeps ⁱŷ (its estimate of the auxiliary collective variable
y = x − ∫u, eq. 20) and ∫(ⁱû_g + Γᵢᵀ Δuᵢ); its estimate of the whole team is
ⁱx̂ = ⁱŷ + ∫(ⁱû_g + Γᵢᵀ Δuᵢ) (eq. 21). Eq. 19 is then d/dt ⁱŷ = k_o ⁱr with
ⁱr the residual of eq. 35 (NOTES 1). Arrays carry a leading robot axis:
``y_hat[i]`` is robot i's ⁱŷ, of shape (N, n), and is the message it broadcasts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class ObserverState:
    """Per-robot observer state; updated in place by :func:`update`."""

    y_hat: np.ndarray  # (N, N, n): ⁱŷ, the messages
    int_u_hat: np.ndarray  # (N, N, n): ∫(ⁱû_g + Γᵢᵀ Δuᵢ)
    int_u_own: np.ndarray  # (N, n): ∫uᵢ, robot i's own nominal input

    @classmethod
    def initial(cls, x_m0: np.ndarray, prior: np.ndarray) -> ObserverState:
        """Start with ⁱx̂(0) = the prior (the planned slots) except ⁱx̂ᵢ(0) = x_m,i(0)."""
        n = len(x_m0)
        y_hat = np.repeat(prior[None].astype(float), n, axis=0)
        y_hat[np.arange(n), np.arange(n)] = x_m0
        return cls(y_hat, np.zeros_like(y_hat), np.zeros_like(x_m0, dtype=float))

    def estimate(self, out: np.ndarray | None = None) -> np.ndarray:
        """ⁱx̂ = ⁱŷ + ∫(ⁱû_g + Γᵢᵀ Δuᵢ) for every robot (eq. 21), shape (N, N, n)."""
        return np.add(self.y_hat, self.int_u_hat, out=out)


SPARSE_FROM = 16  # team size from which messages are summed with a sparse matrix


class Messages:
    """Delivers the broadcast ŷ along the graph's edges only.

    ``neighbour_sum(y_hat)[i] = Σ_{j∈Nᵢ} (ʲŷ − ⁱŷ)`` is computed from the
    messages on edges into i, so robot i's result cannot depend on a robot
    that is not its in-neighbour.
    """

    def __init__(self, edges: tuple[tuple[int, int], ...], n: int):
        order = sorted(edges, key=lambda e: (e[1], e[0]))
        self.src = np.array([j for j, _ in order], dtype=np.intp)
        dst = np.array([i for _, i in order], dtype=np.intp)
        self.in_degree = np.bincount(dst, minlength=n).astype(float)
        # robots that hear someone, and where their incoming edges start in src
        self.rows = np.flatnonzero(self.in_degree > 0)
        self.starts = np.searchsorted(dst, self.rows)
        # edges into robot i are src[first_edge[i]:first_edge[i + 1]] (every robot, for kernels)
        self.first_edge = np.searchsorted(dst, np.arange(n + 1)).astype(np.intp)
        # large teams: a sparse adjacency (non-zeros only on the edges) sums the messages
        # without gathering a copy of every one (N = 100: 142 -> ~20 us a step)
        self.adjacency = None
        if n >= SPARSE_FROM and len(self.src):
            from scipy.sparse import csr_matrix

            self.adjacency = csr_matrix((np.ones(len(self.src)), (dst, self.src)), shape=(n, n))

    def neighbour_sum(self, y_hat: np.ndarray) -> np.ndarray:
        """Σ_{j∈Nᵢ} (ʲŷ − ⁱŷ) for every robot i, shape (N, N, n)."""
        out = -self.in_degree[:, None, None] * y_hat
        if self.adjacency is not None:
            n = len(y_hat)
            out += (self.adjacency @ y_hat.reshape(n, -1)).reshape(y_hat.shape)
        elif len(self.src):
            received = np.add.reduceat(y_hat[self.src], self.starts, axis=0)
            if len(self.rows) == len(out):
                out += received
            else:
                out[self.rows] += received
        return out


def residual(state: ObserverState, messages: Messages, x_m: np.ndarray) -> np.ndarray:
    """ⁱr = Σ_{j∈Nᵢ}(ʲŷ − ⁱŷ) + Πᵢ(y_m − ⁱŷ) for every robot (eq. 35), shape (N, N, n).

    Πᵢ y_m uses only robot i's own data: y_m,i = x_m,i − ∫uᵢ (eq. 21, NOTES 2).
    """
    r = messages.neighbour_sum(state.y_hat)
    idx = np.arange(len(x_m))
    r[idx, idx] += x_m - state.int_u_own - state.y_hat[idx, idx]
    return r


def update(
    state: ObserverState,
    r: np.ndarray,
    u_hat_g: np.ndarray,
    delta_u: np.ndarray,
    u: np.ndarray,
    ko: float,
    dt: float,
) -> None:
    """Advance the observer by one control period, in place (eqs. 19-21, forward Euler).

    ``u_hat_g`` (N, N, n) is ⁱû_g, ``delta_u`` (N, n) is Δuᵢ (eq. 22) and
    ``u`` (N, n) the nominal input uᵢ of eq. 8 each robot applied.
    """
    idx = np.arange(len(u))
    state.y_hat += (ko * dt) * r  # d/dt ⁱŷ = k_o ⁱr (eq. 19 in y-form)
    state.int_u_hat += dt * u_hat_g  # ∫ ⁱû_g
    state.int_u_hat[idx, idx] += dt * delta_u  # ∫ Γᵢᵀ Δuᵢ
    state.int_u_own += dt * u  # ∫ uᵢ, for y_m (eq. 21)
