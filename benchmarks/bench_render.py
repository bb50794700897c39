"""Video throughput: frames per second rendered *and* encoded (H.264) from a run's records.

    python benchmarks/bench_render.py [--size 640x480] [--seconds 20]

Simulates paper_case once (no video), then renders its first ``--seconds``
of video through the same path as the CLI (mujoco.Renderer on MUJOCO_GL,
overlays, imageio's bundled ffmpeg), and reports frames/s.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from dftc_mujoco import scenario
from dftc_mujoco.closed_loop.loop import simulate
from dftc_mujoco.render.options import VideoOptions
from dftc_mujoco.render.video import write_video


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", default="640x480")
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--fps", type=float, default=30.0)
    args = p.parse_args()
    w, h = (int(v) for v in args.size.split("x"))
    s = scenario.load("paper_case")
    r = simulate(s)
    keep = r.log["t"] <= args.seconds + 1e-9
    log = {k: (v[keep] if v.shape[:1] == r.log["t"].shape else v) for k, v in r.log.items()}
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        frames = write_video(
            Path(tmp) / "video.mp4",
            s,
            log,
            r.summary,
            VideoOptions(width=w, height=h, fps=args.fps),
        )
        wall = time.perf_counter() - t0
        size = (Path(tmp) / "video.mp4").stat().st_size
    print(f"MUJOCO_GL={os.environ.get('MUJOCO_GL')}, {os.cpu_count()} cores")
    print(
        f"{frames} frames at {w}x{h}: {wall:.2f} s, {frames / wall:.1f} frames/s "
        f"rendered and encoded, {size / 1e6:.2f} MB"
    )


if __name__ == "__main__":
    main()
