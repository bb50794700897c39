"""The network between the robots' radios: who hears whom, when, and what arrives.

The scenario's graph names the *allowed* links (j hears i only if [i, j] is an edge); the
``[network]`` table (:class:`~dftc_mujoco.scenario.Network`) says what happens on them.
One control period ``p`` of the medium, around the team's step:

* :meth:`Channel.receive` (before the step): the messages whose delay ends now arrive;
  a link keeps the newest (by the round it carries) and the receiver learns its age;
* :meth:`Channel.send` (after the step): every robot whose broadcast is due sends its
  ŷ; each link draws the message's fate: lost (Bernoulli or Gilbert–Elliott, never more
  than ``max_consecutive_losses`` in a row), out of range, cut by a radio fault, or
  delayed by the latency (fixed or random up to ``latency_max``).

Timing (docs/thresholds.md, "Over a network"): a message sent at the end of period q
arrives at the start of period q + 1 + ℓ, ℓ the latency in periods (ideal: ℓ = 0, the
next period). A robot broadcasts at the end of every period q with (q + 1) mod m = 0
(m periods per message, from the rate).
The observers step in *rounds* of R = L + (b + 1) m periods (L the largest latency in
periods, b the declared bound on consecutive losses): round s runs at period s R on the
messages of round s (round 0 on ŷ(0), which the robots exchange before the start), and
with delays ≤ L and ≤ b losses in a row every one of them has arrived by then. On the
ideal network R = 1: the paper's observer.

This module is the simulator's: it reads the robots' true positions (for the range) and
the radio faults, which no robot knows. It never imports MuJoCo or an onboard block; the
robots see only what :meth:`Channel.receive` delivers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from ..core.graph import Graph
from ..onboard.radio import SILENT_ROUNDS
from ..scenario import Network

#: how many rounds of broadcasts a sender keeps (a message in flight carries the round it
#: was sent in, at most one round older than the one being sent: delays are < R)
HISTORY = 3


@dataclass(frozen=True)
class Timing:
    """The network's timing in control periods, as the onboard observers use it."""

    latency: int  # L: the largest delay of a message beyond the next period
    every: int  # m: periods between two broadcasts of a robot
    losses: int | None  # b: the declared bound on consecutive losses (None: no bound)
    round: int  # R = L + (b + 1) m: the observers' round (1: the ideal network)

    @property
    def guaranteed(self) -> bool:
        """Every round's messages arrive in time when the channel keeps its declared bounds
        (False: losses without a bound, only a statistical statement is possible)."""
        return self.losses is not None


def timing(net: Network, control_period: float) -> Timing:
    """The round R and its parts for ``net`` at ``control_period`` h [s]."""
    h = control_period
    worst = net.latency_max if net.latency_max is not None else net.latency
    worst = max([worst, *(d for _, d in net.link_latency)])  # [[network.links]] latencies
    latency = max(0, math.ceil(worst / h - 1e-9))
    every = 1 if net.rate is None else max(1, round(1.0 / (net.rate * h)))
    if net.lossy:
        losses = net.max_consecutive_losses
    else:
        losses = 0
    rounds = latency + ((losses if losses is not None else 0) + 1) * every
    return Timing(latency, every, losses, rounds)


