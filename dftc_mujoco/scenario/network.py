"""Reading the ``[network]`` table (:class:`~.parts.Network`; the medium itself is
:mod:`dftc_mujoco.closed_loop.network`)."""

from __future__ import annotations

import numpy as np

from ..runtime.tomlcheck import Table, number_or_word
from .parts import Network, Physics, RadioFault


def read_network(t: Table, physics: Physics | None, faults: tuple[RadioFault, ...]) -> Network:
    """The ``[network]`` table: latency (a number, or {mean, max}), rate, loss and its
    model, the declared bound on consecutive losses, the range (docs/thresholds.md)."""
    raw = t.data.get("latency", 0.0)
    latency_max = None
    if isinstance(raw, dict):
        lat = t.table("latency")
        latency = lat.number("mean", low=0.0)
        latency_max = lat.number("max", low=0.0)
        lat.finish()
        if lat.ok("mean", "max") and latency_max < latency:
            lat.report("max", f"expected at least mean = {latency:g} s, got {latency_max:g}")
    else:
        latency = t.number("latency", 0.0, low=0.0, strict_low=False)
    h = physics.control_period if physics is not None else None
    rate = None
    if t.given("rate"):
        rate = t.number("rate", low=0.0)
        if h is not None and t.ok("rate") and rate * h > 1 + 1e-9:
            t.report(
                "rate",
                f"a robot sends at most once a control period: expected at most "
                f"{1 / h:g} messages per second, got {rate:g}",
            )
    loss = t.number("loss", 0.0, low=0.0, strict_low=False, high=1.0)
    model = t.string("loss_model", "bernoulli", choices=("bernoulli", "gilbert_elliott"))
    burst = {}
    for key, default in (("p_bad", 0.0), ("p_good", 1.0), ("loss_bad", 1.0)):
        if key in t.data and model != "gilbert_elliott":
            t.report(key, 'only with loss_model = "gilbert_elliott"')
        burst[key] = t.number(key, default, low=0.0, strict_low=False, high=1.0)
    bound = None
    if t.given("max_consecutive_losses"):
        bound = t.integer("max_consecutive_losses", low=0, high=10**6)
    reach = None
    if t.given("range"):
        reach = t.number("range", low=0.0)
    hysteresis = t.number("range_hysteresis", 0.0, low=0.0, strict_low=False)
    if reach is not None and t.ok("range", "range_hysteresis") and hysteresis >= reach:
        t.report("range_hysteresis", f"expected less than range = {reach:g} m, got {hysteresis:g}")
    if reach is None and "range_hysteresis" in t.data:
        t.report("range_hysteresis", "only with a range")
    link_loss: list[tuple[tuple[int, int], float]] = []
    link_latency: list[tuple[tuple[int, int], float]] = []
    for lt in t.tables("links"):  # [[network.links]]: link = [from, to], loss = p, latency = s
        link = lt.array("link", (2,), what="[from, to], robots numbered from 1")
        p = lt.number("loss", low=0.0, strict_low=False, high=1.0) if lt.given("loss") else None
        d = lt.number("latency", low=0.0, strict_low=False) if lt.given("latency") else None
        lt.finish()
        if "loss" not in lt.data and "latency" not in lt.data:
            lt.report("link", "expected a loss, a latency or both for the link")
        elif lt.ok("link") and np.all(link == np.round(link)):
            pair = (int(link[0]) - 1, int(link[1]) - 1)
            if p is not None:
                link_loss.append((pair, p))
            if d is not None:
                link_latency.append((pair, d))
        elif lt.ok("link"):
            lt.report("link", f"expected two robot numbers, got {link.tolist()}")
    what = "a distance in m"
    tolerance = number_or_word(t, "sighting_tolerance", "auto", what, strict_low=False)
    window = None
    if t.given("connectivity_window"):
        window = t.number("connectivity_window", low=0.0)
    sighting_range = None
    if t.given("sighting_range"):
        sighting_range = t.number("sighting_range", low=0.0, strict_low=False)
    t.finish()
    net = Network(
        latency=latency,
        latency_max=latency_max,
        rate=rate,
        loss=loss,
        loss_model=model,
        max_consecutive_losses=bound,
        range=reach,
        range_hysteresis=hysteresis,
        faults=faults,
        link_loss=tuple(link_loss),
        link_latency=tuple(link_latency),
        sighting_tolerance=tolerance,
        sighting_range=sighting_range,
        connectivity_window=window,
        **burst,
    )
    if bound is None and any(p >= 1 for _, p in link_loss):
        t.report("links", "a link that loses every message needs max_consecutive_losses")
    if (
        net.lossy
        and bound is None
        and (loss >= 1 or (model == "gilbert_elliott" and burst["p_good"] == 0))
    ):
        t.report("loss", "every message would be lost: give max_consecutive_losses")
    if bound == 0 and net.lossy:  # a bound of 0 would drop none of the losses asked for
        t.report(
            "max_consecutive_losses",
            "0 lets no message be lost, which cancels the losses given (loss, loss_model or "
            "links); expected at least 1, or no losses",
        )
    return net
