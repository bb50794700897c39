"""Detection delay and smallest detectable fault against N, per rule: docs/scale.png, the
scale figure of docs/guide/campaigns.md.

    python campaigns/scale_figure.py [--out docs/scale.png]

Left: the first-flag delay of the stop faults of the campaigns ``scale_sweep`` and
``scale_sweep_block_row`` (run them first; their rows are read from
``./renders/campaigns/``), median and maximum per rule and N over the graph families.
Right: the smallest constant fault the steady thresholds let a teammate detect, k_o·μ_ik
(docs/notes.md, 8: the residual of a constant fault φ settles at φ/k_o), for the most sensitive
teammate and for every teammate, on the campaign's ring + chord 2 graphs with its gains
and the disk's noise bounds and drift offset.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

RULES = {"paper": "tab:gray", "block_row": "tab:blue", "l1": "tab:green"}
NS = (4, 16, 64, 100, 200)


def delays(folder: Path) -> dict[tuple[str, int], list[float]]:
    """First-flag delays of the detected stops, by (rule, N)."""
    out: dict[tuple[str, int], list[float]] = {}
    for name in ("scale_sweep", "scale_sweep_block_row"):
        path = folder / name / "results.jsonl"
        if not path.is_file():
            raise SystemExit(f"{path}: run python -m dftc_mujoco.campaign campaigns/{name}.toml")
        for line in path.read_text().splitlines():
            r = json.loads(line)
            if r.get("status") == "ok" and r.get("delay_first") is not None:
                out.setdefault((r["thresholds"], r["robots"]), []).append(r["delay_first"])
    return out


def detectable(rule: str, n: int) -> tuple[float, float]:
    """(most sensitive teammate, every teammate) smallest detectable constant fault [m/s]."""
    from dftc_mujoco.blocks import create
    from dftc_mujoco.closed_loop.loop import team_config
    from dftc_mujoco.scenario import load_scenario
    from dftc_mujoco.sim import robots

    s = load_scenario(
        "paper_case",
        {
            "team.robots": n,
            "team.graph": {"family": "ring_chords", "chords": [c for c in (2,) if c < n]},
            "team.initial_positions": {"layout": "formation"},
            "mission.formation": {"shape": "grid", "side": 0.6},
            "obstacles": [],
            "faults": [],
        },
    )
    config = team_config(s, robots.get("disk"))  # η̄, ξ̄ and the disk's drift offset ē
    th = create("thresholds", rule, {})
    x0 = np.asarray(s.team.initial_positions)
    th.reset(config, x0, x0)
    mu = np.array(th.mu(1e9), dtype=float)
    off = mu[~np.eye(n, dtype=bool)]  # teammates i != k
    return s.gains.ko * float(off.min()), s.gains.ko * float(off.max())


def main() -> None:
    from dftc_mujoco.render.figures import new_figure

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=Path, default=Path("renders/campaigns"))
    p.add_argument("--out", type=Path, default=Path("docs/scale.png"))
    args = p.parse_args()
    d = delays(args.runs)
    fig, (left, right) = new_figure(figsize=(10, 3.8), ncols=2)
    for rule, colour in RULES.items():
        ns = [n for n in NS if (rule, n) in d]
        if ns:
            med = [np.median(d[(rule, n)]) for n in ns]
            worst = [np.max(d[(rule, n)]) for n in ns]
            left.plot(ns, med, "o-", color=colour, label=f"{rule}: median")
            left.plot(ns, worst, "v--", color=colour, alpha=0.6, label=f"{rule}: max")
        sizes = [n for n in NS if rule != "block_row" or n <= 64]
        pairs = [detectable(rule, n) for n in sizes]
        right.plot(sizes, [a for a, _ in pairs], "o-", color=colour, label=f"{rule}: some")
        right.plot(
            sizes,
            [b for _, b in pairs],
            "v--",
            color=colour,
            alpha=0.6,
            label=f"{rule}: every teammate",
        )
    left.set_ylabel("first flag after a stop [s]")
    left.set_title("Detection delay (scale_sweep)")
    right.set_ylabel("smallest detectable constant fault [m/s]")
    right.set_yscale("log")
    right.set_title("Detectability (k_o μ, ring + chord 2)")
    for ax in (left, right):
        ax.set_xscale("log")
        ax.set_xlabel("N")
        ax.legend(fontsize=7)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=90)
    print(f"written {args.out}")


if __name__ == "__main__":
    main()
