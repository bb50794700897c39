"""Step a run period by period and plot one residual against its threshold.

    python examples/step_and_plot.py [OUT.png]

Steps paper_case 0.1 s at a time from 40 s to 48 s (robot 1 stops at 41.8 s),
collects robot 3's residual on robot 1 and its threshold from each Snapshot,
prints the events as they happen and saves the plot.
"""

from __future__ import annotations

import sys

import matplotlib.pyplot as plt

from dftc_mujoco import Simulation, load_scenario


def main() -> None:
    out = sys.argv[1] if len(sys.argv) > 1 else "residual_3_on_1.png"
    s = load_scenario("paper_case", {"duration": 48.0})
    t, r, mu = [], [], []
    with Simulation(s) as sim:
        sim.step(4000)  # the first 40 s in one call
        while not sim.done:
            snap = sim.step(10)  # 0.1 s
            t.append(snap.t)
            r.append(snap.residual[2, 0])  # robot 3 (row 2) on robot 1 (column 0)
            mu.append(snap.threshold[2, 0])
            for e in snap.events:
                print(f"{e['t']:6.2f} s  {e['kind']}  robot {e.get('robot')}")
    fig, ax = plt.subplots(figsize=(6, 3))
    ax.plot(t, r, label="‖³r₁‖ (eq. 35)")
    ax.plot(t, mu, "--", label="³μ₁ (eq. 40)")
    ax.axvline(41.8, color="grey", lw=0.8)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("[m]")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    print(f"saved {out}")


if __name__ == "__main__":
    main()
