"""An object's collision geometry as a union of convex coal shapes, and signed distances to it.

Convex pieces (coal primitives or convex hulls) give a signed distance: positive outside, the
negative penetration depth inside, which a triangle mesh (``coal.BVHModel``) cannot give for a
point inside a closed surface. Each piece carries a bounding sphere, so that a query skips the
pieces that cannot be the closest.

:class:`PieceTree` puts the pieces in coal's broad phase (a dynamic AABB tree, queried in C++)
under a coarse level of convex hulls, each holding the pieces of one grid cell: a link clear of
the hulls by a margin is clear of the pieces, so most links cost one coarse query, and whether a
link comes closer than a margin is answered without a Python call per piece.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import coal
import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp.core.frames import FloatArray, transform_points

__all__ = [
    "COARSE_CELL_M",
    "BuiltOnce",
    "CollisionShape",
    "PieceTree",
    "convex_hull",
    "signed_distances",
]

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


class BuiltOnce:
    """Mixin of solids whose collision pieces are built once (``functools.cached_property``).

    Coal shapes cannot be pickled, and a solid goes to worker processes as plain data: pickling
    leaves out every cached property, and the worker builds it again on first use.
    """

    def __getstate__(self) -> dict[str, Any]:
        cached = {
            name
            for cls in type(self).__mro__
            for name, value in vars(cls).items()
            if isinstance(value, cached_property)
        }
        return {k: v for k, v in self.__dict__.items() if k not in cached}


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
    ``cell_m``, holding the pieces whose centres fall in it (a lone piece stands for itself).
    A query is a coal collision test with a security margin, run in C++ over the AABB tree:
    coal's default distance callback cannot serve, as it keeps the last pair's distance, not the
    smallest.

    Args:
        shapes: The object's pieces.
        cell_m: Coarse grid cell [m].

    Attributes:
        coarse_centres_m: Centre of a ball about each coarse hull, object frame (K, 3) [m].
        coarse_radii_m: Radius of each such ball (K,) [m].
        boxes_m: Each piece's axis-aligned box in the object frame, (N, 2, 3): low, high [m].
        coarse_boxes_m: Each coarse hull's box in the object frame, (K, 2, 3) [m].
        cells: The coarse hull holding each piece, (N,).
        members: The pieces of each coarse hull, in hull order (K arrays of indices).
        sizes: How many pieces each coarse hull holds, (K,).
    """

    def __init__(self, shapes: Sequence[CollisionShape], cell_m: float = COARSE_CELL_M) -> None:
        self.cells = _cells(shapes, cell_m)
        order = np.argsort(self.cells, kind="stable")
        splits = np.flatnonzero(np.diff(self.cells[order])) + 1
        self.members = tuple(np.split(order, splits)) if len(order) else ()
        self.sizes = np.array([len(m) for m in self.members], dtype=np.intp)
        coarse = _coarse_pieces(shapes, self.cells)
        # The trees hold raw pointers to the collision objects: keep them (and their shapes).
        self._shapes = (tuple(shapes), tuple(coarse))
        self._objects = tuple([_collision_object(s) for s in level] for level in self._shapes)
        self._fine, self._coarse = (_manager(objects) for objects in self._objects)
        self.coarse_centres_m = np.array([s.placement[:3, 3] for s in coarse]).reshape(-1, 3)
        self.coarse_radii_m = np.array([s.bounding_radius_m for s in coarse])
        self.boxes_m = _boxes(self._objects[0])
        self.coarse_boxes_m = _boxes(self._objects[1])
        self._callback = coal.CollisionCallBackDefault()
        # Its request and result, looked up once: init() clears the result in place and keeps
        # the request, and each lookup through ``data`` builds two Python wrappers.
        self._request = self._callback.data.request
        self._result = self._callback.data.result
        self._distances = coal.DistanceCallBackDefault()
        self._distances.data.request.enable_signed_distance = True  # init() keeps the request

    def clear_of(self, link: coal.CollisionObject, threshold_m: float) -> bool:
        """True if no piece is closer to ``link`` than ``threshold_m`` [m] (signed distance).

        Exact up to coal's GJK/EPA tolerances: the coarse hulls hold the pieces, so a link
        clear of them is clear of the pieces; otherwise the pieces are tested.
        """
        return not (
            self._closer(self._coarse, link, threshold_m)
            and self._closer(self._fine, link, threshold_m)
        )

    def first_pair(
        self, link: coal.CollisionObject, threshold_m: float
    ) -> tuple[float, FloatArray, FloatArray, FloatArray] | None:
        """A (piece, ``link``) pair closer than ``threshold_m`` [m], None if there is none.

        The first pair coal's collision test finds in the pieces' AABB tree (one C++ query, the
        link posed in the object frame): its signed distance [m], witness points on the piece
        and on the link and normal from the piece towards the link, in the object frame; the
        values GJK/EPA gives that pair's distance query.
        """
        if not self._closer(self._fine, link, threshold_m):
            return None
        contact = self._result.getContact(0)  # the piece is o1, the link o2
        return (
            float(contact.penetration_depth),  # coal stores the signed distance there
            np.array(contact.getNearestPoint1(), dtype=np.float64),
            np.array(contact.getNearestPoint2(), dtype=np.float64),
            np.array(contact.normal, dtype=np.float64),
        )

    def overlapped_by(self, links: coal.BroadPhaseCollisionManager, depth_m: float) -> bool:
        """True if a link of ``links`` enters a piece deeper than ``depth_m`` >= 0 [m].

        A C++ query of two AABB trees (coal's collision test with the security margin
        ``-depth_m``, per pair of overlapping boxes), whatever the number of links: the verdict
        :meth:`clear_of` gives link by link at the threshold ``-depth_m``, the links posed in
        the object frame and the manager updated. The coarse hulls first, as there: a link no
        deeper than ``depth_m`` in a hull is no deeper in its pieces (on the contact tips of
        the IK's acceptance tests, 31 instead of 52 us on the coffee cup).
        """
        return self._entered(self._coarse, links, depth_m) and self._entered(
            self._fine, links, depth_m
        )

    def _entered(
        self,
        manager: coal.BroadPhaseCollisionManager,
        links: coal.BroadPhaseCollisionManager,
        depth_m: float,
    ) -> bool:
        """True if a link of ``links`` enters a shape of ``manager`` deeper than ``depth_m``."""
        return self._collides(manager, links, -depth_m)

    def nearest(
        self,
        links: coal.BroadPhaseCollisionManager | coal.CollisionObject,
        below_m: float = math.inf,
    ) -> tuple[float, FloatArray]:
        """The smallest signed distance [m] from the pieces to ``links`` (posed, object frame).

        And the pair's witness point on the link, object frame [m] (meaningless when no pair
        is nearer than ``below_m``).

        One C++ query: coal's broad-phase distance, a GJK/EPA call per (piece, link) pair whose
        boxes are nearer than the smallest distance found so far, the pair's arguments in the
        order :class:`~sahgrasp.collision.hand_object.HandObjectClearance` measures them in. Exact
        when positive and below ``below_m``; ``below_m`` or more if no pair is nearer than
        ``below_m`` (the search starts from it: only nearer boxes are opened). Coal stops at
        the first pair touching or overlapping: a value <= 0 says that some pair does, not that
        it is the deepest.
        """
        self._distances.init()
        self._distances.data.result.min_distance = below_m  # coal keeps the smaller one
        self._fine.distance(links, self._distances)
        result = self._distances.data.result  # the piece is o1, the link o2
        return float(result.min_distance), np.array(result.getNearestPoint2(), dtype=np.float64)

    def _closer(
        self, manager: coal.BroadPhaseCollisionManager, link: coal.CollisionObject, limit_m: float
    ) -> bool:
        """True if a shape of ``manager`` is closer to ``link`` than ``limit_m`` [m]."""
        link.computeAABB()
        if limit_m > 0.0:  # the tree only pairs overlapping boxes: grow the link's by the margin
            link.getAABB().expand(limit_m)
        closer = self._collides(manager, link, limit_m)
        link.computeAABB()  # leave the link's own box for the caller's bounds
        return closer

    def _collides(
        self,
        manager: coal.BroadPhaseCollisionManager,
        other: coal.BroadPhaseCollisionManager | coal.CollisionObject,
        margin_m: float,
    ) -> bool:
        """One collision test of ``manager`` against ``other`` with the security margin given.

        The callback keeps its result (the first pair found) for :meth:`first_pair`.
        """
        self._callback.init()
        self._request.security_margin = margin_m
        manager.collide(other, self._callback)
        return bool(self._result.isCollision())


