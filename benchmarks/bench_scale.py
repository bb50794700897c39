"""Scale benchmark: N = 4, 16, 64, 100 (up to 1000) on the same kind of scene.

    python benchmarks/bench_scale.py [--n 4 16 64 100] [--duration 20]
    python benchmarks/bench_scale.py --n 1000 --duration 30 --repeat 1
    python benchmarks/bench_scale.py --n 100 --network     # the network's cost
    python benchmarks/bench_scale.py --n 1000 --duration 20 --repeat 1 --sparse

``--sparse``: the graph a benchmark does not choose: a ring in both directions with a
chord into a quarter of the robots (in-degree 2-3, :func:`sparse_ring`), which mixes
slowly and is not invariant under rotation, with the l1 rule and ``fdir.dt_d_max =
"auto"``: every robot's columns are swept at set-up (no symmetry to share them).

``--network``: each N twice, on the ideal network and over a lossy, delayed,
range-limited one (:data:`NETWORK`), both with the l1 rule at k_o = 2 (the round of that
network needs k_o R h (d_max + 1) <= 1), and the network's cost as the loop's ratio.

For each N, in a fresh process (so peak memory is that process's own): a grid
formation of 0.5 m spacing, a ring with chords 2 and 5, no cylinders, a stop
fault at half time. Reports the κ/λ computation (part of the onboard
set-up), the whole set-up of a Simulation, µs per control period of the
closed loop and of bare ``mj_step`` replaying the run's own commands (median
of ``--repeat``, numba's cache loaded before timing: see ``replay.py``), their
ratio, the real-time factor of the loop alone and with the cold set-up (the first
Simulation of the fresh process: κ/λ, numba's cache) and post-run derivation, the peak
resident memory of the benchmark's process (its warm-up, recording and timed runs), the wall
time of the whole process (imports included), whether the replay ended in the closed loop's
final state bit for bit (the exact floor), and the peak memory of one run alone in a fresh
process (``--peak-duration`` s, as ``python -m dftc_mujoco.run`` makes it, figures aside).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

#: the network of ``--network``: 50 ms, 10 % Bernoulli loss (at most 5 in a row), a range
#: every link of the grid keeps (so its cost is measured, not a changed graph)
NETWORK = {
    "latency": 0.05,
    "loss": 0.1,
    "max_consecutive_losses": 5,
    "range": 100.0,
    "range_hysteresis": 0.5,
}


def sparse_ring(n: int, seed: int = 5) -> list[list[int]]:
    """A ring in both directions plus, into a random quarter of the robots, one chord from
    a robot 3 to 39 places ahead: in-degree 2 or 3 (robots numbered from 1)."""
    import numpy as np

    rng = np.random.default_rng(seed)
    edges = {(i, (i + 1) % n) for i in range(n)} | {((i + 1) % n, i) for i in range(n)}
    for i in rng.choice(n, n // 4, replace=False) if n > 4 else ():
        edges.add(((int(i) + int(rng.integers(3, min(40, n - 1)))) % n, int(i)))
    return [[a + 1, b + 1] for a, b in sorted(edges)]


def _seconds(x: float) -> str:
    return "-" if x != x else f"{x:.2f}s"  # NaN: not measured


def scene(n: int, duration: float, log_rate: float = 10.0, network: str = ""):
    """The benchmark's scenario for ``n`` robots (see the module docstring)."""
    from dftc_mujoco import scenario

    d = {
        "name": f"scale{n}",
        "duration": duration,
        "seed": 1,
        "physics": {"timestep": 0.002, "control_period": 0.01, "log_rate": log_rate},
        "team": {
            "robots": n,
            "initial_positions": {"layout": "formation", "jitter": 0.05},
            "graph": {"family": "ring_chords", "chords": [c for c in (2, 5) if c < n]},
        },
        "gains": {"kc": 4.0, "ko": 3.0, "K": 3.0, "G": 0.01, "theta": 3.0},
        "noise": {"eta_bar": 0.001},
        "mission": {
            "transient": 2.0,
            "centroid": {"waypoints": [[0, 0], [20, 0]], "speed": 0.1},
            "formation": {"shape": "grid", "side": 0.5},
        },
        "faults": [{"robot": 1, "kind": "stop", "t": duration / 2}],
    }
    if network == "sparse":  # the graph no benchmark chose, with l1 and Δt_d,max "auto"
        d["team"]["graph"] = sparse_ring(n)
        d["onboard"] = {"thresholds": "l1"}
        d["fdir"] = {"dt_d_max": "auto"}
    elif network:  # both variants with l1 at k_o = 2; "lossy" adds the network
        d["gains"]["ko"] = 2.0
        d["onboard"] = {"thresholds": "l1"}
        if network == "lossy":
            d["network"] = NETWORK
    return scenario.from_dict(d, source=f"bench N={n}")


