"""Bumpers: each robot's own touch sensor, read from MuJoCo's contacts.

A robot knows when its hull touches something (a bumper, a contact switch, a motor-current
spike): this is that sensor, on the simulator side. Each period :meth:`Bumpers.read` says
which robots touch a teammate, an excluded robot or a cylinder (the floor does not count).
The onboard recovery uses it to postpone an exclusion that a contact may explain
(``onboard/recovery.py``); the premises monitor labels the same contacts with their depth.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

FLOOR = -1  # geom owner: the floor, the world, anything that is neither a robot nor a cylinder
CYLINDER = -2  # geom owner: a cylinder obstacle


def geom_owners(scene: Any) -> np.ndarray:
    """(ngeom,) the robot (0-based) each geom belongs to, CYLINDER or FLOOR."""
    model = scene.model
    root = model.body_rootid
    robot_of_root = np.full(model.nbody, FLOOR, dtype=np.int64)  # one pass, not one per robot
    robot_of_root[root[np.asarray(scene.body, dtype=np.int64)]] = np.arange(len(scene.body))
    owner = robot_of_root[root[model.geom_bodyid]]
    owner[np.asarray(scene.obstacle_geom, dtype=np.int64)] = CYLINDER
    return owner


@njit(cache=True)
def touching(owner, contact_geom, ncon, out):  # pragma: no cover - compiled
    """``out`` (N,) set to whether each robot touches another robot or a cylinder."""
    out[:] = False
    for c in range(ncon):
        a, b = owner[contact_geom[c, 0]], owner[contact_geom[c, 1]]
        if a == FLOOR or b == FLOOR or a == b or (a < 0 and b < 0):
            continue
        if a >= 0:
            out[a] = True
        if b >= 0:
            out[b] = True


class Bumpers:
    """Every robot's touch sensor (N,), read after each physics step."""

    def __init__(self, scene: Any, data: Any) -> None:
        self.owner = geom_owners(scene)
        self.data = data
        self.value = np.zeros(len(scene.body), bool)
        self._clear = True  # ``value`` is all False (the last read had no contact)

    def read(self) -> np.ndarray:
        """Which robots touch something now (a view, rewritten by the next read)."""
        ncon = self.data.ncon
        if ncon:
            touching(self.owner, self.data.contact.geom, ncon, self.value)
            self._clear = False
        elif not self._clear:  # no contact at all: nobody touches (no compiled call)
            self.value[:] = False
            self._clear = True
        return self.value
