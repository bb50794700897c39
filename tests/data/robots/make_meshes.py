"""Make the meshes of the test robots (run once; the STL files are committed).

holobase/assets/shell.stl: an octagonal shell (0.22 m across the flats) and
holobase/assets/plate.stl: a thin top plate; mobilearm/meshes/chassis.stl: a rounded box.
"""

from pathlib import Path

import trimesh

here = Path(__file__).parent


def prism(radius: float, height: float, sides: int, z0: float) -> trimesh.Trimesh:
    m = trimesh.creation.cylinder(radius=radius, height=height, sections=sides)
    m.apply_translation([0, 0, z0 + height / 2])
    return m


prism(0.24, 0.12, 8, 0.03).export(here / "holobase" / "assets" / "shell.stl")
prism(0.18, 0.01, 8, 0.15).export(here / "holobase" / "assets" / "plate.stl")
box = trimesh.creation.box(extents=[0.34, 0.26, 0.1])
box.apply_translation([0, 0, 0.0])
box.export(here / "mobilearm" / "meshes" / "chassis.stl")
print("ok", [p.stat().st_size for p in here.rglob("*.stl")])
