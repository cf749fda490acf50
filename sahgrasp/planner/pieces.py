"""The planner's collision pieces of a mesh object: one prism per triangle, no merging.

A mesh object's convex pieces (:class:`sahgrasp.objects.MeshSolid`) are its triangles' inward
prisms, joined into larger convex pieces where that keeps them inside the mesh. The joining is
most of the build (about 3 s for the shipped mug and 4.4 s for the bottle on the machine of
docs/planning.md, against 0.15 s and 0.13 s without it), while the IK with the object as an
obstacle is as fast on the single prisms (the pieces sit in a bounding-volume tree). The planner
therefore uses the prisms unjoined: the same union of prisms before the merge (so never outside
the mesh by more than the prisms' own error), and every planned grasp is verified against the
true mesh anyway (:mod:`sahgrasp.planner.verify`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from sahgrasp.collision.shapes import CollisionShape, convex_hull
from sahgrasp.objects.body import GraspObject
from sahgrasp.objects.mesh_file import MeshSolid

__all__ = ["PrismSolid", "planning_object"]


@dataclass(frozen=True, eq=False)
class PrismSolid(MeshSolid):
    """A :class:`MeshSolid` whose collision pieces are its triangles' prisms, unjoined."""

    @cached_property
    def _shapes(self) -> tuple[CollisionShape, ...]:
        if self.collision == "hull" or self.trimesh.is_convex:
            return (convex_hull(self.vertices_m),)
        corners = self.vertices_m[self.faces]
        depth = self.wall_thickness_m()[:, None, None] * self.trimesh.face_normals[:, None, :]
        return tuple(convex_hull(p) for p in np.concatenate([corners, corners - depth], axis=1))


def planning_object(obj: GraspObject) -> GraspObject:
    """``obj`` with each :class:`MeshSolid` replaced by its :class:`PrismSolid`."""
    solids = tuple(
        PrismSolid(s.name, s.vertices_m, s.faces, s.collision, s.repairs)
        if type(s) is MeshSolid
        else s
        for s in obj.solids
    )
    return dataclasses.replace(obj, solids=solids)
