"""The speed targets, each measured on this machine and judged: met or not met.

    python benchmarks/targets.py                  # the default sizes (1.7-3.9 min on 2 cores)
    python benchmarks/targets.py --json out.json  # the figures as well, for a record
    python benchmarks/targets.py --strict         # exit 1 unless every target is met

Every measurement runs in a fresh process of its own (``bench_scale.py --one``, or this
file's ``--paper``), as ``bench_step.py`` and ``bench_scale.py`` make them:

- loop / exact floor ≤ 2.0 at every N: paper_case (N = 4, ``--repeat`` runs, at least 3)
  and the scale scene at ``--n`` (``--duration`` s each) and at ``--large-n``
  (``--large-duration`` s); the floor is bare ``mj_step`` replaying the run's own
  commands and fault changes (``replay.py``), and a row whose replay did not end in the
  closed loop's final state bit for bit is not judged;
- ``--large-n`` at ≥ 2× real time with set-up: simulated time over the loop's median time
  plus a fresh process's first set-up (κ/λ, numba's cache) and the post-run derivation;
- the set-up at ``--large-n`` ≤ 1.5 s: that fresh process's first set-up;
- peak resident memory of one ``--peak-duration`` s run at ``--large-n`` ≤ 1.5 GB, alone in
  a fresh process (as ``python -m dftc_mujoco.run`` makes it, figures aside).

The machine's floor is printed beside each ratio: the targets are ratios and times on
*this* machine, and the shared machines' speed moves by 10-50 % between invocations. What
the figures stand on is printed first (:func:`machine`): the cores, what one Python call
costs and how CPython was configured (outside the physics and its compiled stages, a small
team's period is Python calls), and how fast one core streams memory (what the pass over
a large team's N × N state waits on): the figures to compare before two invocations'
ratios are. paper_case's ratio read 1.84-1.86 on the machine of 2026-12-06 (a call 19-20
ns, one core 40 GB/s) and 2.1-4.0 on slower machines (docs/performance.md).
paper_case's records matching the stored reference records is a test
(``tests/test_api.py``), not a benchmark.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import sysconfig
import time
import timeit
from pathlib import Path

HERE = Path(__file__).resolve().parent
RATIO, RTF, SETUP_S, PEAK_MB = 2.0, 2.0, 1.5, 1.5 * 1024  # the targets


def _child(*args: str) -> dict:
    """The last line of a benchmark child process's output, as JSON."""
    done = subprocess.run([sys.executable, *args], capture_output=True, text=True, cwd=HERE.parent)
    if done.returncode != 0:
        sys.exit(f"targets.py: {' '.join(args)} failed:\n{done.stderr.strip()}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def cpu_name() -> str:
    """The CPU model from /proc/cpuinfo (Linux), else what platform knows."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def machine() -> dict:
    """What the figures stand on, measured here: cores, processor, the cost of one Python
    call with two arguments (ns, the minimum of 5 × 200,000), whether CPython was configured
    with ``--enable-optimizations`` (profile-guided) and ``--enable-shared``, and one core's
    memory stream (GB/s read + written, a 64 MB float64 copy, best of 5)."""
    import numpy as np

    def f(a: int, b: int) -> int:
        return a

    call = min(timeit.repeat("f(1, 2)", globals={"f": f}, number=200_000, repeat=5)) / 200_000
    a, b = np.ones(8 << 20), np.empty(8 << 20)
    best = np.inf
    for _ in range(5):
        t0 = time.perf_counter()
        np.copyto(b, a)
        best = min(best, time.perf_counter() - t0)
    config = str(sysconfig.get_config_var("CONFIG_ARGS") or "")
    return {
        "cores": os.cpu_count(),
        "cpu": cpu_name(),
        "python": platform.python_version(),
        "pgo": "--enable-optimizations" in config,
        "shared": bool(sysconfig.get_config_var("Py_ENABLE_SHARED")),
        "call_ns": call * 1e9,
        "stream_gb_s": 2 * a.nbytes / best / 1e9,
    }


def describe(m: dict) -> str:
    """:func:`machine`'s figures in one line."""
    build = "with" if m["pgo"] else "without"
    shared = ", with --enable-shared" if m["shared"] else ", without --enable-shared"
    return (
        f"machine: {m['cpu']}, {m['cores']} cores; Python {m['python']} configured {build} "
        f"--enable-optimizations{shared}, a call {m['call_ns']:.0f} ns; one core streams "
        f"{m['stream_gb_s']:.1f} GB/s"
    )


def _paper(repeat: int) -> dict:
    """paper_case's loop against its exact replay, in this (fresh) process."""
    sys.path.insert(0, str(HERE))
    from replay import measure

    from dftc_mujoco import load_scenario

    r = measure(load_scenario("paper_case"), repeat)
    r.pop("summary")
    return r


def judge(rows: list[dict], large: dict, peak: dict, large_n: int) -> list[tuple]:
    """(target, measured, met) for every target, from the measurements' figures."""
    out = []
    for r in rows:
        floor = f"loop {r['loop_us']:.1f} µs, floor {r['bare_us']:.1f} µs"
        if not r["exact"]:
            out.append((f"loop / floor ≤ {RATIO:g} at {r['label']}", f"{floor}: inexact", None))
            continue
        out.append((f"loop / floor ≤ {RATIO:g} at {r['label']}",
                    f"{r['ratio']:.3f} ({floor})", r["ratio"] <= RATIO))  # fmt: skip
    out.append((f"N = {large_n} at ≥ {RTF:g}× real time with set-up",
                f"{large['rtf_with_setup']:.2f}× (loop alone {large['rtf']:.2f}×)",
                large["rtf_with_setup"] >= RTF))  # fmt: skip
    out.append((f"set-up ≤ {SETUP_S:g} s at N = {large_n} (a fresh process's)",
                f"{large['cold_setup_s']:.2f} s (a later one {large['setup_s']:.2f} s)",
                large["cold_setup_s"] <= SETUP_S))  # fmt: skip
    out.append((f"peak memory of a {peak['duration']:g} s run at N = {large_n} ≤ 1.5 GB",
                f"{peak['run_peak_mb']:.0f} MB", peak["run_peak_mb"] <= PEAK_MB))  # fmt: skip
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, nargs="*", default=[4, 16, 64, 100, 400])
    p.add_argument("--duration", type=float, default=10.0, help="s simulated at each --n")
    p.add_argument("--large-n", type=int, default=1000)
    p.add_argument("--large-duration", type=float, default=30.0)
    p.add_argument("--peak-duration", type=float, default=60.0)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--no-paper", action="store_true", help="leave paper_case out")
    p.add_argument("--json", type=Path, help="write every figure here")
    p.add_argument("--strict", action="store_true", help="exit 1 unless every target is met")
    p.add_argument("--paper", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.paper:
        print(json.dumps(_paper(args.repeat)))
        return
    here = machine()  # before the children: nothing else runs on this process's cores
    print(describe(here), flush=True)
    scale = str(HERE / "bench_scale.py")
    rows = []
    if not args.no_paper:
        r = _child(__file__, "--paper", "--repeat", str(max(args.repeat, 3)))
        rows.append({**r, "label": "N = 4 (paper_case)"})
    for n in args.n:
        r = _child(scale, "--one", str(n), "--duration", str(args.duration),
                   "--repeat", str(args.repeat))  # fmt: skip
        rows.append({**r, "label": f"N = {n} (scale scene, {args.duration:g} s)"})
    large = _child(scale, "--one", str(args.large_n), "--duration", str(args.large_duration),
                   "--repeat", str(args.repeat))  # fmt: skip
    rows.append({**large, "label": f"N = {args.large_n} (scale scene, {args.large_duration:g} s)"})
    peak = _child(scale, "--one", str(args.large_n), "--peak", "--duration",
                  str(args.peak_duration))  # fmt: skip
    peak["duration"] = args.peak_duration
    verdicts = judge(rows, large, peak, args.large_n)
    width = max(len(t) for t, _, _ in verdicts)
    for target, measured, met in verdicts:
        word = "not judged" if met is None else "met" if met else "NOT MET"
        print(f"{target:<{width}}  {measured:<44} {word}")
    met_all = all(m for _, _, m in verdicts)
    print(f"{sum(bool(m) for _, _, m in verdicts)} of {len(verdicts)} targets met")
    if args.json is not None:
        record = {"machine": here, "rows": rows, "peak": peak, "met": met_all, "verdicts": verdicts}
        args.json.write_text(json.dumps(record, indent=1))
    sys.exit(1 if args.strict and not met_all else 0)


if __name__ == "__main__":
    main()
