"""Communication graph of the team (paper §3.1).

Robots are indexed from 0 inside the code and shown from 1 to users. An edge
``(j, i)`` means robot ``i`` receives messages from robot ``j`` (j is an
in-neighbour of i), so the adjacency has ``a[i, j] = 1``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components, shortest_path


@dataclass(frozen=True)
class Graph:
    """A directed graph on ``n`` robots, edges as 0-based ``(from, to)`` pairs."""

    n: int
    edges: tuple[tuple[int, int], ...]

    def adjacency(self) -> np.ndarray:
        """Adjacency matrix ``A`` with ``a[i, j] = 1`` iff ``j -> i`` (§3.1)."""
        a = np.zeros((self.n, self.n))
        for j, i in self.edges:
            a[i, j] = 1.0
        return a

    def laplacian(self) -> np.ndarray:
        """Laplacian ``L = diag(d) - A`` with ``d_i`` the in-degree (§3.1)."""
        a = self.adjacency()
        return np.diag(a.sum(axis=1)) - a

    def in_degree(self) -> np.ndarray:
        """In-degree ``d_i = |N_i|`` of every robot (from the edges: no N x N matrix)."""
        dst = np.fromiter((i for _, i in self.edges), dtype=np.intp, count=len(self.edges))
        return np.bincount(dst, minlength=self.n).astype(float)

    def in_neighbours(self, i: int) -> list[int]:
        """The robots whose messages robot ``i`` receives."""
        return sorted(j for j, k in self.edges if k == i)

    def is_strongly_connected(self) -> bool:
        """True when a directed path joins every ordered pair of robots."""
        if self.n <= 1:
            return True
        src = [j for j, _ in self.edges]
        dst = [i for _, i in self.edges]
        m = csr_matrix((np.ones(len(src)), (src, dst)), shape=(self.n, self.n))
        count, _ = connected_components(m, directed=True, connection="strong")
        return bool(count == 1)

    def without(self, k: int, relay: bool = False) -> Graph:
        """The graph with robot ``k`` and its edges removed; later robots shift down by one.

        ``relay``: ``k`` stays on the network as a static relay (an excluded robot whose
        radio still works): every message it heard from j it forwards to every i it spoke
        to, so j -> i joins the survivors' graph for each j -> k -> i."""

        def shift(v: int) -> int:
            return v - 1 if v > k else v

        kept = {(shift(j), shift(i)) for j, i in self.edges if k not in (j, i)}
        if relay:
            heard = [j for j, i in self.edges if i == k]
            told = [i for j, i in self.edges if j == k]
            kept |= {(shift(j), shift(i)) for j in heard for i in told if j != i}
        return Graph(self.n - 1, tuple(sorted(kept)))

    def rewired(self, k: int) -> tuple[Graph, list[tuple[int, int]]]:
        """The graph without robot ``k`` whose survivors took over its links (j → i for each
        j → k → i: a path through k has a shortcut, so strong connectivity is kept), and the
        links added (numbered as in the new graph)."""
        plain, wired = self.without(k), self.without(k, relay=True)
        return wired, sorted(set(wired.edges) - set(plain.edges))

    def components(self) -> list[list[int]]:
        """The strongly connected components (0-based robots), largest first."""
        src = [j for j, _ in self.edges]
        dst = [i for _, i in self.edges]
        m = csr_matrix((np.ones(len(src)), (src, dst)), shape=(self.n, self.n))
        _, label = connected_components(m, directed=True, connection="strong")
        groups = [np.flatnonzero(label == c).tolist() for c in range(int(label.max()) + 1)]
        return sorted(groups, key=lambda g: (-len(g), g))

    def unheard(self) -> np.ndarray:
        """(n, n) bool: ``[i, k]`` when no directed path leads from k to i, so robot i's
        estimate of robot k is not driven by k's measurements and has no bound (eq. 19)."""
        src = [j for j, _ in self.edges]
        dst = [i for _, i in self.edges]
        m = csr_matrix((np.ones(len(src)), (src, dst)), shape=(self.n, self.n))
        reach = np.isfinite(shortest_path(m, directed=True, unweighted=True))  # [k, i]
        return ~reach.T


