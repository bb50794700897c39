"""Queries on a compiled robot or scene model's kinematic tree: which bodies, joints and
actuators belong to a robot (one pass for a whole team), qpos addresses, which geoms
collide, a robot's footprint and a wheel's radius from its collision surface."""

from __future__ import annotations

import mujoco
import numpy as np


def subtree(model: mujoco.MjModel, root: int) -> np.ndarray:
    """(nbody,) bool: the bodies of the subtree of body ``root`` (numbered depth first)."""
    inside = np.zeros(model.nbody, bool)
    inside[root] = True
    for b in range(root + 1, model.nbody):
        inside[b] = inside[model.body_parentid[b]]
    return inside


def owners(model: mujoco.MjModel, roots: np.ndarray) -> np.ndarray:
    """(nbody,) the index into ``roots`` of the root whose subtree holds each body, -1 for
    none (bodies are numbered depth first: a parent comes before its children)."""
    owner = np.full(model.nbody, -1, dtype=np.int64)
    owner[np.asarray(roots, dtype=np.int64)] = np.arange(len(roots))
    parent = model.body_parentid
    for b in range(1, model.nbody):  # one pass over the bodies, not one per root
        if owner[b] < 0:
            owner[b] = owner[parent[b]]
    return owner


def actuator_bodies(model: mujoco.MjModel) -> np.ndarray:
    """(nu,) the body each actuator acts on (its joint's, site's or body's; a fixed tendon's
    first joint's), -1 for a tendon of sites or geoms."""
    trn = model.actuator_trntype
    target = model.actuator_trnid[:, 0]
    out = np.full(model.nu, -1, dtype=np.int64)
    joint = (trn == mujoco.mjtTrn.mjTRN_JOINT) | (trn == mujoco.mjtTrn.mjTRN_JOINTINPARENT)
    out[joint] = model.jnt_bodyid[target[joint]]
    site = trn == mujoco.mjtTrn.mjTRN_SITE
    out[site] = model.site_bodyid[target[site]]
    body = trn == mujoco.mjtTrn.mjTRN_BODY
    out[body] = target[body]
    for a in np.flatnonzero(trn == mujoco.mjtTrn.mjTRN_TENDON):
        wrap = int(model.tendon_adr[target[a]])
        if model.tendon_num[target[a]] and model.wrap_type[wrap] == mujoco.mjtWrap.mjWRAP_JOINT:
            out[a] = model.jnt_bodyid[model.wrap_objid[wrap]]
    return out


def attached_actuators(model: mujoco.MjModel, body: int) -> np.ndarray:
    """The actuators that come along when body ``body`` is attached (its subtree's joints,
    sites and bodies, or the joints of their fixed tendons, are their targets), in model
    order."""
    on = actuator_bodies(model)
    inside = subtree(model, body)
    return np.flatnonzero((on >= 0) & inside[np.maximum(on, 0)])


def qpos_widths(model: mujoco.MjModel, joints: np.ndarray) -> np.ndarray:
    """How many qpos coordinates each of ``joints`` has (7 for a free joint, 4 for a ball)."""
    kind = model.jnt_type[np.asarray(joints, dtype=np.int64)]
    return np.where(
        kind == mujoco.mjtJoint.mjJNT_FREE, 7, np.where(kind == mujoco.mjtJoint.mjJNT_BALL, 4, 1)
    )


def qpos_addresses(model: mujoco.MjModel, joints: np.ndarray) -> np.ndarray:
    """The qpos addresses of ``joints``, in order (7 for a free joint, 4 for a ball)."""
    joints = np.asarray(joints, dtype=np.int64)
    return ranges(model.jnt_qposadr[joints], qpos_widths(model, joints))


def ranges(start: np.ndarray, length: np.ndarray) -> np.ndarray:
    """start[0] … start[0] + length[0] − 1, then start[1] …: the ranges end to end (int64)."""
    ends = np.cumsum(length, dtype=np.int64)
    first = np.asarray(start, dtype=np.int64) - ends + length
    return np.repeat(first, length) + np.arange(ends[-1] if len(ends) else 0, dtype=np.int64)


def _wheel_radius(model, data, wheel: int, anchor: np.ndarray, axis: np.ndarray) -> float:
    """Largest distance from the axle line of the colliding geoms of body ``wheel``."""
    r = 0.0
    for g in range(model.ngeom):
        if model.geom_bodyid[g] != wheel or not (
            model.geom_contype[g] or model.geom_conaffinity[g]
        ):
            continue
        pts = _surface_points(model, data, g)
        rel = pts - anchor
        r = max(r, float(np.linalg.norm(rel - np.outer(rel @ axis, axis), axis=1).max()))
    return r


def _surface_points(model: mujoco.MjModel, data: mujoco.MjData, g: int) -> np.ndarray:
    """World points whose horizontal hull contains geom ``g`` (corners, rims, vertices)."""
    t = int(model.geom_type[g])
    size = model.geom_size[g]
    rot = data.geom_xmat[g].reshape(3, 3)
    pos = data.geom_xpos[g]
    ring = np.linspace(0.0, 2 * np.pi, 33)[:-1]
    circle = np.stack([np.cos(ring), np.sin(ring), np.zeros_like(ring)], axis=1)
    if t == int(mujoco.mjtGeom.mjGEOM_MESH):
        mid = model.geom_dataid[g]
        start, count = model.mesh_vertadr[mid], model.mesh_vertnum[mid]
        local = model.mesh_vert[start : start + count]
    elif t == int(mujoco.mjtGeom.mjGEOM_BOX):
        local = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        local = local * size
    elif t == int(mujoco.mjtGeom.mjGEOM_CYLINDER):
        local = np.vstack([circle * size[0] + [0, 0, h] for h in (-size[1], size[1])])
    elif t == int(mujoco.mjtGeom.mjGEOM_CAPSULE):
        sphere = _sphere_points(size[0])
        local = np.vstack([sphere + np.array([0.0, 0.0, h]) for h in (-size[1], size[1])])
    elif t == int(mujoco.mjtGeom.mjGEOM_SPHERE):
        local = _sphere_points(size[0])
    elif t == int(mujoco.mjtGeom.mjGEOM_ELLIPSOID):
        local = _sphere_points(1.0) * size
    else:  # planes, height fields, SDFs: their bounding sphere
        local = _sphere_points(float(model.geom_rbound[g]))
    return local @ rot.T + pos


def _sphere_points(r: float) -> np.ndarray:
    ring = np.linspace(0.0, 2 * np.pi, 33)[:-1]
    pts = [
        np.stack(
            [np.cos(ring) * np.cos(e), np.sin(ring) * np.cos(e), np.full_like(ring, np.sin(e))],
            axis=1,
        )
        for e in np.linspace(-np.pi / 2, np.pi / 2, 9)
    ]
    return r * np.vstack(pts)


def colliding(model: mujoco.MjModel, g: int) -> bool:
    """Geom ``g`` takes part in collisions (its own model's contype or conaffinity)."""
    return bool(model.geom_contype[g] or model.geom_conaffinity[g])


def _footprint(model: mujoco.MjModel, data: mujoco.MjData, site: int, inside: np.ndarray) -> float:
    """Largest horizontal reach from the control point of the colliding geoms of the bodies
    ``inside`` (the base's subtree: what is attached to the scene)."""
    centre = data.site_xpos[site][:2]
    reach = 0.0
    for g in range(model.ngeom):
        if not inside[model.geom_bodyid[g]] or not colliding(model, g):
            continue
        pts = _surface_points(model, data, g)
        reach = max(reach, float(np.linalg.norm(pts[:, :2] - centre, axis=1).max()))
    return reach
