"""A threshold rule of your own beside the paper's eq. 40, on paper_case.

    python examples/custom_thresholds.py [--factor 0.25]

Defines a rule in a few lines (here: eq. 40 with a floor and a scale), runs
paper_case with the paper's thresholds and with it, and prints when each
robot first flags the stopped robot 1, and the largest residual / threshold
ratio on healthy robots (above 1 would be a false alarm).
"""

from __future__ import annotations

import argparse

import numpy as np

from dftc_mujoco import Simulation, load_scenario
from dftc_mujoco.blocks import paper


class Tighter(paper.Thresholds):
    """factor × eq. 40, never below ``floor`` metres (a rule with no proof: a demo)."""

    def __init__(self, factor: float = 0.25, floor: float = 0.002) -> None:
        self.factor, self.floor = factor, floor

    def mu(self, t: float) -> np.ndarray:
        return np.maximum(self.factor * super().mu(t), self.floor)


def first_flags(summary: dict, robot: int = 1) -> dict[int, float]:
    """Robot -> time it first flagged ``robot``."""
    return {d["by"]: d["t"] for d in summary["detections"] if d["robot"] == robot}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--factor", type=float, default=0.25)
    args = p.parse_args()
    s = load_scenario("paper_case")
    stop = next(f.t for f in s.faults if f.kind == "stop")
    for label, blocks in (
        ("paper eq. 40", None),
        ("tighter", {"thresholds": Tighter(args.factor)}),
    ):
        with Simulation(s, blocks=blocks) as sim:
            result = sim.run(progress=False)
        flags = first_flags(result.summary)
        delays = ", ".join(f"robot {by}: {t - stop:.2f} s" for by, t in sorted(flags.items()))
        print(
            f"{label:>13}: path {result.summary['onboard']['path']}, "
            f"thresholds {result.summary['onboard']['blocks']['thresholds']}, "
            f"margin {result.summary['margin']:.3f}, flags on robot 1 after the stop: {delays}"
        )


if __name__ == "__main__":
    main()
