"""dftc-mujoco: distributed fault-tolerant control of robot teams on MuJoCo physics.

Implements Arrichiello, Marino & Pierri (2017), *Distributed Fault-Tolerant
Control for Networked Robots in the Presence of Recoverable/Unrecoverable
Faults and Reactive Behaviors*, Frontiers in Robotics and AI.
"""

__version__ = "0.1.0"