def _boxes(objects: Sequence[coal.CollisionObject]) -> FloatArray:
    """The objects' axis-aligned boxes, (N, 2, 3): low and high corners [m]."""
    boxes = [(o.getAABB().min_, o.getAABB().max_) for o in objects]
    return np.array(boxes, dtype=np.float64).reshape(-1, 2, 3)


def _collision_object(shape: CollisionShape) -> coal.CollisionObject:
    return coal.CollisionObject(shape.geometry, shape.transform(np.eye(4)))


def _manager(objects: list[coal.CollisionObject]) -> coal.BroadPhaseCollisionManager:
    """A dynamic AABB tree of ``objects`` (the caller keeps them alive)."""
    manager = coal.DynamicAABBTreeCollisionManager()
    for obj in objects:
        obj.computeAABB()
        manager.registerObject(obj)
    manager.setup()
    return manager


def _cells(shapes: Sequence[CollisionShape], cell_m: float) -> NDArray[np.intp]:
    """The grid cell of each piece's centre, numbered from 0, (N,)."""
    if not shapes:
        return np.zeros(0, dtype=np.intp)
    centres = np.array([s.placement[:3, 3] for s in shapes])
    _, cells = np.unique(np.floor(centres / cell_m), axis=0, return_inverse=True)
    return np.asarray(cells, dtype=np.intp).ravel()


def _coarse_pieces(
    shapes: Sequence[CollisionShape], cells: NDArray[np.intp]
) -> list[CollisionShape]:
    """One convex hull per grid cell of the pieces' centres, holding that cell's pieces."""
    if not shapes:
        return []
    out = []
    for cell in range(int(cells.max()) + 1):
        members = [shapes[int(i)] for i in np.flatnonzero(cells == cell)]
        if len(members) == 1:
            out.append(members[0])
        else:
            out.append(convex_hull(np.vstack([_support_points(m) for m in members])))
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
