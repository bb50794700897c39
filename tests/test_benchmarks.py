"""The benchmarks run as the README says, each in a process of its own."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _bench(script: str, *args: str) -> str:
    """``python benchmarks/SCRIPT ARGS`` in a process of its own, from the repository's root,
    as the README runs it; its standard output, once it exited 0."""
    done = subprocess.run(
        [sys.executable, f"benchmarks/{script}", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_the_peers_benchmark_times_each_peer_on_the_formation_task():
    """MuJoCo with a numpy controller and the DFTC loop do the task (every healthy robot
    within 2 cm of its slot after 5 s) faster than real time; a peer that is not installed
    is named, not a traceback."""
    peers = ["mujoco", "dftc", "pybullet"]
    out = _bench(
        "bench_peers.py", "--n", "4", "--duration", "5", "--repeat", "1", "--peers", *peers
    )
    rows = {
        m["peer"]: (float(m["us"]), float(m["rtf"]), float(m["err"]))
        for m in re.finditer(
            r"^\s+4\s+(?P<peer>\w+)\s+(?P<us>[\d.]+)\s+(?P<rtf>[\d.e+]+)x\s+(?P<err>[\d.]+)m$",
            out,
            flags=re.M,
        )
    }
    for peer in ("mujoco", "dftc"):
        us, rtf, err = rows[peer]
        assert err < 0.02, (peer, err)
        assert rtf > 1.0 and abs(rtf - 1e4 / us) < 0.01 * rtf, (peer, us, rtf)
    if importlib.util.find_spec("pybullet") is None:
        assert "pybullet: not installed" in out
        assert "pybullet" not in rows
    else:
        assert rows["pybullet"][2] < 0.02


def test_the_pass_benchmark_times_each_stage_and_the_shared_period():
    """``bench_pass.py`` at N = 160 (a team that shares its pass): every stage and both
    precisions timed, float32's next ŷ within 1e-5 m of float64's, and the shared part of
    the period ending within the period."""
    out = _bench("bench_pass.py", "--n", "160", "--repeat", "2", "--periods", "20")
    times = re.findall(r"^  (\S.*?)\s+([\d.]+) /\s+([\d.]+)$", out, flags=re.M)
    assert len(times) == 6, out
    assert all(0 < float(lo) <= float(med) for _, lo, med in times), times
    gap = re.search(r"at most ([\d.e+-]+) m from float64's", out)
    assert gap is not None and float(gap.group(1)) < 1e-5, out
    split = re.search(
        r"a period ([\d.]+) ms; .* beside the pass ([\d.]+) ms, the helpers end at ([\d.]+) ms, "
        r"the calling thread at ([\d.]+) ms",
        out,
    )
    assert split is not None, out
    period, beside, helpers, caller = (float(v) for v in split.groups())
    assert 0 < beside <= caller <= period and 0 < helpers <= period, split.groups()