class Channel:
    """The medium of one run: the links' state, the messages in flight, what was measured.

    ``graph`` is the allowed links (0-based robots, ``(from, to)``), ``rng`` the run's
    random state for the channel (drawn from the scenario's seed).
    """

    def __init__(
        self, net: Network, graph: Graph, control_period: float, rng: np.random.Generator
    ) -> None:
        self.net, self.graph, self.h, self.rng = net, graph, control_period, rng
        self.timing = timing(net, control_period)
        order = sorted(graph.edges, key=lambda e: (e[1], e[0]))  # the observer's edge order
        self.edges = np.array(order, dtype=np.intp).reshape(-1, 2)
        self.src, self.dst = self.edges[:, 0], self.edges[:, 1]
        e = len(self.edges)
        self._slots = self.timing.latency + 2  # a ring of arrival periods
        self._pending = np.full((e, self._slots), -1, dtype=np.int64)  # round carried
        self._sent_at = np.full((e, self._slots), -1, dtype=np.int64)  # period it left
        # the newest round each link delivered: ŷ(0), exchanged before the start
        self.newest = np.zeros(e, dtype=np.int64)
        self.held_sent = np.full(e, -1, dtype=np.int64)  # when the last copy it got left
        self.bad = np.zeros(e, bool)  # Gilbert–Elliott state of each link
        self.in_a_row = np.zeros(e, dtype=np.int64)  # consecutive losses on each link
        self.up = np.ones(e, bool)  # within range (with hysteresis)
        self.corrupting = np.zeros(graph.n)  # [m] each sender's corruption (0: none)
        self.silent = np.zeros(graph.n, bool)
        self.cut = np.zeros(e, bool)  # link_down faults
        self._faults = sorted(net.faults, key=lambda f: f.t)
        self._next_fault = 0
        self._index = {(int(j), int(i)): k for k, (j, i) in enumerate(order)}
        # what was measured, per link
        self.sent = np.zeros(e, dtype=np.int64)
        self.lost = np.zeros(e, dtype=np.int64)
        self.delivered = np.zeros(e, dtype=np.int64)
        self.delay_sum = np.zeros(e)  # [periods] of the messages delivered
        self.delay_max = np.zeros(e, dtype=np.int64)
        self.worst_run = np.zeros(e, dtype=np.int64)  # the longest run of losses seen
        self._p_loss = np.full(e, net.loss)  # per link: ``loss`` unless [[network.links]] says
        for link, p in net.link_loss:
            k = self._index.get((int(link[0]), int(link[1])))
            if k is not None:
                self._p_loss[k] = p
        self._mean_periods = net.latency / control_period
        # per link: a fixed latency in periods from [[network.links]] (-1: the global one)
        self._own_delay = np.full(e, -1, dtype=np.int64)
        for link, d in net.link_latency:
            k = self._index.get((int(link[0]), int(link[1])))
            if k is not None:
                self._own_delay[k] = max(0, math.ceil(d / control_period - 1e-9))
        self._fixed_delay = np.where(
            self._own_delay >= 0,
            self._own_delay,
            max(0, math.ceil(net.latency / control_period - 1e-9)),
        )
        self._own = self._own_delay >= 0
        self._joint_key: tuple[bytes, bytes] | None = None
        # network.connectivity_window in rounds (unset: the rounds after which a receiver
        # reports a link silent)
        given, h_o = net.connectivity_window, self.timing.round * control_period
        self.window = SILENT_ROUNDS if given is None else max(1, math.ceil(given / h_o - 1e-9))
        self._joint_parts = 1

    # ------------------------------------------------------------------ faults

    def faults_due(self, t: float) -> list[Any]:
        """Switch on the radio faults that start at or before ``t``; returns them."""
        started = []
        while self._next_fault < len(self._faults) and self._faults[self._next_fault].t <= t:
            f = self._faults[self._next_fault]
            self._next_fault += 1
            if f.kind == "silent":
                self.silent[f.robot] = True
            elif f.kind == "corrupt":
                self.corrupting[f.robot] = f.value
            elif f.kind == "link_down":
                k = self._index.get((int(f.link[0]), int(f.link[1])))
                if k is not None:
                    self.cut[k] = True
            started.append(f)
        return started

    @property
    def next_fault(self) -> float:
        """When the next radio fault starts (inf: none left)."""
        if self._next_fault < len(self._faults):
            return float(self._faults[self._next_fault].t)
        return math.inf

    # ------------------------------------------------------------------ one period

    def receive(self, period: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The messages that arrive at the start of ``period``: (links, rounds carried,
        corruption [m] of their senders), only those newer than what each link holds."""
        slot = period % self._slots
        carried = self._pending[:, slot]
        heard = (carried >= 0) & (carried >= self.newest)  # a copy of the held round counts
        self.held_sent[heard] = self._sent_at[heard, slot]
        new = np.flatnonzero(carried > self.newest)
        rounds = carried[new].copy()
        if len(new):
            delay = period - 1 - self._sent_at[new, slot]
            self.delay_sum[new] += delay
            np.maximum.at(self.delay_max, new, delay)
            self.delivered[new] += 1
            self.newest[new] = rounds
        carried[:] = -1
        self._sent_at[:, slot] = -1
        return new, rounds, self.corrupting[self.src[new]]

    def send(self, period: int, content_round: int, positions: np.ndarray) -> None:
        """The broadcasts at the end of ``period`` (if due), each carrying ``content_round``;
        ``positions`` (N, 2): the robots' true positions, for the range."""
        tm = self.timing
        if (period + 1) % tm.every:
            return
        net, e = self.net, len(self.edges)
        if e == 0:
            return
        if net.range is not None:
            d = np.hypot(*(positions[self.src] - positions[self.dst]).T)
            self.up &= d <= net.range  # a link leaves beyond the range
            self.up |= d <= net.range - net.range_hysteresis  # and comes back within
        go = self.up & ~self.cut & ~self.silent[self.src]
        self.sent += go
        if net.lossy:
            u = self.rng.random(e)
            if net.loss_model == "gilbert_elliott":
                flip = self.rng.random(e)
                self.bad = np.where(self.bad, flip >= net.p_good, flip < net.p_bad)
                p = np.where(self.bad, net.loss_bad, self._p_loss)
            else:
                p = self._p_loss
            lost = go & (u < p)
            if net.max_consecutive_losses is not None:  # the declared bound b is kept
                lost &= self.in_a_row < net.max_consecutive_losses
            self.in_a_row = np.where(lost, self.in_a_row + 1, np.where(go, 0, self.in_a_row))
            np.maximum(self.worst_run, self.in_a_row, out=self.worst_run)
            self.lost += lost
            go &= ~lost
        if not go.any():
            return
        if net.latency_max is not None:  # exponential of mean `latency`, cut at latency_max
            drawn = self.rng.exponential(max(self._mean_periods, 1e-12), e)
            top = math.ceil(net.latency_max / self.h - 1e-9)
            delay = np.minimum(np.ceil(drawn - 1e-9), top).astype(np.int64)
            delay[self._own] = self._own_delay[self._own]
        else:
            delay = self._fixed_delay
        links = np.flatnonzero(go)
        slot = (period + 1 + delay[links]) % self._slots
        newer = content_round > self._pending[links, slot]
        links, slot = links[newer], slot[newer]
        self._pending[links, slot] = content_round
        self._sent_at[links, slot] = period

    # ------------------------------------------------------------------ the graph

    def joint_components(self, s: int, members: np.ndarray) -> int:
        """How many strongly connected parts the members' graph has when it is made of the
        links that delivered a message of the last :attr:`window` rounds, at round ``s`` (1:
        the graph over that window is strongly connected, the consensus's premise)."""
        fresh = self.newest >= s - self.window + 1
        key = (fresh.tobytes(), members.tobytes())
        if key != self._joint_key:
            inside = np.zeros(self.graph.n, bool)
            inside[members] = True
            keep = fresh & inside[self.src] & inside[self.dst]
            index = np.full(self.graph.n, -1)
            index[members] = np.arange(len(members))
            m = len(members)
            adj = csr_matrix(
                (np.ones(int(keep.sum())), (index[self.src[keep]], index[self.dst[keep]])),
                shape=(m, m),
            )
            parts, _ = connected_components(adj, directed=True, connection="strong")
            self._joint_key, self._joint_parts = key, int(parts)
        return self._joint_parts

    # ------------------------------------------------------------------ records

    def ages(self, period: int, out: np.ndarray) -> None:
        """How long ago [s] the last message each link delivered (of its newest round) left
        its sender, at the start of ``period``, into ``out`` (E,)."""
        np.multiply(period - 1 - self.held_sent, self.h, out=out)

    def bounds(self) -> tuple[float, float]:
        """The ages [s] a link's message has at most when no message was lost (L periods)
        and when at most b were (a round, R periods): beyond it the premise breaks."""
        tm = self.timing
        return tm.latency * self.h, tm.round * self.h

    def summary(self) -> dict[str, Any]:
        """What the channel did per link: messages sent, lost, rounds received, their delay [s]
        (mean and largest, beyond the ideal network's next period) and the longest run of
        losses; the timing it was run with."""
        h = self.h
        links = []
        for k, (j, i) in enumerate(self.edges):
            n = int(self.delivered[k])
            links.append(
                {
                    "link": [int(j) + 1, int(i) + 1],
                    "sent": int(self.sent[k]),
                    "lost": int(self.lost[k]),
                    "rounds_received": n,  # messages that brought a newer round
                    "loss_rate": float(self.lost[k] / self.sent[k]) if self.sent[k] else None,
                    "delay_mean": float(self.delay_sum[k] / n * h) if n else None,
                    "delay_max": float(self.delay_max[k] * h) if n else None,
                    "longest_loss_run": int(self.worst_run[k]),
                }
            )
        tm = self.timing
        return {
            "ideal": self.net.ideal,
            "round_periods": tm.round,
            "latency_periods": tm.latency,
            "send_every_periods": tm.every,
            "max_consecutive_losses": tm.losses,
            "links": links,
        }


def refusals(s: Any, rule: str, where: str) -> tuple[list[str], list[str]]:
    """What a scenario's network makes meaningless (refused) or only statistical (warned),
    one line each, before simulating: (refusals, warnings)."""
    net = s.network
    if net.ideal:
        return [], []
    h = s.physics.control_period
    tm = timing(net, h)
    refused: list[str] = []
    warned: list[str] = []
    if rule == "paper":
        refused.append(
            f'{where}: network: eq. 40\'s thresholds (onboard.thresholds = "paper") are a '
            "continuous-time bound, not derived for the observers' rounds over a network; "
            'use onboard.thresholds = "l1", "block_row" or "drive" (docs/thresholds.md, '
            '"Over a network")'
        )
    if s.fdir.excluded_relay or s.fdir.rewire in ("adopt", "relay"):
        key = "excluded_relay" if s.fdir.excluded_relay else "rewire"
        refused.append(
            f"{where}: fdir.{key}: re-wiring the survivors after an exclusion (links adopted "
            "or relayed) is modelled for the ideal network only: the radios of a [network] "
            'carry the scenario\'s links; set fdir.rewire = "none" (or leave it "auto")'
        )
    if tm.round * h > s.duration:  # and its ring of messages in flight would not fit
        refused.append(f"{where}: {_longest_part(net, tm, h)}")
        return refused, warned
    d = int(s.team.graph.in_degree().max()) if s.team.graph.edges else 0
    h_o = h * tm.round
    why = (
        f"the observers step once a round of the network, R = {tm.round} periods (latency "
        f"{tm.latency} + ({tm.losses or 0} losses + 1) x {tm.every} periods between messages)"
    )
    if rule in ("l1", "block_row", "drive"):  # the rules need A_k >= 0 at the round
        worst = s.gains.ko * h_o * (d + 1)
        if worst > 1 + 1e-12:
            refused.append(
                f"{where}: gains.ko: {why}, and rule {rule!r} needs ko * R * control_period * "
                f"(max in-degree + 1) <= 1, got {worst:.3g}: lower ko to at most "
                f"{1 / (h_o * (d + 1)):.3g}, or the latency, the loss bound or the message period"
            )
    else:
        gain = s.gains.ko * h_o * (2 * d + 1)
        if gain >= 2:
            refused.append(
                f"{where}: gains.ko: {why}, and ko * R * control_period * (2 * max in-degree "
                f"+ 1) = {gain:.3g} makes that step unstable (expected < 2): lower ko below "
                f"{2 / (h_o * (2 * d + 1)):.3g}, or the latency, the loss bound or the message "
                "period"
            )
    if not tm.guaranteed:
        warned.append(
            "network: losses have no bound (network.max_consecutive_losses is not set): a "
            "round's message may be missing, and then the thresholds hold no more than "
            "statistically; flags after a missed message are labelled with premise 'network'"
        )
    return refused, warned


def _longest_part(net: Network, tm: Timing, h: float) -> str:
    """``key: why`` for a round longer than the mission, naming the key that makes it so."""
    said = (
        f"the observers would step once a round of R = {tm.round} periods ({tm.round * h:g} s: "
        f"latency {tm.latency} + ({tm.losses or 0} losses + 1) x {tm.every} periods between "
        "messages), longer than the whole mission: no message would arrive before its end"
    )
    if tm.latency >= ((tm.losses or 0) + 1) * tm.every:
        worst = net.latency_max if net.latency_max is not None else net.latency
        key = "network.latency" + (".max" if net.latency_max is not None else "")
        for k, (_, d) in enumerate(net.link_latency):
            if d > worst:
                worst, key = d, f"network.links[{k + 1}].latency"
        return f"{key}: {worst:g} s: {said}; expected a latency in s (20 ms is 0.02)"
    if tm.every > 1 and (tm.losses or 0) + 1 < tm.every:
        return f"network.rate: {net.rate:g} messages/s: {said}; expected messages per second"
    return f"network.max_consecutive_losses: {tm.losses}: {said}; expected a smaller bound"