def run_peak(n: int, duration: float, log_rate: float, variant: str = "") -> dict:
    """One run as ``python -m dftc_mujoco.run`` makes it (set-up, the whole run, the records
    and their derived fields), alone in this fresh process: its peak resident memory and
    wall time (imports excluded)."""
    from dftc_mujoco.closed_loop.loop import Simulation

    s = scene(n, duration, log_rate, variant)
    t0 = time.perf_counter()
    with Simulation(s) as sim:
        sim.run(progress=False)
    return {
        "run_s": time.perf_counter() - t0,
        "run_peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def one(
    n: int, duration: float, log_rate: float = 10.0, repeat: int = 3, network: str = ""
) -> dict:
    from replay import measure

    from dftc_mujoco.core.graph import ring_with_chords
    from dftc_mujoco.onboard.thresholds import decay

    s = scene(n, duration, log_rate, network)
    t0 = time.perf_counter()
    if network != "sparse":  # (l1 needs no κ/λ)
        decay.decay_bounds(ring_with_chords(n, tuple(c for c in (2, 5) if c < n)), s.gains.ko)
    kappa = time.perf_counter() - t0 if network != "sparse" else float("nan")
    # forget it: the cold set-up below is a fresh process's, which computes κ/λ itself
    decay._cached_decay_bounds.cache_clear()
    r = measure(s, repeat)
    loop_s = r["loop_us"] * (r["periods"] + 1) * 1e-6
    return {
        "n": n,
        "network": network,
        "kappa_lambda_s": kappa,
        "bare_us": r["bare_us"],
        "loop_us": r["loop_us"],
        "ratio": r["ratio"],
        "rtf": duration / loop_s,
        "rtf_with_setup": duration / (loop_s + r["cold_setup_s"] + r["derive_s"]),
        "cold_setup_s": r["cold_setup_s"],
        "exact": r["exact"],
        "setup_s": r["setup_s"],
        "derive_s": r["derive_s"],
        "path": r["path"],
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "detected": [x["by"] for x in r["summary"]["detections"]],
    }


sys.path.insert(0, str(Path(__file__).resolve().parent))  # replay.py beside this file


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, nargs="+", default=[4, 16, 64, 100])
    p.add_argument("--duration", type=float, default=20.0)
    p.add_argument("--log-rate", type=float, default=10.0, help="log.npz rate [Hz]")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--network", action="store_true", help="the network's cost (see above)")
    p.add_argument("--sparse", action="store_true", help="a ring with sparse chords (see above)")
    p.add_argument("--one", type=int, help=argparse.SUPPRESS)
    p.add_argument("--variant", default="", help=argparse.SUPPRESS)
    p.add_argument("--peak", action="store_true", help=argparse.SUPPRESS)
    p.add_argument(
        "--peak-duration",
        type=float,
        help="simulated seconds of the run whose peak memory is measured (default --duration)",
    )
    args = p.parse_args()
    if args.one and args.peak:
        print(json.dumps(run_peak(args.one, args.duration, args.log_rate, args.variant)))
        return
    if args.one:
        r = one(args.one, args.duration, args.log_rate, args.repeat, args.variant)
        print(json.dumps(r))
        return
    print(
        f"{os.cpu_count()} cores; {args.duration:g} s of simulated time per N, "
        f"log at {args.log_rate:g} Hz"
    )
    print(
        f"{'N':>4} {'κ/λ':>8} {'setup':>8} {'cold':>8} {'bare':>10} {'loop':>10} "
        f"{'ratio':>6} {'RTF':>7} {'RTF+setup':>10} {'peak':>8} {'process':>8} exact "
        f"{'run peak':>9}"
    )
    variants = ["ideal", "lossy"] if args.network else ["sparse"] if args.sparse else [""]
    runs = [(n, v) for n in args.n for v in variants]
    loops: dict[tuple[int, str], float] = {}
    for n, variant in runs:
        t0 = time.perf_counter()
        out = subprocess.run(
            [
                sys.executable,
                __file__,
                "--one",
                str(n),
                "--duration",
                str(args.duration),
                "--log-rate",
                str(args.log_rate),
                "--repeat",
                str(args.repeat),
                "--variant",
                variant,
            ],
            capture_output=True,
            text=True,
            check=True,
        )
        whole = time.perf_counter() - t0  # the whole child process, imports included
        r = json.loads(out.stdout.strip().splitlines()[-1])
        loops[(n, variant)] = r["loop_us"]
        cost = ""
        if variant != "lossy":  # one run alone in a fresh process: its own peak memory
            peak_s = args.peak_duration or args.duration
            alone = subprocess.run(
                [
                    sys.executable,
                    __file__,
                    "--one",
                    str(n),
                    "--peak",
                    "--duration",
                    str(peak_s),
                    "--log-rate",
                    str(args.log_rate),
                    "--variant",
                    variant,
                ],
                capture_output=True,
                text=True,
                check=True,
            )
            a = json.loads(alone.stdout.strip().splitlines()[-1])
            cost = f" {a['run_peak_mb']:>6.0f}MB ({peak_s:g} s run: {a['run_s']:.1f} s)"
        if variant == "lossy":
            cost = f"  network: loop x{r['loop_us'] / loops[(n, 'ideal')]:.3f} of the ideal one"
        print(
            f"{variant:<6}" * bool(variant) + f"{r['n']:>4} {_seconds(r['kappa_lambda_s']):>8} "
            f"{r['setup_s']:>7.2f}s {r['cold_setup_s']:>7.2f}s "
            f"{r['bare_us']:>8.1f}us {r['loop_us']:>8.1f}us "
            f"{r['ratio']:>6.2f} {r['rtf']:>6.1f}x {r['rtf_with_setup']:>9.1f}x "
            f"{r['peak_mb']:>6.0f}MB {whole:>7.1f}s {'yes' if r['exact'] else 'NO'}{cost}"
        )


if __name__ == "__main__":
    main()
