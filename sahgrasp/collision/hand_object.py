"""Hand-object clearance: signed distances between a hand's collision shapes and an object.

The object is a union of convex coal pieces (:mod:`sahgrasp.collision.shapes`); every hand link
shape (box, cylinder, sphere of the URDF) is convex too, so coal's GJK/EPA gives each (link, piece)
pair an exact signed distance: the gap outside, minus the penetration depth inside. A triangle
mesh (``coal.BVHModel``) would give no negative distance for a link wholly inside a closed surface.
The signed distance of a link to the object is the smallest over the pieces: its sign is exact
(negative if and only if the link overlaps the object), and inside its magnitude is the depth to
the nearest face of an overlapped piece, which may be an internal face between two pieces, so it
can underestimate the depth into the union.

Contact fingertips. The fingertip sphere of a finger that has a contact (the geometry of that
finger's ``tip_link``, e.g. ``ring_tip`` of the SAH) touches the object by design, and the IK
accepts its contact point up to ``d_min`` from the surface: that sphere alone may penetrate the
object by up to ``allowance_m``. Only the tip link's geometry is excepted; the distal phalanx on
the same joint is checked as every other link.

Cost. The object may have thousands of small pieces (one per mesh triangle, or per sector of a
revolved band), so no query tries them all. One numpy pass bounds every link against every
coarse hull of the :class:`~sahgrasp.collision.shapes.PieceTree` (the link's box or sphere, a
cylinder's box, against the hull's ball, and the two boxes' gap) and, through one anchor point
inside each hull, bounds the closest distance from above: links bounded away cost nothing more.
A remaining link's pieces are taken by increasing lower bound (the link's shape against the
piece's ball, and their boxes) and measured with bare ``coal.distance`` calls (GJK/EPA, about
2 us each); up to :data:`_FEW_PIECES` candidates are measured directly, more are bounded first
and the piece tree (C++, object frame, built once) is asked whether any is closer at all. The
results are those of measuring every pair (docs/methods/meshes.md, "What a hand–object query
costs").
The IK's acceptance test (:meth:`HandObjectClearance.clearance_if_clear`) and repair query
(:meth:`HandObjectClearance.penetrations` with ``per_link=1``) go to the piece tree's C++ queries
instead: collision tests and one broad-phase distance, whatever the number of links.

The object side of a :class:`~sahgrasp.collision.hand_self.Penetration` is joint 0 (the universe,
which does not move), so the IK's separation rows ``n^T (J_b(p_b) - J_a(p_a))`` hold with ``J_a =
0``.

The hand and the object are what the queries read of them (:class:`ClearanceHand`,
:class:`ClearanceObject`): a :class:`sahgrasp.model.hand.Hand` and a
:class:`sahgrasp.objects.GraspObject` are both, and this package, below the model and the
objects, imports neither.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar

import coal
import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from sahgrasp.collision.hand_self import (
    Penetration,
    SelfCollision,
    copied_placements,
    geometry_placement_views,
)
from sahgrasp.collision.shapes import CollisionShape, PieceTree
from sahgrasp.core.errors import InvalidSettingsError, InvalidTargetError
from sahgrasp.core.frames import FloatArray, as_placement

__all__ = [
    "CONTACT_ALLOWANCE_M",
    "FREE_FINGER_MARGIN_M",
    "Clearance",
    "ClearanceHand",
    "ClearanceObject",
    "FreeFingerPlacement",
    "HandObjectClearance",
]


class _Finger(Protocol):
    @property
    def name(self) -> str: ...

    @property
    def tip_link(self) -> str: ...


class _Description(Protocol):
    @property
    def name(self) -> str: ...

    @property
    def fingers(self) -> Sequence[_Finger]: ...


class ClearanceHand(Protocol):
    """What the clearance queries read of a hand (:class:`sahgrasp.model.hand.Hand` is one).

    Its Pinocchio model and collision geometry (``collision``), its fingers' names and tip links
    (``description``), its coordinates (names, each finger's, the virtual contact joints, the
    limits [rad]) and the two helpers on configurations.
    """

    @property
    def model(self) -> pin.Model:
        """The Pinocchio model (free-flyer wrist)."""

    @property
    def collision(self) -> SelfCollision:
        """The self-collision queries, whose ``geometry_model`` the links are."""

    @property
    def description(self) -> _Description:
        """The hand's name and fingers (names, tip links)."""

    @property
    def virtual_joint_names(self) -> tuple[str, ...]:
        """The virtual contact joints, not moved to place a free finger."""

    @property
    def coordinate_names(self) -> tuple[str, ...]:
        """The joint of each finger coordinate."""

    @property
    def finger_coordinates(self) -> dict[str, NDArray[np.intp]]:
        """Per finger, its coordinates' indices in ``finger_part(q)``."""

    @property
    def lower(self) -> NDArray[np.float64]:
        """Lower limits of the finger coordinates [rad]."""

    @property
    def upper(self) -> NDArray[np.float64]:
        """Upper limits of the finger coordinates [rad]."""

    def check_q(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``q`` checked: its size and finiteness."""

    def finger_part(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """The finger coordinates of ``q`` (a view)."""


class ClearanceObject(Protocol):
    """What the clearance queries read of an object (:class:`sahgrasp.objects.GraspObject` is one).

    Its convex pieces in the object frame and its placement in the world.
    """

    @property
    def T_world_object(self) -> FloatArray:
        """The object's placement in the world (4x4)."""

    def collision_shapes(self) -> tuple[CollisionShape, ...]:
        """The convex pieces whose union is the object, in the object frame."""


class _NoObject:
    """No object: no piece, every link clear of it (to place free fingers clear of the hand)."""

    T_world_object: FloatArray = as_placement(np.eye(4))

    def collision_shapes(self) -> tuple[CollisionShape, ...]:
        return ()


HandT = TypeVar("HandT", bound=ClearanceHand)
"""The hand type of a :class:`HandObjectClearance` (its ``hand`` attribute is the one given)."""

CONTACT_ALLOWANCE_M = 1.5e-3
"""Default penetration allowed to a contact fingertip sphere: the IK's ``d_min`` [m]."""

FREE_FINGER_MARGIN_M = 2e-3
"""Default clearance [m] a free finger keeps from the object and from the other links."""

_GRID_STEPS = 6
"""Values per joint of a free finger tried by :meth:`HandObjectClearance.place_free_fingers`."""

_TIE_M = 1e-12
"""Distances [m] within this of the smallest are measured again link by link to find its link:
the pair coal's broad phase found is measured with the same arguments, so equal up to rounding."""

_ON_SURFACE_M = 1e-5
"""How far [m] outside a link's shape the witness point of its nearest pair may be found (a
margin far above GJK's tolerance): the links within it of a pair's witness are its candidates."""

_FEW_PIECES = 12
"""Up to this many candidate pieces, a link is measured against each (about 2 us per GJK call)
rather than bounded in numpy or asked about in the piece tree (tens of microseconds each)."""


@dataclass(frozen=True)
class Clearance:
    """Signed distances from the hand's links to the object at one configuration.

    Attributes:
        distance_m: Smallest signed distance [m] over the links, contact tips within their
            allowance left out (negative: a link is inside the object).
        link: The link at ``distance_m``.
        links_m: Signed distance [m] of every link to the object, contact tips included; from
            a query that asked for the closest link only, the links measured to find it.
    """

    distance_m: float
    link: str
    links_m: Mapping[str, float]

    def clear(self, tolerance_m: float = 0.0) -> bool:
        """True if no link (allowed contact tips excepted) is deeper than ``tolerance_m`` [m]."""
        return self.distance_m >= -tolerance_m


@dataclass(frozen=True)
class FreeFingerPlacement:
    """Where :meth:`HandObjectClearance.place_free_fingers` put the fingers without a contact.

    Attributes:
        q: The configuration with the free fingers placed (every other coordinate unchanged).
        distance_m: Smallest signed distance [m] of the free fingers' links to the object and to
            the other links they are checked against: exact below the margin; when clear, some
            value at least the margin (pairs whose bounding balls are farther apart are not
            measured; infinite if none is nearer).
        clear: Whether ``distance_m`` reaches the margin asked for.
    """

    q: NDArray[np.float64]
    distance_m: float
    clear: bool


@dataclass(frozen=True)
class _FreeFinger:
    """A finger's own joint coordinates, the geometries they move, and its self-collision pairs."""

    coordinates: NDArray[np.intp]  # indices in hand.finger_part(q)
    grid: NDArray[np.float64]  # candidate values of those coordinates, (N, len(coordinates))
    geometries: NDArray[np.intp]  # hand geometries moved by the coordinates
    pairs: NDArray[np.intp]  # hand geometry pairs (P, 2) the hand checks for self-collision


@dataclass(frozen=True)
class _Pair:
    """One (hand geometry, object piece) signed distance with coal's witnesses (world frame)."""

    geometry: int
    distance_m: float
    point_object: FloatArray
    point_hand: FloatArray
    normal: FloatArray  # from the object towards the hand link


class HandObjectClearance(Generic[HandT]):
    """Signed distances between a hand's collision geometry and an object's convex pieces.

    Independent of any solver: it owns its Pinocchio data and coal geometry data, so queries
    share no mutable state with the hand or with other queries.

    Args:
        hand: The hand (its model and coal collision geometry are used, not modified).
        obj: The object; its pieces are placed at ``obj.T_world_object`` unless a query gives
            another placement. None: no object (every link is clear of it), e.g. to place free
            fingers clear of the other links only.
    """

    def __init__(self, hand: HandT, obj: ClearanceObject | None) -> None:
        self.hand = hand
        self.object: ClearanceObject = _NoObject() if obj is None else obj
        self._model = hand.model
        self._data = hand.model.createData()
        self._geometry_model = hand.collision.geometry_model
        self._geometry_data = pin.GeometryData(self._geometry_model)
        geometries = self._geometry_model.geometryObjects
        self._links = tuple(str(hand.model.frames[g.parentFrame].name) for g in geometries)
        self._joints = tuple(int(g.parentJoint) for g in geometries)
        self._shapes = self.object.collision_shapes()
        self._piece_centres = np.array([s.placement[:3, 3] for s in self._shapes]).reshape(-1, 3)
        self._piece_radii = np.array([s.bounding_radius_m for s in self._shapes])
        self._all_pieces = np.arange(len(self._shapes))
        centres, radii, halves = [], [], []
        for g in geometries:
            g.geometry.computeLocalAABB()
            centres.append(np.asarray(g.geometry.aabb_center, dtype=np.float64))
            radii.append(float(g.geometry.aabb_radius))
            box = g.geometry.aabb_local
            halves.append((np.asarray(box.max_) - np.asarray(box.min_)) / 2.0)
        self._link_centres = np.array(centres)
        self._link_radii = np.array(radii)
        self._link_halves = np.array(halves)  # local box half extents [m]
        # The placements at the last _place: views of oMg, which Pinocchio writes in place.
        views = geometry_placement_views(self._geometry_data)
        self._copy_placements = views is None
        self._link_R, self._link_t = views or copied_placements(self._geometry_data)
        self._every = np.arange(len(geometries))
        # Pinocchio's broad phase of the hand holds a collision object per geometry and places
        # them all in one C++ call (2 instead of 33 us for the SAH's 22, in Python): the link
        # objects when the object frame is the world's. It leaves a geometry in no active
        # collision pair unplaced: then the links are placed one by one, as otherwise.
        hand_tree = pin.BroadPhaseManager_DynamicAABBTreeCollisionManager(
            self._model, self._geometry_model, self._geometry_data
        )
        self._hand_tree = hand_tree if all(hand_tree.getCollisionObjectStatus()) else None
        self._link_objects: list[coal.CollisionObject] = list(hand_tree.getCollisionObjects())
        self._geometries = [g.geometry for g in geometries]
        self._link_transforms: list[coal.Transform3s | None] = [None] * len(geometries)
        self._posed = [False] * len(geometries)  # link objects in the object frame
        self._hand_placed = False  # the hand tree placed the link objects (at _place)
        self._centred = not self._link_centres.any()  # boxes about the link origins
        self._describe_shapes([g.geometry for g in geometries])
        self._tree = PieceTree(self._shapes)
        # The pieces' boxes as two contiguous (N, 3) arrays: one gather each per bound.
        self._piece_lows_m = np.ascontiguousarray(self._tree.boxes_m[:, 0])
        self._piece_highs_m = np.ascontiguousarray(self._tree.boxes_m[:, 1])
        boxes = self._tree.boxes_m
        # The low and high corners of the box holding every piece (none: an empty box).
        self._object_box_m = (
            np.array([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)])
            if len(boxes)
            else np.array([np.full(3, np.inf), np.full(3, -np.inf)])
        )
        # Per coarse hull, the centre of its piece nearest its ball's centre: inside the object.
        self._anchors = np.array(
            [
                self._piece_centres[m][
                    np.argmin(np.linalg.norm(self._piece_centres[m] - c, axis=1))
                ]
                for m, c in zip(self._tree.members, self._tree.coarse_centres_m, strict=True)
            ]
        ).reshape(-1, 3)
        self._coarse_points = np.vstack([self._tree.coarse_centres_m, self._anchors])
        self._tips = {f.name: f.tip_link for f in hand.description.fingers}
        self._request = coal.DistanceRequest()
        self._request.enable_signed_distance = True
        self._result = coal.DistanceResult()  # cleared before each use
        self._free: dict[str, _FreeFinger] = {}
        self._transforms_key = b""
        self._thresholds_cache: dict[tuple[frozenset[str], float, float], FloatArray] = {}
        self._link_trees: dict[
            bytes,
            tuple[
                coal.BroadPhaseCollisionManager, coal.BroadPhaseCollisionManager, NDArray[np.intp]
            ],
        ] = {}
        self._placement_key = b""
        self._object_world = pin.SE3.Identity()  # T^-1 of the last _place
        self._object_at_origin = True  # whether that T is the identity

    def _describe_shapes(self, shapes: Sequence[coal.ShapeBase]) -> None:
        """Per hand geometry, the rounded box :meth:`_shape_gaps` measures it as.

        A box is itself, a sphere a box of no size rounded by its radius: their gaps are exact.
        A cylinder is measured as its bounding box (exactly, by :meth:`_piece_bounds`), another
        shape as its bounding ball: their gaps are lower bounds only.
        """
        self._half_m = np.zeros((len(shapes), 1, 3))
        self._rounding_m = np.zeros((len(shapes), 1))
        self._offset_m = np.zeros((len(shapes), 1, 3))  # the box's centre in the link frame
        self._exact = np.zeros(len(shapes), dtype=bool)
        self._cylinder_m = np.zeros((len(shapes), 1, 3))  # (radius, half length, inf)
        for g, shape in enumerate(shapes):
            if isinstance(shape, coal.Box):
                self._half_m[g] = shape.halfSide
                self._exact[g] = True
            elif isinstance(shape, coal.Cylinder):
                self._half_m[g] = shape.radius, shape.radius, shape.halfLength
                self._cylinder_m[g] = shape.radius, shape.halfLength, np.inf
            elif isinstance(shape, coal.Sphere):
                self._rounding_m[g] = shape.radius
                self._exact[g] = True
            else:
                self._rounding_m[g] = self._link_radii[g]
                self._offset_m[g] = self._link_centres[g]
        self._offset = bool(self._offset_m.any())

    @property
    def piece_tree(self) -> PieceTree:
        """The object's pieces in coal's broad phase with their coarse cells (object frame)."""
        return self._tree

    @property
    def links(self) -> tuple[str, ...]:
        """Links with collision geometry, one per hand geometry (a link may repeat)."""
        return self._links

    # ----- queries --------------------------------------------------------------------------
    def penetrations(
        self,
        q: NDArray[np.float64],
        margin_m: float = 0.0,
        contacts: Iterable[str] = (),
        allowance_m: float = CONTACT_ALLOWANCE_M,
        T_world_object: FloatArray | None = None,
        per_link: int | None = None,
        geometries: Iterable[int] | None = None,
    ) -> list[Penetration]:
        """Every (link shape, object piece) pair closer than required at ``q``.

        A link shape must stay ``margin_m`` [m] away from the object. The fingertip sphere of a
        finger in ``contacts`` is exempt from the margin and may penetrate up to ``allowance_m``
        [m]: it is reported only below ``-allowance_m``. ``joint_a`` is 0 (the object, fixed),
        ``point_a`` on the object, ``normal`` from the object towards the link, and ``depth_m``
        how far the link must move along ``normal`` to reach its required distance.

        ``per_link``: at most this many pairs per link shape, the first ones found closer than
        required, pieces taken by increasing lower bound of their distance (None: all); with 1,
        the first pair coal's collision test finds in the piece tree, one C++ query per link
        whose bounding ball comes within its threshold of the object's box
        (:meth:`PieceTree.first_pair`). The IK's repair asks for one: a link deep in a finely
        cut object overlaps hundreds of pieces, and a row per pair costs a GJK call and a
        Jacobian each, for normals that mostly agree
        (:data:`sahgrasp.ik.obstacle.REPAIR_PAIRS_PER_LINK`). ``geometries`` (with
        ``per_link=1``): the only hand geometries to ask about, e.g. those the IK's compiled
        check found near the object (None: those whose balls come near the object's box).

        Raises:
            InvalidTargetError: A finger in ``contacts`` is not a finger of the hand.
            InvalidSettingsError: ``margin_m`` or ``allowance_m`` is negative or not finite.
        """
        thresholds, T = self._query(q, contacts, margin_m, allowance_m, T_world_object)
        pairs: list[_Pair] = []
        if per_link == 1:  # a C++ query per link costs less than finer bounds in numpy
            near = (
                self._within_object_box(T, thresholds).tolist()
                if geometries is None
                else list(geometries)
            )
            self._pose_links(near)
            for g in near:
                pairs += self._first_pair(T, g, float(thresholds[g]))
        else:
            for g, bounds, upper in self._near_links(T, thresholds, None):
                self._link_pieces(T, g, bounds, thresholds[g], per_link, pairs, upper)
        return [
            Penetration(
                0,
                self._joints[p.geometry],
                p.point_object,
                p.point_hand,
                p.normal,
                float(thresholds[p.geometry] - p.distance_m),
            )
            for p in pairs
        ]

    def penetrated(
        self,
        q: NDArray[np.float64],
        contacts: Iterable[str] = (),
        allowance_m: float = CONTACT_ALLOWANCE_M,
        T_world_object: FloatArray | None = None,
    ) -> bool:
        """Whether a link is inside the object at ``q`` (contact tips: deeper than allowed).

        The verdict of ``bool(penetrations(q, 0.0, contacts, allowance_m))`` and of
        ``not clearance(...).clear()``, found at the first such pair: a grasp optimization
        checking thousands of chart centres needs the verdict only.

        Raises:
            InvalidTargetError: A finger in ``contacts`` is not a finger of the hand.
            InvalidSettingsError: ``allowance_m`` is negative or not finite.
        """
        thresholds, T = self._query(q, contacts, 0.0, allowance_m, T_world_object)
        near = self._near_links(T, thresholds, None)
        return any(
            self._link_pieces(T, g, bounds, thresholds[g], 1, None, upper)
            for g, bounds, upper in near
        )

    def clearance(
        self,
        q: NDArray[np.float64],
        contacts: Iterable[str] = (),
        allowance_m: float = CONTACT_ALLOWANCE_M,
        T_world_object: FloatArray | None = None,
        all_links: bool = True,
    ) -> Clearance:
        """Signed distance of every link to the object and the smallest one at ``q``.

        The fingertip sphere of a finger in ``contacts`` enters the smallest distance only when
        it is deeper than ``allowance_m`` [m] inside the object.

        Args:
            q: Hand configuration.
            contacts: Fingers whose tip spheres touch the object at their contacts.
            allowance_m: How deep those spheres may enter the object [m].
            T_world_object: The object's placement (default: its own).
            all_links: False: find the smallest distance and its link only, measuring just the
                links whose lower bound is below it (``links_m`` holds those); a far link then
                costs one coarse query instead of an exact distance.

        Raises:
            InvalidTargetError: A finger in ``contacts`` is not a finger of the hand.
            InvalidSettingsError: ``allowance_m`` is negative or not finite.
        """
        thresholds, T = self._query(q, contacts, 0.0, allowance_m, T_world_object)
        measured = self._every_link(T) if all_links else self._closest_links(T, thresholds)
        return self._summary(measured, thresholds)

    def clearance_if_clear(
        self,
        q: NDArray[np.float64],
        contacts: Iterable[str] = (),
        allowance_m: float = CONTACT_ALLOWANCE_M,
        T_world_object: FloatArray | None = None,
    ) -> Clearance | None:
        """The clearance at ``q`` if no link is inside the object, None if one is.

        The IK's acceptance test: the verdict, and the exact clearance of a configuration it
        accepts (what ``clearance(q, contacts, allowance_m, all_links=False)`` gives, up to the
        rounding of the object frame: ``links_m`` holds the links at the smallest distance),
        without measuring where a configuration inside is deepest. Two C++ queries of the
        piece tree answer it, whatever the number of links: are the contact tips deeper than
        ``allowance_m`` (one collision test), and the smallest distance of the other links (one
        broad-phase distance). Its link is the one whose shape holds the pair's witness point;
        when several do, each is measured alone, and when none does, the search of
        :meth:`clearance` finds it.

        Raises:
            InvalidTargetError: A finger in ``contacts`` is not a finger of the hand.
            InvalidSettingsError: ``allowance_m`` is negative or not finite.
        """
        thresholds, T = self._query(q, contacts, 0.0, allowance_m, T_world_object)
        if not self._shapes:
            return Clearance(math.inf, "", {})
        counted, tips, members = self._managers(thresholds)
        self._pose_links(self._every.tolist())
        tips.update()
        counted.update()
        if tips.size() and self._tree.overlapped_by(tips, allowance_m):
            return None
        distance_m, point_m = self._tree.nearest(counted)
        if distance_m < 0.0:
            return None
        if distance_m == 0.0:  # coal stops at a touching pair: another may be inside
            found = self._summary(self._closest_links(T, thresholds, 0.0), thresholds)
            return found if found.clear() else None
        # The pair's link holds its witness point: it is among the links whose shape (box,
        # sphere; a cylinder's box, another shape's ball) comes within _ON_SURFACE_M of it.
        # A lone such link is the pair's; several are measured (ties go as in clearance).
        world_m = T[:3, :3] @ point_m + T[:3, 3]
        gaps = self._shape_gaps(None, world_m[None])[members, 0]  # no gathers of placements
        holders = members[gaps <= _ON_SURFACE_M].tolist()
        if len(holders) == 1:
            measured = {holders[0]: distance_m}
        else:  # the ceiling lets a last-bit difference through
            ceiling_m = distance_m + _TIE_M
            distances = {
                g: self._tree.nearest(self._link_objects[g], ceiling_m)[0] for g in holders
            }
            measured = {g: d for g, d in distances.items() if d < ceiling_m}
        # None found (a witness off its shape): the search measures them as clearance does.
        return self._summary(measured or self._closest_links(T, thresholds), thresholds)

    def place_free_fingers(
        self,
        q: NDArray[np.float64],
        fingers: Iterable[str],
        margin_m: float = FREE_FINGER_MARGIN_M,
        T_world_object: FloatArray | None = None,
    ) -> FreeFingerPlacement:
        """Move each finger without a contact to the nearest configuration that touches nothing.

        A free finger is no part of the grasp constraints, so only its own joints move: over a
        grid of its joint range (the fully opened and fully closed ends included) and its
        current values, the candidate nearest to its current joint values (Euclidean, in
        radians) whose links keep ``margin_m`` [m] from the object and from every other link
        the hand's self-collision checks them against. Fingers are placed in turn, each seeing
        the ones before. When no candidate is clear, the finger takes the clearest one and the
        result says ``clear=False``.

        Raises:
            InvalidTargetError: A name in ``fingers`` is not a finger of the hand.
            InvalidSettingsError: ``margin_m`` is negative or not finite.
        """
        self.thresholds((), margin_m, 0.0)
        q = self.hand.check_q(q).copy()
        T = self._placement(T_world_object)
        distance = math.inf
        for finger in fingers:
            q, finger_distance = self._place_finger(q, self._free_finger(finger), margin_m, T)
            distance = min(distance, finger_distance)
        return FreeFingerPlacement(q, distance, distance >= margin_m)

    # ----- internals ------------------------------------------------------------------------
    def _summary(self, measured: Mapping[int, float], thresholds: FloatArray) -> Clearance:
        """The clearance of the hand geometries' ``measured`` signed distances [m]."""
        links: dict[str, float] = {}
        distance, closest = math.inf, ""
        for g in sorted(measured):  # in geometry order: a tie goes to the first link
            link, d = self._links[g], measured[g]
            links[link] = min(links.get(link, math.inf), d)
            excepted = thresholds[g] < 0.0 and d >= thresholds[g]
            if not excepted and d < distance:
                distance, closest = d, link
        return Clearance(float(distance), closest, links)

    def _managers(
        self, thresholds: FloatArray
    ) -> tuple[coal.BroadPhaseCollisionManager, coal.BroadPhaseCollisionManager, NDArray[np.intp]]:
        """The link objects in two AABB trees: counted links and excepted contact tips.

        Built once per set of contact tips (the trees hold the same link objects, posed by
        :meth:`_pose_links`; ``update`` refits them). Also the counted geometries, in order.
        """
        tips = thresholds < 0.0
        key = tips.tobytes()
        if key not in self._link_trees:
            trees = coal.DynamicAABBTreeCollisionManager(), coal.DynamicAABBTreeCollisionManager()
            for g, tip in enumerate(tips.tolist()):
                self._link_objects[g].computeAABB()
                trees[tip].registerObject(self._link_objects[g])
            for tree in trees:
                tree.setup()
            self._link_trees[key] = (*trees, np.flatnonzero(~tips))
        return self._link_trees[key]

    def _place_finger(
        self, q: NDArray[np.float64], finger: _FreeFinger, margin_m: float, T: FloatArray
    ) -> tuple[NDArray[np.float64], float]:
        current = self.hand.finger_part(q)[finger.coordinates]
        grid = np.vstack([current, finger.grid])
        order = np.argsort(np.linalg.norm(grid - current, axis=1), kind="stable")
        candidates = []
        for values in grid[order]:
            candidate = q.copy()
            self.hand.finger_part(candidate)[finger.coordinates] = values
            # A candidate fails at its first pair closer than the margin: cheap rejections.
            distance = self._finger_distance(candidate, finger, T, margin_m, True)
            if distance >= margin_m:
                return candidate, distance
            candidates.append(candidate)
        exact = [self._finger_distance(c, finger, T, margin_m) for c in candidates]
        best = int(np.argmax(exact))
        return candidates[best], exact[best]

    def _finger_distance(
        self,
        q: NDArray[np.float64],
        finger: _FreeFinger,
        T: FloatArray,
        limit_m: float,
        fail_fast: bool = False,
    ) -> float:
        """Smallest signed distance [m] of a finger's links to the object and to other links.

        Exact below ``limit_m``; at or above it, some value at least ``limit_m`` (the pairs whose
        bounding spheres are that far apart are skipped). With ``fail_fast``, the first distance
        found below ``limit_m`` is returned, not the smallest.
        """
        stop = limit_m if fail_fast else -math.inf
        limits = np.full(len(self._links), limit_m)
        self._place(q, T)
        distance = math.inf
        for g, bounds, _ in self._near_links(T, limits, finger.geometries):
            distance = min(distance, self._link_nearest(T, g, bounds, limit_m, stop)[0])
            if distance < stop:
                return distance
        shapes, result = self._geometries, self._result
        centres = self._ball_centres()
        a, b = finger.pairs.T
        bounds = np.linalg.norm(centres[a] - centres[b], axis=1)
        bounds -= self._link_radii[a] + self._link_radii[b]
        order = np.argsort(bounds)
        for bound, (a, b) in zip(bounds[order].tolist(), finger.pairs[order].tolist(), strict=True):
            if bound >= min(distance, limit_m):
                break
            result.clear()  # coal keeps the smaller of the result's and the new distance
            signed = coal.distance(
                shapes[a], self._at_link(a), shapes[b], self._at_link(b), self._request, result
            )
            distance = min(distance, float(signed))
            if distance < stop:
                break
        return distance

    def _free_finger(self, name: str) -> _FreeFinger:
        if name not in self._tips:
            raise InvalidTargetError(
                f"unknown free finger {name!r} for hand {self.hand.description.name}; "
                f"valid: {list(self._tips)}"
            )
        if name not in self._free:
            self._free[name] = self._build_free_finger(name)
        return self._free[name]

    def _build_free_finger(self, name: str) -> _FreeFinger:
        hand, model = self.hand, self._model
        virtual = set(hand.virtual_joint_names)
        coordinates = np.array(
            [i for i in hand.finger_coordinates[name] if hand.coordinate_names[i] not in virtual],
            dtype=np.intp,
        )
        joints = {int(model.getJointId(hand.coordinate_names[i])) for i in coordinates}
        geometries = np.array(
            [g for g, joint in enumerate(self._joints) if joints & set(model.supports[joint])],
            dtype=np.intp,
        )
        pairs = np.array(
            [
                (p.first, p.second)
                for p in self._geometry_model.collisionPairs
                if p.first in geometries or p.second in geometries
            ],
            dtype=np.intp,
        ).reshape(-1, 2)
        axes = [np.linspace(hand.lower[i], hand.upper[i], _GRID_STEPS) for i in coordinates]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(coordinates))
        return _FreeFinger(coordinates, grid, geometries, pairs)

    def thresholds(
        self, contacts: Iterable[str], margin_m: float, allowance_m: float
    ) -> NDArray[np.float64]:
        """Smallest accepted signed distance [m] per hand geometry (kept per argument set).

        ``margin_m`` for every link, ``-allowance_m`` for the tip spheres of the fingers in
        ``contacts``; read-only.

        Raises:
            InvalidTargetError: A finger in ``contacts`` is not a finger of the hand.
            InvalidSettingsError: ``margin_m`` or ``allowance_m`` is negative or not finite.
        """
        key = (frozenset(contacts), margin_m, allowance_m)
        cached = self._thresholds_cache.get(key)
        if cached is not None:
            return cached
        for name, value in (("margin_m", margin_m), ("allowance_m", allowance_m)):
            if not (math.isfinite(value) and value >= 0.0):
                raise InvalidSettingsError(f"{name} must be a finite length >= 0 m, got {value}")
        tips = set()
        for finger in key[0]:
            if finger not in self._tips:
                raise InvalidTargetError(
                    f"unknown contact finger {finger!r} for hand {self.hand.description.name}; "
                    f"valid: {list(self._tips)}"
                )
            tips.add(self._tips[finger])
        thresholds = np.array([-allowance_m if link in tips else margin_m for link in self._links])
        thresholds.setflags(write=False)
        self._thresholds_cache[key] = thresholds
        return thresholds

    def _query(
        self,
        q: NDArray[np.float64],
        contacts: Iterable[str],
        margin_m: float,
        allowance_m: float,
        T_world_object: FloatArray | None,
    ) -> tuple[NDArray[np.float64], FloatArray]:
        """A query's thresholds and object placement, with the hand and object placed at them."""
        thresholds = self.thresholds(contacts, margin_m, allowance_m)
        T = self._placement(T_world_object)
        self._place(q, T)
        return thresholds, T

    def _placement(self, T_world_object: FloatArray | None) -> FloatArray:
        """The object placement a query uses: its own, or ``T_world_object`` validated."""
        if T_world_object is None:
            return self.object.T_world_object
        return as_placement(T_world_object)

    def _place(self, q: NDArray[np.float64], T: FloatArray) -> None:
        """Place the hand geometries at ``q`` and the object at ``T`` (a validated placement).

        ``_link_R`` and ``_link_t`` (views of Pinocchio's placements) then hold the links'
        world placements; ``_object_world`` the inverse of ``T``, computed when ``T`` changes.
        """
        pin.updateGeometryPlacements(
            self._model, self._data, self._geometry_model, self._geometry_data, self.hand.check_q(q)
        )
        if self._copy_placements:
            self._link_R, self._link_t = copied_placements(self._geometry_data)
        self._link_transforms = [None] * len(self._links)
        self._posed = [False] * len(self._links)
        self._hand_placed = False
        key = T.tobytes()
        if key != self._placement_key:
            self._placement_key = key
            self._object_world = pin.SE3(T).inverse()
            self._object_at_origin = bool(np.array_equal(T, np.eye(4)))

    def _pose_links(self, geometries: Iterable[int]) -> None:
        """Place the coal objects of hand ``geometries`` in the frame of the object (at _place).

        The piece tree stays in the object frame, built once, whatever the object's placement.
        A geometry is posed once per placement, its box the tight one of its shape.
        """
        hand_tree = self._hand_tree if self._object_at_origin else None
        if hand_tree is not None and not self._hand_placed:  # the world is the object frame
            hand_tree.update(False)  # all links at once
            self._hand_placed = True
        T_object_world = self._object_world  # T^-1, from _place
        for g in geometries:
            if self._posed[g]:
                continue
            link = self._link_objects[g]
            if hand_tree is None:
                if self._object_at_origin:
                    at_link = self._at_link(g)
                else:
                    M = T_object_world * self._geometry_data.oMg[g]
                    at_link = coal.Transform3s(M.rotation, M.translation)
                link.setTransform(at_link)
            link.computeAABB()  # Pinocchio grows the boxes by its collision pairs' margins
            self._posed[g] = True

    def _near_links(
        self, T: FloatArray, thresholds: NDArray[np.float64], geometries: NDArray[np.intp] | None
    ) -> list[tuple[int, FloatArray, float]]:
        """The ``geometries`` (None: all) whose coarse bounds come below their thresholds [m].

        Every geometry left out has no piece closer than its threshold (numpy only, no coal
        call); each one returned comes with its bounds to the coarse hulls, (K,), and an upper
        bound [m] of its distance to some piece (:meth:`_coarse_bounds`).
        """
        if not self._shapes:
            return []
        cell_bounds, upper = self._coarse_bounds(T, geometries)
        chosen = self._every if geometries is None else geometries
        near = np.flatnonzero(cell_bounds.min(axis=1) < thresholds[chosen]).tolist()
        return [(int(chosen[i]), cell_bounds[i], float(upper[i])) for i in near]

    def _within_object_box(
        self, T: FloatArray, thresholds: NDArray[np.float64]
    ) -> NDArray[np.intp]:
        """The hand geometries whose bounding balls come within their thresholds of the object.

        Of the object's box, placed at ``T`` (object frame: the box holding every piece): a
        geometry left out has no piece closer than its threshold [m]. A few numpy operations
        on all links at once; in the IK's repair queries about half the links are that far,
        and each one asked of the piece tree costs about 6 us of Python calls.
        """
        centres = self._ball_centres()
        if not self._object_at_origin:
            centres = (centres - T[:3, 3]) @ T[:3, :3]
        low, high = self._object_box_m
        gaps = _gap_lengths(np.maximum(low - centres, centres - high)) - self._link_radii
        return np.flatnonzero(gaps < thresholds)

    def _coarse_bounds(
        self, T: FloatArray, geometries: NDArray[np.intp] | None
    ) -> tuple[FloatArray, FloatArray]:
        """Bounds [m] of hand geometries' signed distances to the coarse hulls and the object.

        ``geometries``: None for all. Lower bounds to each hull, (G, K): the larger of the
        link's own shape against the hull's ball and of their boxes' gap (object at ``T``).
        Upper bounds to the object, (G,): the link's distance to the nearest anchor (a point
        inside a piece; infinite for a link measured by a bound only). Numpy only.
        """
        tree = self._tree
        gaps = self._shape_gaps(geometries, self._placed_pieces(T)[2])
        K = len(tree.coarse_radii_m)
        lower = np.maximum(
            gaps[:, :K] - tree.coarse_radii_m,
            self._link_box_gaps(T, geometries, tree.coarse_boxes_m),
        )
        exact = self._exact if geometries is None else self._exact[geometries]
        return lower, np.where(exact, gaps[:, K:].min(axis=1), np.inf)

    def _every_link(self, T: FloatArray) -> dict[int, float]:
        """Signed distance [m] of every hand geometry to the object (none without pieces)."""
        if not self._shapes:
            return {}
        cell_bounds = self._coarse_bounds(T, None)[0]
        return {
            g: self._link_nearest(T, g, cell_bounds[g], math.inf)[0] for g in self._every.tolist()
        }

    def _closest_links(
        self, T: FloatArray, thresholds: NDArray[np.float64], stop_m: float = -math.inf
    ) -> dict[int, float]:
        """Signed distances [m] of the hand geometries that may hold the smallest one.

        Geometries are taken by increasing lower bound (:meth:`_coarse_bounds`) until the bound
        exceeds the smallest distance found. A contact tip with no piece deeper than its
        allowance is excepted; the others are measured against the pieces whose bounds are
        below that distance, so a far link costs no GJK call. The search ends at the first
        counted distance below ``stop_m`` (a contact tip's: below its threshold as well).
        """
        if not self._shapes:
            return {}
        cell_bounds, upper = self._coarse_bounds(T, None)
        bounds = cell_bounds.min(axis=1)
        # No counted link is farther than the nearest anchor to a link that is no contact tip.
        ceiling = float(np.where(thresholds < 0.0, np.inf, upper).min())
        measured: dict[int, float] = {}
        smallest = math.inf
        for g in np.argsort(bounds, kind="stable").tolist():
            limit = min(smallest, ceiling)
            if bounds[g] > limit:
                break
            tip = thresholds[g] < 0.0  # counts only deeper than its allowance
            if tip and not self._link_pieces(T, g, cell_bounds[g], float(thresholds[g]), 1):
                continue
            stop = min(stop_m, float(thresholds[g]))
            distance = self._link_nearest(T, g, cell_bounds[g], limit, stop, float(upper[g]))[0]
            if distance < smallest:  # exact up to the limit
                measured[g] = smallest = distance
                if distance < stop:
                    break
        return measured

    def _link_nearest(
        self,
        T: FloatArray,
        g: int,
        cell_bounds: FloatArray,
        limit_m: float,
        stop_m: float = -math.inf,
        upper_m: float = math.inf,
    ) -> tuple[float, int]:
        """The signed distance [m] of geometry ``g`` to its nearest piece, and that piece.

        Exact up to ``limit_m``; else some distance above it (infinite, piece -1, if none was
        measured). Branch and bound: pieces by increasing lower bound (for a few pieces, by
        their hulls' bounds), until the bound reaches the nearest distance found. The search
        ends at the first distance below ``stop_m``. ``upper_m`` as in :meth:`_link_pieces`.
        """
        members, distance = self._tree.members, self._gjk(T, g)
        proven = limit_m >= 0.0 and upper_m < limit_m
        if limit_m < math.inf and not proven and self._tree_says_clear(g, cell_bounds, limit_m):
            return math.inf, -1
        cells = np.flatnonzero(cell_bounds <= limit_m)
        candidates: Iterable[tuple[int, float]]
        if self._tree.sizes[cells].sum() > _FEW_PIECES:  # numpy bounds beat that many GJK calls
            pieces = np.concatenate([members[c] for c in cells.tolist()])
            pieces, bounds = self._piece_bounds(T, g, pieces, limit_m)
            candidates = zip(pieces.tolist(), bounds.tolist(), strict=True)
        else:  # each piece bounded by its hull's bound
            hull_bounds = cell_bounds.tolist()
            candidates = (
                (piece, hull_bounds[cell])
                for cell in cells[np.argsort(cell_bounds[cells])].tolist()
                for piece in members[cell].tolist()
            )
        best, nearest = math.inf, -1
        for piece, bound in candidates:
            if bound >= best:  # no piece left can be nearer
                break
            d = distance(piece)
            if d < best:
                best, nearest = d, piece
                if d < stop_m:
                    break
        return best, nearest

    def _link_pieces(
        self,
        T: FloatArray,
        g: int,
        cell_bounds: FloatArray,
        threshold_m: float,
        per_link: int | None,
        pairs: list[_Pair] | None = None,
        upper_m: float = math.inf,
    ) -> list[int]:
        """The pieces closer than ``threshold_m`` [m] to geometry ``g``.

        The first ``per_link`` (None: all) of them by increasing lower bound: the ones a search
        in that order finds first. ``pairs``: each one's witnesses are appended to it, read
        from the GJK/EPA call that found it (no second call). ``upper_m``: an upper bound of
        the distance to some piece (through a point inside it); below a threshold >= 0 it
        proves a piece closer, and the piece tree is not asked. (Not below 0: a link deep
        around a point of a thin piece may still penetrate that piece only a little.)
        """
        proven = threshold_m >= 0.0 and upper_m < threshold_m
        if not proven and self._tree_says_clear(g, cell_bounds, threshold_m):
            return []
        cells = np.flatnonzero(cell_bounds < threshold_m).tolist()
        if not cells:
            return []
        pieces = np.concatenate([self._tree.members[c] for c in cells])
        distance = self._gjk(T, g)
        if len(pieces) <= _FEW_PIECES:  # measure them all, then order the few found
            found = [p for p in pieces.tolist() if distance(p) < threshold_m]
            if len(found) <= 1 and pairs is None:
                return found
            # In the order of a search by bound: the repair's rows come in the same order (no
            # order to find for one piece: its witnesses come from measuring it again below).
            pieces = np.array(found, dtype=np.intp)
            if len(found) > 1:
                pieces = self._piece_bounds(T, g, pieces, math.inf)[0]
        else:
            pieces, bounds = self._piece_bounds(T, g, pieces, threshold_m)
            pieces = pieces[bounds < threshold_m]
        out: list[int] = []
        for piece in pieces.tolist():
            d = distance(piece)
            if d < threshold_m:
                out.append(piece)
                if pairs is not None:
                    pairs.append(self._witnesses(g, d))
                if per_link is not None and len(out) >= per_link:
                    break
        return out

    def _first_pair(self, T: FloatArray, g: int, threshold_m: float) -> list[_Pair]:
        """Geometry ``g``'s first pair closer than ``threshold_m`` [m] in the piece tree (or none).

        The link posed (:meth:`_pose_links`). The tree answers in the object frame; the pair is
        returned in the world (object at ``T``).
        """
        found = self._tree.first_pair(self._link_objects[g], threshold_m)
        if found is None:
            return []
        distance_m, on_piece, on_link, normal = found
        if not self._object_at_origin:
            R, t = T[:3, :3], T[:3, 3]
            on_piece, on_link, normal = R @ on_piece + t, R @ on_link + t, R @ normal
        return [_Pair(g, distance_m, on_piece, on_link, normal)]

    def _tree_says_clear(self, g: int, cell_bounds: FloatArray, limit_m: float) -> bool:
        """True if the piece tree finds no piece closer than ``limit_m`` [m] to geometry ``g``.

        Asked only when more than a few pieces lie in the hulls bounded below ``limit_m``: one
        C++ query then costs less than their GJK calls. False when not asked.
        """
        if len(self._shapes) <= _FEW_PIECES:
            return False
        count = int(self._tree.sizes[cell_bounds < limit_m].sum())
        if count <= _FEW_PIECES:
            return False
        self._pose_links((g,))
        return self._tree.clear_of(self._link_objects[g], limit_m)

    def _gjk(self, T: FloatArray, g: int) -> Callable[[int], float]:
        """Signed distance [m] of geometry ``g`` (placed) to a piece: coal's GJK/EPA, no more."""
        geometry, at_link = self._geometries[g], self._at_link(g)
        shapes, transforms = self._shapes, self._placed_pieces(T)[1]
        request, result = self._request, self._result

        def distance(piece: int) -> float:
            at_piece = transforms[piece]
            if at_piece is None:
                at_piece = transforms[piece] = shapes[piece].transform(T)
            result.clear()  # coal keeps the smaller of the result's and the new distance
            return float(
                coal.distance(shapes[piece].geometry, at_piece, geometry, at_link, request, result)
            )

        return distance

    def _at_link(self, g: int) -> coal.Transform3s:
        """Geometry ``g``'s world placement as a coal transform (built once per placement)."""
        at_link = self._link_transforms[g]
        if at_link is None:  # from the placement views: no Pinocchio SE3 built (1 instead of 2 us)
            at_link = self._link_transforms[g] = coal.Transform3s(self._link_R[g], self._link_t[g])
        return at_link

    def _piece_bounds(
        self, T: FloatArray, g: int, pieces: NDArray[np.intp], limit_m: float
    ) -> tuple[NDArray[np.intp], FloatArray]:
        """``pieces`` bounded at most ``limit_m`` [m] from geometry ``g``, and their bounds.

        By increasing bound: the larger of the link's shape (a cylinder exactly) against the
        piece's ball and of their boxes' gap (the link posed here).
        """
        self._pose_links((g,))
        centres = self._placed_pieces(T)[0][pieces]
        local = (centres - self._link_t[g]) @ self._link_R[g]  # R^T (p - t)
        if self._cylinder_m[g, 0, 2] == np.inf:  # measured as (radial, axial)
            radius, half_length = self._cylinder_m[g, 0, :2]
            radial = np.hypot(local[:, 0], local[:, 1]) - radius
            gaps = _box_distances(radial, np.abs(local[:, 2]) - half_length)
        else:
            local -= self._offset_m[g, 0]
            half = self._half_m[g, 0]
            x, y, z = (np.abs(local[:, j]) - half[j] for j in range(3))
            gaps = _box_distances(x, y, z) - self._rounding_m[g, 0]
        bounds = gaps - self._piece_radii[pieces]
        bounds = np.maximum(bounds, self._box_gaps(g, pieces))
        kept = bounds <= limit_m
        pieces, bounds = pieces[kept], bounds[kept]
        order = np.argsort(bounds)
        return pieces[order], bounds[order]

    def _ball_centres(self) -> FloatArray:
        """Centres (G, 3) of the links' bounding balls in the world, at the last _place."""
        return np.einsum("gij,gj->gi", self._link_R, self._link_centres) + self._link_t

    def _shape_gaps(self, geometries: NDArray[np.intp] | None, points_m: FloatArray) -> FloatArray:
        """Signed distances [m] from hand geometries, placed, to world points: (G, N).

        ``geometries``: None for all. Exact for a box or a sphere (negative inside); for a
        cylinder, the distance to its bounding box, for another shape to its bounding ball
        (:meth:`_describe_shapes`). A piece within a ball of radius r about a point is then at
        least this minus r from the link, inside as well (its penetration is at most the
        ball's): a much tighter bound than the link's own ball when the pieces are small.
        """
        if geometries is None:
            R, t, half, rounding = self._link_R, self._link_t, self._half_m, self._rounding_m
        else:
            R, t = self._link_R[geometries], self._link_t[geometries]
            half, rounding = self._half_m[geometries], self._rounding_m[geometries]
        # R^T (p - t) per geometry as one (N, 3) x (3, 3G) product, then coordinate by
        # coordinate on (N, G) arrays: numpy reduces a length-3 axis several times slower.
        shift = (t[:, :, None] * R).sum(axis=1)  # t^T R, (G, 3)
        if self._offset:
            shift += (self._offset_m if geometries is None else self._offset_m[geometries])[:, 0]
        local = (points_m @ R.transpose(1, 0, 2).reshape(3, -1)).reshape(len(points_m), -1, 3)
        x, y, z = (np.abs(local[:, :, j] - shift[:, j]) - half[:, 0, j] for j in range(3))
        return (_box_distances(x, y, z) - rounding[:, 0]).T

    def _link_box_gaps(
        self, T: FloatArray, geometries: NDArray[np.intp] | None, boxes_m: FloatArray
    ) -> FloatArray:
        """Gaps [m] between hand geometries' boxes and ``boxes_m`` (K, 2, 3): (G, K).

        ``geometries``: None for all. Boxes in the object frame at placement ``T``, the links'
        from their local boxes and their placements at the last :meth:`_place` (no coal call).
        Disjoint boxes bound the distance from below; overlapping ones bound nothing (-inf).
        """
        every = slice(None) if geometries is None else geometries
        R_object = T[:3, :3]
        R = np.matmul(R_object.T, self._link_R[every])  # link frame -> object frame
        centres = (self._link_t[every] - T[:3, 3]) @ R_object
        if not self._centred:
            centres += np.einsum("gij,gj->gi", R, self._link_centres[every])
        halves = np.einsum("gij,gj->gi", np.abs(R), self._link_halves[every])[:, None]
        low, high = centres[:, None] - halves, centres[:, None] + halves
        gaps = _gap_lengths(np.maximum(low - boxes_m[:, 1], boxes_m[:, 0] - high))
        gaps[gaps == 0.0] = -np.inf
        return gaps

    def _box_gaps(self, g: int, pieces: NDArray[np.intp]) -> FloatArray:
        """Per piece in ``pieces``, the gap [m] between its box and the posed link's box.

        Both boxes in the object frame. Disjoint boxes bound the distance from below;
        overlapping ones bound nothing (-inf).
        """
        box = self._link_objects[g].getAABB()
        low, high = self._piece_lows_m[pieces], self._piece_highs_m[pieces]
        gaps = _gap_lengths(np.maximum(np.asarray(box.min_) - high, low - np.asarray(box.max_)))
        return np.where(gaps > 0.0, gaps, -np.inf)

    def _placed_pieces(
        self, T: FloatArray
    ) -> tuple[FloatArray, list[coal.Transform3s | None], FloatArray]:
        """The pieces' centres (N, 3), coal transforms (built on first use), hulls' points (2K, 3).

        The hulls' points: their balls' centres, then their anchors (:meth:`_coarse_bounds`).
        All in the world, kept while the object stays at placement ``T``: every query of a
        solve reuses them.
        """
        key = T.tobytes()
        if self._transforms_key != key:
            self._transforms_key = key
            self._centres_world = self._piece_centres @ T[:3, :3].T + T[:3, 3]
            self._transforms: list[coal.Transform3s | None] = [None] * len(self._shapes)
            self._coarse_world = self._coarse_points @ T[:3, :3].T + T[:3, 3]
        return self._centres_world, self._transforms, self._coarse_world

    def _witnesses(self, g: int, distance_m: float) -> _Pair:
        """Geometry ``g``'s pair at ``distance_m`` [m], witnesses from the last GJK/EPA call."""
        result = self._result
        normal = np.array(result.normal, dtype=np.float64)
        length = math.sqrt(float(normal.dot(normal)))
        return _Pair(
            g,
            distance_m,
            np.array(result.getNearestPoint1(), dtype=np.float64),
            np.array(result.getNearestPoint2(), dtype=np.float64),
            normal / max(length, 1e-12),
        )


_ONES = np.ones(3)


def _gap_lengths(gaps_m: FloatArray) -> FloatArray:
    """Lengths [m] of the positive parts of per-axis gaps (..., 3) between boxes: (...).

    A product with ones sums the last axis: numpy's reductions over a length-3 axis cost
    several times more (they dominated the bounds of a query).
    """
    positive = np.maximum(gaps_m, 0.0)
    return np.sqrt(np.square(positive) @ _ONES)


def _box_distances(*excess_m: FloatArray) -> FloatArray:
    """Signed distances [m] to a box from per-axis excesses ``|p_i| - h_i`` (same shapes).

    Outside, the length of the positive excesses; inside, the largest excess (negative).
    Elementwise on whole arrays, one per axis: no reduction over a short axis.
    """
    outside = np.square(np.maximum(excess_m[0], 0.0))
    largest = excess_m[0]
    for excess in excess_m[1:]:
        outside += np.square(np.maximum(excess, 0.0))
        largest = np.maximum(largest, excess)
    return np.sqrt(outside) + np.minimum(largest, 0.0)
