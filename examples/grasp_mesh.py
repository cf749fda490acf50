"""A grasp on an object loaded from a mesh file: the SAH holding the shipped mug.

The mesh (``examples/meshes/mug.stl`` by default, any STL/OBJ/PLY with ``--mesh``) is read with
``sahgrasp.objects.load_mesh``. The object is taken as standing on z = 0 with its axis along z
through x = y = 0, as the shipped meshes are: the thumb touches it from -x, the index, middle and
ring fingers from +x, 30 mm apart, each at the surface point nearest to where it reaches in, with
the mesh's outward normal there. The IK solves the grasp with the object as an obstacle, then the
hand-object clearance (``sahgrasp.objects.HandObjectClearance``) checks that no link but the
fingertips at their contacts is inside the object. Run `python examples/grasp_mesh.py` to open the
viewer, or add `--html OUT` to write the scene.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import cast

import numpy as np

import sahgrasp
from sahgrasp.experiments.arguments import add_html_argument, positive_float
from sahgrasp.objects import HandObjectClearance, MeshFileError, MeshSolid, load_mesh
from sahgrasp.viz import Viewer, frame_grasp, present, show_grasp

MUG = Path(__file__).resolve().parent / "meshes" / "mug.stl"
HEIGHTS_M = {"thumb": 0.06, "index": 0.09, "middle": 0.06, "ring": 0.03}
"""Contact heights above the object's base; the thumb faces the middle finger."""
REACH_M = 0.5
"""Distance along x from which each finger reaches in towards the axis [m]."""


def side_grasp(solid: MeshSolid, name: str) -> sahgrasp.GraspTarget:
    """The thumb on the -x side, the fingers on the +x side, at :data:`HEIGHTS_M`."""
    sides = {"thumb": -1.0, "index": 1.0, "middle": 1.0, "ring": 1.0}
    fingers = list(HEIGHTS_M)
    reach = np.array([[sides[f] * REACH_M, 0.0, HEIGHTS_M[f]] for f in fingers])
    points, normals = solid.nearest_surface(reach)
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    contacts = [sahgrasp.ContactTarget(*c) for c in zip(fingers, points, normals, strict=True)]
    return sahgrasp.GraspTarget(name, contacts)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="A grasp on an object from a mesh file.")
    parser.add_argument("--mesh", type=Path, default=MUG, help="STL, OBJ or PLY (default: mug)")
    parser.add_argument("--scale", type=positive_float, default=1.0, help="file unit in metres")
    add_html_argument(parser)
    args = parser.parse_args(argv)
    hand = sahgrasp.load_hand("sah")
    try:
        obj = load_mesh(args.mesh, scale=args.scale)
    except MeshFileError as error:  # a file the user named: one line, not a traceback
        parser.error(str(error))
    solid = cast(MeshSolid, obj.solids[0])  # load_mesh makes an object of one MeshSolid
    print(f"{obj.name}: {len(solid.faces)} triangles, {len(obj.collision_shapes())} convex "
          f"pieces; repairs: {', '.join(solid.repairs) or 'none'}")  # fmt: skip
    target = side_grasp(solid, obj.name)
    result = sahgrasp.solve_ik(hand, target, obstacle=obj, record_history=True)
    print(f"IK: {'solved' if result.success else 'not solved'} ({result.reason}), "
          f"{result.inits_used} initial configurations, {result.iterations} iterations, "
          f"max contact error {result.max_error_m * 1e3:.3f} mm")  # fmt: skip
    clearance = HandObjectClearance(hand, obj).clearance(result.q, contacts=hand.fingers)
    print(f"clearance: {clearance.distance_m * 1e3:.2f} mm at {clearance.link} "
          f"({'clear of the object' if clearance.clear() else 'INSIDE the object'}; "
          "fingertips at their contacts excepted)")  # fmt: skip

    def build(viewer: Viewer) -> None:
        show_grasp(viewer, "grasp", hand, result.q, obj, target, result.history)
        frame_grasp(viewer, hand, result.q, target, obj)

    present(build, args.html, f"sahgrasp {obj.name}")
    return 0 if result.success and clearance.clear() else 1


if __name__ == "__main__":
    sys.exit(main())
