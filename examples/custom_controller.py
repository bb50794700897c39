"""Your own controller in place of eq. 15, checked for locality and run on paper_case.

    python examples/custom_controller.py

Uses ``mylab.control.Lyapunov`` (a saturated Lyapunov-gradient law, beside this
script), checks that it uses only what each robot may know, and compares the
task errors and the fault handling with the paper's controller.
"""

from __future__ import annotations

import sys
from pathlib import Path

from dftc_mujoco import Simulation, check_locality, load_scenario

sys.path.insert(0, str(Path(__file__).resolve().parent))  # mylab/ beside this script
from mylab.control import Lyapunov


def main() -> None:
    problems = check_locality({"controller": Lyapunov(gain=2.0)})
    print(f"locality check: {'ok' if not problems else problems}")
    s = load_scenario("paper_case")
    for label, blocks in (("paper eq. 15", None), ("Lyapunov", {"controller": Lyapunov(2.0)})):
        with Simulation(s, blocks=blocks) as sim:
            result = sim.run(progress=False)
        err = result.summary["errors"]
        excluded = [e["robot"] for e in result.summary["exclusions"]]
        print(
            f"{label:>13}: path {result.summary['onboard']['path']}, centroid rms "
            f"{err['centroid_rms']:.4f} m, formation rms {err['formation_rms']:.4f} m, "
            f"excluded {excluded}, final formation error {err['final_formation']:.4f} m"
        )


if __name__ == "__main__":
    main()
