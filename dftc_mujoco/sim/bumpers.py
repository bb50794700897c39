"""Bumpers: each robot's own touch sensor, read from MuJoCo's contacts.

A robot knows when its hull touches something (a bumper, a contact switch, a motor-current
spike): this is that sensor, on the simulator side. Each period :func:`contacts` says
which robots touch a teammate, an excluded robot or a cylinder (the floor does not count),
and how deep (``closed_loop/physics_step.py`` senses it with the rest of the period's truth). The
onboard recovery uses the bumpers to postpone an exclusion that a contact may explain
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
def contacts(owner, contact_geom, contact_dist, ncon, depth, touching):  # pragma: no cover
    """Each robot's deepest contact with another robot or a cylinder into ``depth`` (N,)
    (0: none) and its bumper into ``touching`` (N,), from MuJoCo's ``ncon`` contacts (each
    geom's ``owner``: :func:`geom_owners`)."""
    depth[:] = 0.0
    touching[:] = False
    for c in range(ncon):
        a, b = owner[contact_geom[c, 0]], owner[contact_geom[c, 1]]
        if a == FLOOR or b == FLOOR or a == b or (a < 0 and b < 0):
            continue  # the floor, the world, a robot's own parts, cylinder against cylinder
        deep = max(-contact_dist[c], 1e-12)
        for r in (a, b):
            if r >= 0:
                depth[r] = max(depth[r], deep)
                touching[r] = True
