"""Set-up cost of the FDIR thresholds: κ/λ (eq. 41), each rule's tables, Δt_d and a restart.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 \\
        python benchmarks/bench_setup.py [--n 4 16 64 100 200 400] [--repeat 3] [--json out.json]

For every N and graph family (ring with chords 2 and 5, random with in-degree 3, k = 3
nearest neighbours on a grid of 0.5 m), with k_o = 3, h = 0.01 s, η̄ = 1 mm, ξ̄ = 5 mm/s
and, for l1 and block_row, ē = ‖G‖Φ̄ + 2η̄ (what the compensation adds, 4 mm): the median
over ``--repeat`` runs (numba's cache loaded first, κ/λ's per-graph cache cleared) of

* ``kappa``: κ_k, λ_k of eq. 41 for every robot (what ``thresholds = "paper"`` needs),
* for each rule (paper, l1, drive, block_row up to N = 64): its set-up on the graph, the
  predicted ⁱΔt_d of eq. 46 for a constant 0.1 m/s fault over the faulty robot's teammates
  (what ``fdir.dt_d_max = "auto"`` takes)
  and the restart after robot 1 is excluded at t = 60 s;

and, once, each rule's steady thresholds (min-max over i, k) and the largest ⁱΔt_d.
BLAS must be pinned to one thread by the environment, as above (the script refuses
otherwise), so that the figures are per core.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

KO, H, ETA, XI, FAULT = 3.0, 0.01, 0.001, 0.005, 0.1
FAMILIES = ("ring_chords", "random", "knn")


def graph_of(family: str, n: int):
    """The family's graph on n robots, as the scenarios generate it."""
    from dftc_mujoco.core.graph import k_nearest, random_strongly_connected, ring_with_chords
    from dftc_mujoco.core.mission import grid_offsets

    if family == "ring_chords":
        return ring_with_chords(n, tuple(c for c in (2, 5) if c < n))
    if family == "random":
        return random_strongly_connected(n, 3, np.random.default_rng([1, 11]))
    return k_nearest(grid_offsets(n, 0.5), 3)


