"""The paper's six onboard blocks (Arrichiello, Marino & Pierri 2017, Fig. 1).

These are the defaults of every scenario (``[onboard] <block> = "paper"``).
Subclass one and override its documented methods to try your own algorithm
beside the paper's::

    from dftc_mujoco.blocks import paper

    class Saturated(paper.Controller):
        def collective_input(self, x_hat, x_d, xd_dot):
            return np.clip(super().collective_input(x_hat, x_d, xd_dot), -0.3, 0.3)

A team made only of these classes (thresholds aside: any rule) runs its
control period as one compiled call; a subclass runs the same blocks through
their Python methods (``summary.json`` says which path ran).

=================  ==========================================  ===========
block              methods                                      equations
=================  ==========================================  ===========
Observer           estimate(), residual(x_m), update(...)       19-21, 35
Controller         collective_input(x_hat, x_d, xd_dot),        15-16
                   own_input(u_hat_g)
Supervisor         step(x, u_g, obstacles, safe, activation)    8, 17-18, 22
FaultEstimator     step(x_m, u) -> u_bar                        28-31
Thresholds         mu(t) -> (M, M), restart(graph, y0, t0)      40-41
Detector           judge(r_norm, mu, observer, x_m)             35, 39
                   -> (score, bound) (M, M)
Decision           update(r_norm, mu) -> raised (M, M)          39, Rem. 5.2
=================  ==========================================  ===========

Every block also has ``reset(config, x_m0, prior)`` (start of a run) and
``drop(p, graph, t)`` (the member at position ``p`` was excluded).
"""

from ..onboard.block import Block, TeamConfig
from ..onboard.controller import Controller
from ..onboard.decision import Decision
from ..onboard.detector import Detector
from ..onboard.fault_estimator import FaultEstimator
from ..onboard.observer import Observer
from ..onboard.supervisor import Supervisor
from ..onboard.thresholds import Thresholds

__all__ = [
    "Block",
    "Controller",
    "Decision",
    "Detector",
    "FaultEstimator",
    "Observer",
    "Supervisor",
    "TeamConfig",
    "Thresholds",
]
