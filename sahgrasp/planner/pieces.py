"""The planner's collision pieces of a mesh object: one prism per triangle, no merging.

A mesh object's convex pieces (:class:`sahgrasp.objects.MeshSolid`) are its triangles' inward
prisms, joined into larger convex pieces where that keeps them inside the mesh. The joining is
most of the build (seconds for the shipped meshes, against a tenth of a second without it),
while the IK with the object as an obstacle is as fast on the single prisms (the pieces sit in a
bounding-volume tree). The planner therefore uses the prisms unjoined: the same union of prisms
before the merge (so never outside the mesh by more than the prisms' own error), and every
planned grasp is verified against the true mesh anyway (:mod:`sahgrasp.planner.verify`). A
prism's faces are known, so it is built as a convex polytope directly, without a hull.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from functools import cached_property

import coal
import numpy as np
from numpy.typing import NDArray

from sahgrasp.collision.shapes import CollisionShape, convex_hull
from sahgrasp.objects.body import GraspObject
from sahgrasp.objects.mesh_file import MeshSolid

__all__ = ["PrismSolid", "planning_object", "prism"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class PrismSolid(MeshSolid):
    """A :class:`MeshSolid` whose collision pieces are its triangles' prisms, unjoined."""

    def _merge(self, budget: int) -> tuple[tuple[CollisionShape, ...], int]:
        """The prisms, unjoined whatever the budget (no triangle tests)."""
        return self._prisms, 0

    @cached_property
    def _prisms(self) -> tuple[CollisionShape, ...]:
        if self.collision == "hull" or self.trimesh.is_convex:
            return (convex_hull(self.vertices_m),)
        corners = self.vertices_m[self.faces]
        depth = self.wall_thickness_m()[:, None, None] * self.trimesh.face_normals[:, None, :]
        prisms = np.concatenate([corners, corners - depth], axis=1)
        area = np.linalg.norm(
            np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1
        )
        scale = float(np.ptp(self.vertices_m, axis=0).max())
        # A prism's faces are known: no hull to compute (Qhull's set-up per piece is most of the
        # build), except for a sliver triangle, whose prism is left to the hull.
        return tuple(
            prism(p) if a > _SLIVER * scale**2 else convex_hull(p)
            for p, a in zip(prisms, area.tolist(), strict=True)
        )


_SLIVER = 1e-10
"""Triangles of a doubled area below this times the mesh's size squared are slivers."""
_PRISM_TRIANGLES = (
    (0, 1, 2),
    (3, 5, 4),
    (0, 3, 4),
    (0, 4, 1),
    (1, 4, 5),
    (1, 5, 2),
    (2, 5, 3),
    (2, 3, 0),
)
"""The faces of a triangular prism (corners 0-2 of the triangle, 3-5 those under them)."""


@functools.cache
def _triangles() -> coal.StdVec_Triangle:
    """:data:`_PRISM_TRIANGLES` as coal holds them (copied by each ``coal.Convex``)."""
    triangles = coal.StdVec_Triangle()
    for a, b, c in _PRISM_TRIANGLES:
        triangles.append(coal.Triangle(a, b, c))
    return triangles


def prism(points_m: FloatArray) -> CollisionShape:
    """The convex prism of a triangle (rows 0-2) and its offset copy (rows 3-5) [m].

    Placed as :func:`convex_hull` places a hull: at the points' centroid.
    """
    centre = points_m.mean(axis=0)
    vertices = coal.StdVec_Vec3s()
    vertices.extend(points_m - centre)
    triangles = _triangles()
    T = np.eye(4)
    T[:3, 3] = centre
    radius = float(np.linalg.norm(points_m - centre, axis=1).max())
    return CollisionShape(coal.Convex(vertices, triangles), T, radius)


def planning_object(obj: GraspObject) -> GraspObject:
    """``obj`` with each :class:`MeshSolid` replaced by its :class:`PrismSolid`."""
    solids = tuple(
        PrismSolid(s.name, s.vertices_m, s.faces, s.collision, s.repairs)
        if type(s) is MeshSolid
        else s
        for s in obj.solids
    )
    return dataclasses.replace(obj, solids=solids)
