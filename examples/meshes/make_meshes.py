"""Generate the example meshes of this folder from trimesh primitives (run once; deterministic).

- ``mug.stl``: a mug 80 mm wide and 100 mm tall with a side handle (binary STL, metres): an open
  cylinder shell with a bottom, and a torus-segment handle, united into one closed surface.
- ``bottle.obj``: a 66 mm wide, 160 mm tall bottle with shoulders and a neck (Wavefront OBJ,
  metres): a revolved profile.

Both are closed (watertight) and small (< 200 KB). Run ``python examples/meshes/make_meshes.py``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import trimesh

HERE = Path(__file__).resolve().parent
MM = 1e-3


def mug() -> trimesh.Trimesh:
    """An 80 mm mug, wall 5 mm, bottom 8 mm, handle on the +y side (boolean union: manifold3d)."""
    outer = trimesh.creation.cylinder(radius=40 * MM, height=100 * MM, sections=64)
    inner = trimesh.creation.cylinder(radius=35 * MM, height=100 * MM, sections=64)
    inner.apply_translation([0.0, 0.0, 8 * MM])
    body = outer.difference(inner)
    handle = trimesh.creation.torus(28 * MM, 6 * MM, major_sections=48, minor_sections=16)
    handle.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0.0, 1.0, 0.0]))
    handle.apply_translation([0.0, 40 * MM, 0.0])
    handle = handle.difference(trimesh.creation.cylinder(radius=38 * MM, height=120 * MM))
    out = body.union(handle)
    out.apply_translation([0.0, 0.0, 50 * MM])  # standing on z = 0
    return out


def bottle() -> trimesh.Trimesh:
    """A bottle revolved about z: body radius 33 mm up to 110 mm, shoulders, a 13 mm neck."""
    profile_mm = [(0, 0), (31, 0), (33, 2), (33, 110), (22, 130), (13, 140), (13, 158),
                  (11, 160), (0, 160)]  # fmt: skip
    return trimesh.creation.revolve(np.array(profile_mm) * MM, sections=48)


def main() -> int:
    for name, mesh in (("mug.stl", mug()), ("bottle.obj", bottle())):
        assert mesh.is_watertight and mesh.volume > 0, name
        path = HERE / name
        mesh.export(path)
        print(f"{path.name}: {len(mesh.faces)} faces, {path.stat().st_size / 1024:.0f} KB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
