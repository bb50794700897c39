"""Checks across tables of a scenario that its readers cannot make alone: a
``[[network.links]]`` latency on a link the graph does not have, a generated graph's
parameter beyond the team's size, a ``team.graph_family`` that does not describe the edges.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..core.graph import Graph, k_nearest, line_with_back_links, ring_with_chords
from ..runtime.tomlcheck import Doc
from .parts import Network, Team


def cross_problems(doc: Doc, fields: dict[str, Any]) -> None:
    """Record every problem across the tables of a read scenario (``fields``: the
    :class:`~.model.Scenario`'s)."""
    team = fields.get("team")
    if not isinstance(team, Team) or team.graph is None:
        return
    link_problems(doc, fields.get("network"), team.graph)
    graph_problems(doc, team)


def link_problems(doc: Doc, net: Network | None, graph: Graph | None) -> None:
    """Record each ``[[network.links]]`` latency on a link the team's graph does not have
    (its losses are checked where the team is read): such a latency set the whole team's
    observer round (R) for a link that carries nothing."""
    if net is None or graph is None:
        return
    edges = set(graph.edges)
    numbered = f"robots numbered from 1 to {graph.n}"
    for k, (link, _) in enumerate(net.link_latency):
        if link in edges or link in (lk for lk, _ in net.link_loss):
            continue  # a link with a loss too is said once, by the loss check
        outside = [r + 1 for r in link if not 0 <= r < graph.n]
        why = (
            f"names robot {outside[0]}, which is not in the team"
            if outside
            else "is not a link of team.graph"
        )
        table = doc.data.get("network") if isinstance(doc.data, dict) else None
        given = table.get("links") if isinstance(table, dict) else None
        which = next(
            (
                i
                for i, lt in enumerate(given if isinstance(given, list) else [])
                if isinstance(lt, dict)
                and "latency" in lt
                and lt.get("link") == [link[0] + 1, link[1] + 1]
            ),
            k,
        )
        doc.record(
            f"network.links[{which + 1}].link",
            f"[{link[0] + 1}, {link[1] + 1}] {why} ([from, to], {numbered}); its latency would "
            "set the round every observer steps by, for a link that carries nothing",
        )


def _raw(doc: Doc, *keys: str) -> Any:
    node: Any = doc.data
    for k in keys:
        node = node.get(k) if isinstance(node, dict) else None
    return node


def graph_problems(doc: Doc, team: Team) -> None:
    """A generated graph's ``k`` or ``in_degree`` beyond N − 1 (clamped without a word
    before), and a ``graph_family`` given beside an edge list that it does not describe."""
    n = team.robots
    generated = _raw(doc, "team", "graph")
    if isinstance(generated, dict):
        for key, what in (("k", "neighbours"), ("in_degree", "robots it hears")):
            v = generated.get(key)
            if (
                isinstance(v, int)
                and not isinstance(v, bool)
                and v > n - 1
                and doc.ok(f"team.graph.{key}")
            ):
                doc.record(
                    f"team.graph.{key}",
                    f"expected at most N - 1 = {n - 1} (a robot of a team of {n} has {n - 1} "
                    f"teammates), got {v}: a graph cannot give a robot {v} {what}",
                )
        return
    family = team.graph_family
    if family == "explicit" or not doc.ok("team.graph", "team.graph_family"):
        return
    if not _matches(team.graph, family, np.asarray(team.initial_positions, float)):
        doc.record(
            "team.graph_family",
            f"{family!r} does not describe the edges of team.graph (reports and campaign rows "
            f"would label this graph {family!r}); expected the family the edges were generated "
            'by, "explicit", or no graph_family',
        )


def _matches(graph: Graph, family: str, x0: np.ndarray) -> bool:
    """Whether ``graph`` is one that ``family`` generates for these robots."""
    n, edges = graph.n, set(graph.edges)
    if family == "line":
        return edges == set(line_with_back_links(n).edges)
    if family == "ring_chords":
        chords = tuple(sorted({(i - j) % n for j, i in edges} - {1}))
        return edges == set(ring_with_chords(n, chords).edges)
    if family == "knn":
        # each robot links its k nearest both ways: it has at least k links out
        out = np.bincount([j for j, _ in edges], minlength=n)
        top = int(out.min()) if n else 0
        return len(x0) == n and any(edges == set(k_nearest(x0, k).edges) for k in range(top, 0, -1))
    if family == "random":  # a ring plus in-edges until every robot hears exactly d
        return len(set(graph.in_degree().tolist())) == 1 and graph.is_strongly_connected()
    return True