# --------------------------------------------------------------------------- generated graphs


def ring_with_chords(n: int, chords: tuple[int, ...] = ()) -> Graph:
    """Directed ring i -> i+1 plus, for each c in ``chords``, i -> i+c (mod n)."""
    edges = {(i, (i + 1) % n) for i in range(n)}
    for c in chords:
        edges |= {(i, (i + c) % n) for i in range(n) if (i + c) % n != i}
    return Graph(n, tuple(sorted(edges)))


def line_with_back_links(n: int) -> Graph:
    """Robots in a line, each talking with the next both ways: i ⇄ i + 1. Strongly
    connected, and every inner robot is a cut: excluding it splits the team."""
    edges = [(i, i + 1) for i in range(n - 1)] + [(i + 1, i) for i in range(n - 1)]
    return Graph(n, tuple(sorted(edges)))


def random_strongly_connected(n: int, in_degree: int, rng: np.random.Generator) -> Graph:
    """A random ring (a random order, so strongly connected) plus random in-edges until
    every robot hears exactly ``in_degree`` others (at most n − 1)."""
    d = min(in_degree, n - 1)
    order = rng.permutation(n)
    edges = {(int(order[k]), int(order[(k + 1) % n])) for k in range(n)}
    for i in range(n):
        have = {j for j, k in edges if k == i}
        pool = np.array([j for j in range(n) if j != i and j not in have])
        extra = rng.choice(pool, size=max(0, d - len(have)), replace=False)
        edges |= {(int(j), i) for j in extra}
    return Graph(n, tuple(sorted(edges)))


def k_nearest(positions: np.ndarray, k: int) -> Graph:
    """Undirected graph linking each robot to its k nearest (by ``positions``), made
    connected by joining nearest pairs across components."""
    n = len(positions)
    dist = np.linalg.norm(positions[:, None] - positions[None], axis=2)
    np.fill_diagonal(dist, np.inf)
    pairs: set[tuple[int, int]] = set()
    for i in range(n):
        for j in np.argsort(dist[i])[: min(k, n - 1)]:
            pairs |= {(i, int(j)), (int(j), i)}
    g = Graph(n, tuple(sorted(pairs)))
    while not g.is_strongly_connected():
        _, labels = connected_components(
            csr_matrix((np.ones(len(g.edges)), tuple(np.array(g.edges).T)), shape=(n, n)),
            directed=False,
        )
        a = labels == labels[0]
        sub = np.where(a[:, None] & ~a[None, :], dist, np.inf)
        ii, jj = np.unravel_index(np.argmin(sub), sub.shape)
        g = Graph(n, tuple(sorted(set(g.edges) | {(int(ii), int(jj)), (int(jj), int(ii))})))
    return g


def reaches_all(graph: Graph) -> np.ndarray:
    """(N,) bool: robot k reaches every robot along the edges, i.e. M_k is positive
    stable (the grounded Laplacian L + e_k e_kᵀ is then a non-singular M-matrix)."""
    n = graph.n
    if graph.is_strongly_connected():
        return np.ones(n, bool)
    e = np.array(graph.edges, dtype=np.int64).reshape(-1, 2)
    m = csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return np.array([len(breadth_first_order(m, k, directed=True)[0]) == n for k in range(n)])


def rotation_invariant(graph: Graph) -> bool:
    """The graph is invariant under the rotation i -> i + 1 (rings, rings with chords):
    M_k = R^k M_0 R^{-k} with R the rotation, so every monitored robot sees the same
    matrices and [f(M_k)]_{ik} = [f(M_0)]_{(i − k) mod N, 0}."""
    n = graph.n
    edges = set(graph.edges)
    return n > 1 and {((j + 1) % n, (i + 1) % n) for j, i in edges} == edges