def median_time(fn, repeat: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def rules(offset: float) -> dict:
    from dftc_mujoco.onboard.thresholds import BLOCK_ROW_MAX, L1, BlockRow, Drive, Thresholds

    return {
        "paper": (Thresholds, {}, 10**9),
        "l1": (L1, {"drift_bound": offset}, 10**9),
        "drive": (Drive, {}, 10**9),
        "block_row": (BlockRow, {"drift_bound": offset}, BLOCK_ROW_MAX),
    }


def build(cls, params: dict, graph):
    """The rule on ``graph`` as a team would set it up (initial error bound 1 m)."""
    from dftc_mujoco.onboard.block import TeamConfig
    from dftc_mujoco.scenario import Formation

    config = TeamConfig(
        graph=graph, kc=4.0, ko=KO, K=3.0 * np.eye(2), G=0.01 * np.eye(2), theta=3.0, dt=H,
        eta_bar=ETA, xi_bar=XI, formation=Formation(), obstacle_position=np.zeros((0, 2)),
        obstacle_safe=np.zeros(0), obstacle_activation=np.zeros(0),
    )  # fmt: skip
    rule = cls(**params)
    x0 = np.zeros((graph.n, 2))
    rule.reset(config, x0, x0)
    return rule


def one(family: str, n: int, repeat: int) -> dict:
    from dftc_mujoco.onboard.thresholds import decay, estimator_gain, predicted_delays

    graph = graph_of(family, n)
    offset = 0.01 * estimator_gain(3 * np.eye(2), 0.01 * np.eye(2), H, ETA, XI) + 2 * ETA

    def kappa():
        decay._cached_decay_bounds.cache_clear()
        return decay.decay_bounds(graph, KO)

    row: dict = {"family": family, "n": n, "max_in_degree": int(graph.in_degree().max())}
    row["kappa_s"], (k, lam) = median_time(kappa, repeat)
    row["kappa_over_lambda"] = [float((k / lam).min()), float((k / lam).max())]
    reduced = graph.without(0)
    for name, (cls, params, limit) in rules(offset).items():
        if n > limit:
            continue

        def setup(cls=cls, params=params):
            decay._cached_decay_bounds.cache_clear()
            return build(cls, params, graph)

        entry: dict = {}
        entry["setup_s"], rule = median_time(setup, repeat)
        steady = np.array(rule.mu(1e9), dtype=float)
        entry["steady_mm"] = [float(steady.min() * 1e3), float(steady.max() * 1e3)]
        entry["delays_s"], delays = median_time(
            lambda steady=steady: predicted_delays(graph, KO, H, steady, FAULT), repeat
        )
        off = delays[~np.eye(len(delays), dtype=bool)]  # the teammates: as dt_d_max = "auto"
        entry["dt_d_max_s"] = float(off.max()) if np.isfinite(off).all() else None

        # the restart replaces the rule's tables: rebuild it (untimed) before each repeat
        times = []
        for _ in range(repeat):
            fresh = build(cls, params, graph)
            decay._cached_decay_bounds.cache_clear()
            t0 = time.perf_counter()
            fresh.drop(0, reduced, 60.0)
            times.append(time.perf_counter() - t0)
        entry["restart_s"] = statistics.median(times)
        tables = getattr(fresh, "env", None)
        if tables is not None:
            entry["intervals"] = len(tables.bp)
        row[name] = entry
    return row


def warm_up() -> None:
    """Load numba's cache (and compile on a first run) on a small graph."""
    small = graph_of("random", 12)
    for cls, params, _ in rules(0.004).values():
        rule = build(cls, params, small)
        rule.drop(0, small.without(0), 5.0)
    from dftc_mujoco.onboard.thresholds import decay, predicted_delays

    decay._decay_bounds_fast(small, KO)
    predicted_delays(small, KO, H, np.full((12, 12), 0.003), FAULT)


def table(rows: list[dict]) -> str:
    """The Markdown tables of the results."""
    out = [
        "| family | N | κ/λ | paper set-up / restart | l1 set-up / Δt_d / restart | "
        "drive set-up / Δt_d / restart | block_row set-up / restart |",
        "|---|---|---|---|---|---|---|",
    ]

    def cell(r: dict, name: str, parts: tuple[str, ...]) -> str:
        e = r.get(name)
        if e is None:
            return "—"
        return " / ".join(f"{e[p]:.3f} s" for p in parts)

    for r in rows:
        out.append(
            f"| {r['family']} | {r['n']} | {r['kappa_s']:.3f} s | "
            f"{cell(r, 'paper', ('setup_s', 'restart_s'))} | "
            f"{cell(r, 'l1', ('setup_s', 'delays_s', 'restart_s'))} | "
            f"{cell(r, 'drive', ('setup_s', 'delays_s', 'restart_s'))} | "
            f"{cell(r, 'block_row', ('setup_s', 'restart_s'))} |"
        )
    out += [
        "",
        "| family | N | paper steady [mm] | l1 steady [mm] | drive steady [mm] | "
        "block_row steady [mm] | Δt_d,max 0.1 m/s: paper / l1 / drive / block_row |",
        "|---|---|---|---|---|---|---|",
    ]

    def rng(r: dict, name: str) -> str:
        e = r.get(name)
        return "—" if e is None else f"{e['steady_mm'][0]:.2f}–{e['steady_mm'][1]:.2f}"

    def dt(r: dict, name: str) -> str:
        e = r.get(name)
        if e is None:
            return "—"
        return "∞" if e["dt_d_max_s"] is None else f"{e['dt_d_max_s']:.2f} s"

    for r in rows:
        out.append(
            f"| {r['family']} | {r['n']} | {rng(r, 'paper')} | {rng(r, 'l1')} | "
            f"{rng(r, 'drive')} | {rng(r, 'block_row')} | "
            + " / ".join(dt(r, name) for name in ("paper", "l1", "drive", "block_row"))
            + " |"
        )
    return "\n".join(out)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, nargs="+", default=[4, 16, 64, 100, 200, 400])
    p.add_argument("--family", nargs="+", default=list(FAMILIES), choices=FAMILIES)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--json", help="also write the results to this file")
    args = p.parse_args()
    pinned = all(os.environ.get(v) == "1" for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS"))
    if not pinned:
        sys.exit("error: set OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1")
    warm_up()
    rows = []
    for n in args.n:
        for family in args.family:
            rows.append(one(family, n, args.repeat))
            print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    print(table(rows))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)


if __name__ == "__main__":
    main()
