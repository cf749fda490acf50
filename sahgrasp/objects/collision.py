"""An object's collision geometry as a union of convex coal shapes, and signed distances to it.

Convex pieces (coal primitives or convex hulls) give a signed distance: positive outside, the
negative penetration depth inside, which a triangle mesh (``coal.BVHModel``) cannot give for a
point inside a closed surface. Each piece carries a bounding sphere, so that a query skips the
pieces that cannot be the closest.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import coal
import numpy as np
from numpy.typing import ArrayLike

from sahgrasp.objects.frames import FloatArray, transform_points

__all__ = ["CollisionShape", "convex_hull", "signed_distances"]


@dataclass(frozen=True, eq=False)
class CollisionShape:
    """One convex piece placed in the object's frame.

    Attributes:
        geometry: The coal shape (``coal.Box``, ``coal.Ellipsoid``, ``coal.ConvexBase``, ...).
        placement: Placement of the shape in the object frame (4x4).
        bounding_radius_m: Radius of a ball about the shape's origin holding the whole shape [m].
    """

    geometry: coal.ShapeBase
    placement: FloatArray
    bounding_radius_m: float

    def transform(self, T_world_object: FloatArray) -> coal.Transform3s:
        """Return the shape's coal transform in the world, given the object's placement."""
        T = T_world_object @ self.placement
        return coal.Transform3s(T[:3, :3], T[:3, 3])


def convex_hull(points_m: ArrayLike) -> CollisionShape:
    """Return the convex hull of ``points_m`` (N, 3) as a shape placed at its centroid."""
    points = np.asarray(points_m, dtype=np.float64)
    centre = points.mean(axis=0)
    vertices = coal.StdVec_Vec3s()
    for p in points - centre:
        vertices.append(p)
    T = np.eye(4)
    T[:3, 3] = centre
    radius = float(np.linalg.norm(points - centre, axis=1).max())
    return CollisionShape(coal.Convex.convexHull(vertices, False, ""), T, radius)


def signed_distances(
    shapes: Sequence[CollisionShape],
    T_world_object: FloatArray,
    points_m: ArrayLike,
    probe_radius_m: float = 0.0,
) -> FloatArray:
    """Return the signed distance [m] from a ball about each point (N, 3) to ``shapes``' union.

    Outside, the gap between the ball and the object (exact up to the pieces' chords). Inside, a
    negative value whose magnitude underestimates the depth: it is measured to the nearest face of
    the piece holding the point, which may be a face between two pieces. A ball of radius
    ``probe_radius_m`` wholly inside the object always gets at most ``-probe_radius_m``.
    """
    points = np.atleast_2d(np.asarray(points_m, dtype=np.float64))
    transforms = [s.transform(T_world_object) for s in shapes]
    centres = transform_points(T_world_object, np.array([s.placement[:3, 3] for s in shapes]))
    radii = np.array([s.bounding_radius_m for s in shapes])
    probe = coal.Sphere(probe_radius_m)
    request = coal.DistanceRequest()
    result = np.empty(len(points))
    for k, point in enumerate(points):
        lower_bounds = np.linalg.norm(centres - point, axis=1) - radii - probe_radius_m
        best = np.inf
        for i in np.argsort(lower_bounds):
            if lower_bounds[i] > best:
                break
            at_point = coal.Transform3s(np.eye(3), point)
            distance = coal.distance(
                shapes[i].geometry, transforms[i], probe, at_point, request, coal.DistanceResult()
            )
            best = min(best, distance)
        result[k] = best
    return result
