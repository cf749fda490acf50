"""An object's collision geometry as a union of convex coal shapes, and signed distances to it.

Convex pieces (coal primitives or convex hulls) give a signed distance: positive outside, the
negative penetration depth inside, which a triangle mesh (``coal.BVHModel``) cannot give for a
point inside a closed surface. Each piece carries a bounding sphere, so that a query skips the
pieces that cannot be the closest.

:class:`PieceTree` puts the pieces in coal's broad phase (a dynamic AABB tree, queried in C++),
with a coarse level of a few convex hulls that each hold the pieces of one grid cell: the
distance to those hulls bounds the distance to the pieces from below, cheaply, so that a link far
from the object costs one coarse query instead of GJK against every piece near its bounding box.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import coal
import numpy as np
from numpy.typing import ArrayLike

from sahgrasp.objects.frames import FloatArray, transform_points

__all__ = ["COARSE_CELL_M", "CollisionShape", "PieceTree", "convex_hull", "signed_distances"]

COARSE_CELL_M = 0.02
"""Grid cell [m] of :class:`PieceTree`'s coarse level: the pieces whose centres share a cell are
bounded by one convex hull (smaller: tighter bounds, more hulls to query)."""


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


def _support_points(shape: CollisionShape) -> FloatArray:
    """Points (N, 3) in the object frame whose convex hull holds ``shape``.

    A convex hull's own vertices; for a primitive (box, ellipsoid), the corners of its box.
    """
    geometry = shape.geometry
    if isinstance(geometry, coal.ConvexBase):
        local = np.asarray(geometry.points(), dtype=np.float64)
    else:
        geometry.computeLocalAABB()
        box = geometry.aabb_local
        low, high = np.asarray(box.min_), np.asarray(box.max_)
        local = np.array([[(low, high)[(k >> i) & 1][i] for i in range(3)] for k in range(8)])
    return transform_points(shape.placement, local)


class PieceTree:
    """An object's convex pieces in coal's broad phase, in the object frame, with a coarse level.

    Queries take a coal collision object (a hand link) already placed in the object frame. The
    fine level holds the pieces themselves; the coarse level one convex hull per grid cell of
    ``cell_m`` holding the pieces whose centres fall in it (a lone piece stands for itself).

    Args:
        shapes: The object's pieces.
        cell_m: Coarse grid cell [m].
    """

    def __init__(self, shapes: Sequence[CollisionShape], cell_m: float = COARSE_CELL_M) -> None:
        self._fine = _Manager([(s.geometry, s.placement) for s in shapes])
        self._coarse = _Manager(_coarse_pieces(shapes, cell_m))
        self.coarse_size = len(self._coarse.objects)
        self._collision = coal.CollisionCallBackDefault()

    def lower_bound(self, link: coal.CollisionObject) -> float:
        """A lower bound [m] of the signed distance from ``link`` to the object (-inf: none).

        The distance to the coarse hulls when it is positive: the hulls hold every piece.
        """
        bound = self._coarse.nearest(link)
        return bound if bound > 0.0 else -math.inf

    def nearest(self, link: coal.CollisionObject) -> float:
        """The smallest signed distance [m] from ``link`` to a piece when it is positive.

        When ``link`` touches or enters a piece, the signed distance of one such pair (<= 0): an
        upper bound of the smallest, as coal's default callback stops at the first pair in
        contact. ``inf`` for an object without pieces.
        """
        return self._fine.nearest(link)

    def clear_of(self, link: coal.CollisionObject, threshold_m: float) -> bool:
        """True if no piece is closer to ``link`` than ``threshold_m`` [m] (signed; exact)."""
        if self.lower_bound(link) >= threshold_m:
            return True
        distance = self.nearest(link)
        if distance > 0.0 or distance < threshold_m:
            return distance >= threshold_m
        if threshold_m > 0.0:
            return False
        # threshold <= distance <= 0: a deeper pair may exist; only overlapping boxes can hold one.
        self._collision.init()
        self._collision.data.request.security_margin = threshold_m
        self._fine.manager.collide(link, self._collision)
        return not self._collision.data.result.isCollision()


class _Manager:
    """Placed shapes registered in a coal dynamic AABB tree, and its distance callback."""

    def __init__(self, placed: Sequence[tuple[coal.ShapeBase, FloatArray]]) -> None:
        self.objects = [
            coal.CollisionObject(geometry, coal.Transform3s(T[:3, :3], T[:3, 3]))
            for geometry, T in placed
        ]
        self.manager = coal.DynamicAABBTreeCollisionManager()
        for obj in self.objects:
            obj.computeAABB()
            self.manager.registerObject(obj)
        self.manager.setup()
        self._callback = coal.DistanceCallBackDefault()
        self._callback.data.request.enable_signed_distance = True

    def nearest(self, link: coal.CollisionObject) -> float:
        if not self.objects:
            return math.inf
        self._callback.init()
        self.manager.distance(link, self._callback)
        return float(self._callback.data.result.min_distance)


def _coarse_pieces(
    shapes: Sequence[CollisionShape], cell_m: float
) -> list[tuple[coal.ShapeBase, FloatArray]]:
    """One convex hull per grid cell of the pieces' centres, holding that cell's pieces."""
    if not shapes:
        return []
    centres = np.array([s.placement[:3, 3] for s in shapes])
    _, cells = np.unique(np.floor(centres / cell_m), axis=0, return_inverse=True)
    out = []
    for cell in range(int(cells.max()) + 1):
        members = [shapes[int(i)] for i in np.flatnonzero(cells.ravel() == cell)]
        if len(members) == 1:
            out.append((members[0].geometry, members[0].placement))
        else:
            hull = convex_hull(np.vstack([_support_points(m) for m in members]))
            out.append((hull.geometry, hull.placement))
    return out


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
