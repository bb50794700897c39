"""Generate hexbot.stl: the mesh robot's body, a hexagonal prism with a raised turret.

    python models/robots/meshes/make_hexbot.py

trimesh builds the solid (a union of two convex prisms, watertight); the robot
file uses it for both collision and looks, and the registry computes its mass,
inertia and footprint from it (density declared in hexbot.xml).
"""

from pathlib import Path

import trimesh

body = trimesh.creation.cylinder(radius=0.11, height=0.05, sections=6)
body.apply_translation([0, 0, 0.025])
turret = trimesh.creation.cylinder(radius=0.05, height=0.03, sections=6)
turret.apply_translation([0, 0, 0.065])
solid = trimesh.util.concatenate([body, turret])
solid = trimesh.convex.convex_hull(solid) if not solid.is_watertight else solid
out = Path(__file__).with_name("hexbot.stl")
solid.export(out)
print(out, "watertight:", solid.is_watertight, "volume:", solid.volume)
