"""dftc-mujoco: distributed fault-tolerant control of robot teams on MuJoCo physics.

Implements Arrichiello, Marino & Pierri (2017), *Distributed Fault-Tolerant
Control for Networked Robots in the Presence of Recoverable/Unrecoverable
Faults and Reactive Behaviors*, Frontiers in Robotics and AI.
"""

import os as _os

# MuJoCo reads MUJOCO_GL when it is imported: default to EGL (Mesa renders on
# the CPU of a headless machine) unless the user chose a backend already.
_os.environ.setdefault("MUJOCO_GL", "egl")
if _os.environ["MUJOCO_GL"].lower() == "egl":
    _os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

__version__ = "0.1.0"
