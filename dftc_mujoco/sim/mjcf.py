"""The composed scene as MJCF text, for tools that load a model from XML (dm_control's
``Physics.from_xml_string``, ``mujoco.MjModel.from_xml_string``, MuJoCo's own viewer).

The text is MuJoCo's own writing of the scene's ``MjSpec`` (:attr:`.scene.Scene.spec`,
``MjSpec.to_xml``) with these changes:

* **Full precision where the scene computed a number.** MuJoCo's writer prints 6
  significant digits, so a number computed in Python (where each robot's frame puts it,
  a mesh robot's mass and inertia, the cylinders, the timestep) would come back rounded
  and a model loaded from the text would step apart from the simulator's by 1e-9 m within
  a few hundred steps. Every number of a named body, geom or site, each robot's frame and
  the options is written again with all its digits (when the written value is that number
  rounded: nothing else is touched), and an orientation given as a z axis or two axes as
  it was given; other numbers of the robots' own files are written as MuJoCo writes them.
* **One name per default class**: the classes that robots attached in groups repeat are
  numbered.
* **The start as a keyframe** (``dftc_start``): every robot at its initial pose and its
  actuators' initial commands, the state a run starts from (``physics.reset(0)`` in
  dm_control; ``mj_resetDataKeyframe`` in MuJoCo).

Mesh and texture files are named by absolute path (the robot models make them so), so
the text loads on the machine that wrote it, wherever it is read from.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Any

import mujoco
import numpy as np

from .scene import Scene

_ZAXIS = mujoco.mjtOrientation.mjORIENTATION_ZAXIS
_XYAXES = mujoco.mjtOrientation.mjORIENTATION_XYAXES

#: the keyframe that holds the scene's start (qpos and ctrl)
START_KEY = "dftc_start"

#: attribute in the XML -> the spec's field, by element
_FIELDS = {
    "body": {"pos": "pos", "quat": "quat"},
    "geom": {"pos": "pos", "quat": "quat", "size": "size", "fromto": "fromto"},
    "site": {"pos": "pos", "quat": "quat", "size": "size"},
    "frame": {"pos": "pos", "quat": "quat"},
    "inertial": {"pos": "ipos", "quat": "iquat", "mass": "mass", "diaginertia": "inertia"},
    "option": {"timestep": "timestep", "gravity": "gravity"},
}


def scene_xml(scene: Scene) -> str:
    """``scene`` as MJCF text that compiles to the same model (module docstring)."""
    if scene.spec is None:
        raise ValueError("this scene keeps no MjSpec (it was not made by sim.scene.compose)")
    spec = scene.spec
    root = ET.fromstring(spec.to_xml())
    parent = {child: node for node in root.iter() for child in node}
    named = {(n.tag, n.get("name")): n for n in root.iter() if n.get("name")}
    _exact(root.find("option"), spec.option, "option")
    for kind, items in (("body", spec.bodies), ("geom", spec.geoms), ("site", spec.sites)):
        for obj in items:
            if not obj.name:
                continue
            node = named.get((kind, obj.name))
            if node is None:
                continue
            _exact(node, obj, kind)
            if kind != "body":
                continue
            if obj.explicitinertial and np.isnan(obj.fullinertia[0]):  # diagonal: no full
                _exact(node.find("inertial"), obj, "inertial")
            frame = obj.frame
            holder = parent.get(node)
            if frame is not None and holder is not None and holder.tag == "frame":
                _exact(holder, frame, "frame")
    _unique_classes(root)
    _start_key(root, scene)
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"


def _exact(node: ET.Element | None, obj: Any, kind: str) -> None:
    """Write each numeric attribute of ``node`` again with all the digits of ``obj``'s
    field, where the written value is that field rounded (MuJoCo's 6 digits); an
    orientation given as a z axis or two axes (which MuJoCo writes as a rounded
    quaternion) as it was given."""
    if node is None:
        return
    alt = getattr(obj, "alt", None)
    if alt is not None and "quat" in node.attrib:
        given = {_ZAXIS: "zaxis", _XYAXES: "xyaxes"}.get(alt.type)
        if given is not None:
            del node.attrib["quat"]
            node.set(given, " ".join(repr(float(v)) for v in getattr(alt, given)))
    for attr, name in _FIELDS[kind].items():
        text = node.get(attr)
        if text is None:
            continue
        value = np.atleast_1d(np.asarray(getattr(obj, name), dtype=float)).ravel()
        try:
            written = np.array([float(v) for v in text.split()])
        except ValueError:
            continue
        if written.shape != value[: len(written)].shape or len(written) > len(value):
            continue
        exact = value[: len(written)]
        if np.allclose(written, exact, rtol=1e-5, atol=1e-12):
            node.set(attr, " ".join(repr(float(v)) for v in exact))


def _unique_classes(root: ET.Element) -> None:
    """Robots attached in groups (``scene.GROUP``) bring one default class each of the same
    name, which MJCF text may hold only once: the repeats are numbered (no element names
    them; the robots' own classes are prefixed, so unique)."""
    used = {n.get(a) for n in root.iter() for a in ("class", "childclass") if n.tag != "default"}
    seen: dict[str, int] = {}
    for node in root.iter("default"):
        name = node.get("class")
        if name is None or name in used:
            continue
        seen[name] = seen.get(name, 0) + 1
        if seen[name] > 1:
            node.set("class", f"{name}{seen[name]}")


def _start_key(root: ET.Element, scene: Scene) -> None:
    """The scene's start (every robot at its initial pose) as the keyframe START_KEY."""
    keys = root.find("keyframe")
    if keys is None:
        keys = ET.SubElement(root, "keyframe")
    key = ET.SubElement(keys, "key", name=START_KEY)
    key.set("qpos", " ".join(repr(float(v)) for v in scene.qpos_init))
    if len(scene.ctrl_init):
        key.set("ctrl", " ".join(repr(float(v)) for v in scene.ctrl_init))


def simulation_xml(sim: Any) -> str:
    """The compiled scene of this simulation as MJCF text (``scene.spec`` is its
    ``MjSpec``): ``dm_control.mujoco.Physics.from_xml_string(sim.scene_xml())`` loads it,
    and it steps as the simulator's own model does from the same state. The keyframe
    ``dftc_start`` holds the start of a run (``physics.reset(0)``); meshes and textures are
    named by absolute path. The scene's own numbers are written with all their digits;
    MuJoCo writes the robots' own with 6 significant digits."""
    return scene_xml(sim.scene)
