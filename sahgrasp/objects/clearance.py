"""Hand-object clearance: signed distances between a hand's collision shapes and an object.

The object is a union of convex coal pieces (:mod:`sahgrasp.objects.collision`); every hand link
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
revolved band), so no query tries them all: a pair's distance is bounded from below by the
link's own shape (sphere, box, cylinder) against a ball about the piece, and by their boxes; a
coal broad phase (:class:`~sahgrasp.objects.collision.PieceTree`, in the object frame, built
once) answers in C++ whether a link comes closer than a margin; only the pairs those leave are
measured with GJK/EPA one by one. The results are those of measuring every pair.

The object side of a :class:`~sahgrasp.collision.Penetration` is joint 0 (the universe, which does
not move), so the IK's separation rows ``n^T (J_b(p_b) - J_a(p_a))`` hold with ``J_a = 0``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from sahgrasp.collision import Penetration
from sahgrasp.errors import InvalidSettingsError, InvalidTargetError
from sahgrasp.hand import Hand
from sahgrasp.objects.body import GraspObject
from sahgrasp.objects.collision import PieceTree
from sahgrasp.objects.frames import FloatArray, as_placement

__all__ = [
    "CONTACT_ALLOWANCE_M",
    "FREE_FINGER_MARGIN_M",
    "Clearance",
    "FreeFingerPlacement",
    "HandObjectClearance",
]

CONTACT_ALLOWANCE_M = 1.5e-3
"""Default penetration allowed to a contact fingertip sphere: the IK's ``d_min`` [m]."""

FREE_FINGER_MARGIN_M = 2e-3
"""Default clearance [m] a free finger keeps from the object and from the other links."""

_GRID_STEPS = 6
"""Values per joint of a free finger tried by :meth:`HandObjectClearance.place_free_fingers`."""


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

    coordinates: NDArray[np.intp]  # indices in Hand.finger_part(q)
    grid: NDArray[np.float64]  # candidate values of those coordinates, (N, len(coordinates))
    geometries: tuple[int, ...]
    pairs: NDArray[np.intp]  # hand geometry pairs (P, 2) the hand checks for self-collision


@dataclass(frozen=True)
class _Pair:
    """One (hand geometry, object piece) signed distance with coal's witnesses (world frame)."""

    geometry: int
    distance_m: float
    point_object: FloatArray
    point_hand: FloatArray
    normal: FloatArray  # from the object towards the hand link


class HandObjectClearance:
    """Signed distances between a hand's collision geometry and an object's convex pieces.

    Independent of any solver: it owns its Pinocchio data and coal geometry data, so queries
    share no mutable state with the hand or with other queries.

    Args:
        hand: The hand (its model and coal collision geometry are used, not modified).
        obj: The object; its pieces are placed at ``obj.T_world_object`` unless a query gives
            another placement. None: no object (every link is clear of it), e.g. to place free
            fingers clear of the other links only.
    """

    def __init__(self, hand: Hand, obj: GraspObject | None) -> None:
        self.hand = hand
        self.object = GraspObject("nothing", (), (0.0, 0.0, 0.0, 0.0)) if obj is None else obj
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
        self._link_R = np.zeros((len(geometries), 3, 3))  # placements at the last _place
        self._link_t = np.zeros((len(geometries), 3))
        self._link_objects = [
            coal.CollisionObject(g.geometry, coal.Transform3s()) for g in geometries
        ]
        self._describe_shapes([g.geometry for g in geometries])
        self._tree = PieceTree(self._shapes)
        self._tips = {f.name: f.tip_link for f in hand.description.fingers}
        self._request = coal.DistanceRequest()
        self._request.enable_signed_distance = True
        self._free: dict[str, _FreeFinger] = {}
        self._transforms_key = b""

    def _describe_shapes(self, shapes: Sequence[coal.ShapeBase]) -> None:
        """Per hand geometry, the parameters :meth:`_shape_gaps` measures it with."""
        self._half_m = np.zeros((len(shapes), 3))
        self._rounding_m = np.zeros(len(shapes))
        self._cylinder = np.array([isinstance(s, coal.Cylinder) for s in shapes])
        self._other = np.zeros(len(shapes), dtype=bool)
        for g, shape in enumerate(shapes):
            if isinstance(shape, coal.Box):
                self._half_m[g] = shape.halfSide
            elif isinstance(shape, coal.Cylinder):  # measured as (radial, axial, none)
                self._half_m[g] = shape.radius, shape.halfLength, np.inf
            elif isinstance(shape, coal.Sphere):
                self._rounding_m[g] = shape.radius
            else:
                self._other[g] = True

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
    ) -> list[Penetration]:
        """Every (link shape, object piece) pair closer than required at ``q``.

        A link shape must stay ``margin_m`` [m] away from the object. The fingertip sphere of a
        finger in ``contacts`` is exempt from the margin and may penetrate up to ``allowance_m``
        [m]: it is reported only below ``-allowance_m``. ``joint_a`` is 0 (the object, fixed),
        ``point_a`` on the object, ``normal`` from the object towards the link, and ``depth_m``
        how far the link must move along ``normal`` to reach its required distance.

        ``per_link``: at most this many pairs per link shape, the first ones found closer than
        required, pieces taken by increasing lower bound of their distance (None: all). The
        IK's repair asks for a few: a link deep in a finely cut object overlaps hundreds of
        pieces, and a row per pair costs a GJK call and a Jacobian each, for normals that
        mostly agree (:data:`sahgrasp.ik.obstacle.REPAIR_PAIRS_PER_LINK`).

        Raises:
            InvalidTargetError: A finger in ``contacts`` is not a finger of the hand.
            InvalidSettingsError: ``margin_m`` or ``allowance_m`` is negative or not finite.
        """
        thresholds = self._thresholds(contacts, margin_m, allowance_m)
        T = self._place(q, T_world_object)
        near = self._screen(T, thresholds, range(len(self._links)))
        pairs = self._pairs(T, thresholds, False, near, per_link=per_link)
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
            if p.distance_m < thresholds[p.geometry]
        ]

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
        thresholds = self._thresholds(contacts, 0.0, allowance_m)
        T = self._place(q, T_world_object)
        if all_links:
            every = range(len(self._links))
            self._pose_links(T, every)
            pairs = self._pairs(T, np.full(len(every), np.inf), True, every)
            measured = {p.geometry: p.distance_m for p in pairs}
        else:
            measured = self._closest_links(T, thresholds)
        links: dict[str, float] = {}
        distance, closest = math.inf, ""
        for g in sorted(measured):  # in geometry order: a tie goes to the first link
            link, d = self._links[g], measured[g]
            links[link] = min(links.get(link, math.inf), d)
            excepted = thresholds[g] < 0.0 and d >= thresholds[g]
            if not excepted and d < distance:
                distance, closest = d, link
        return Clearance(float(distance), closest, links)

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
        self._thresholds((), margin_m, 0.0)
        q = self.hand.check_q(q).copy()
        distance = math.inf
        for finger in fingers:
            q, finger_distance = self._place_finger(q, self._free_finger(finger), margin_m,
                                                    T_world_object)  # fmt: skip
            distance = min(distance, finger_distance)
        return FreeFingerPlacement(q, distance, distance >= margin_m)

    # ----- internals ------------------------------------------------------------------------
    def _place_finger(
        self,
        q: NDArray[np.float64],
        finger: _FreeFinger,
        margin_m: float,
        T_world_object: FloatArray | None,
    ) -> tuple[NDArray[np.float64], float]:
        current = self.hand.finger_part(q)[finger.coordinates]
        grid = np.vstack([current, finger.grid])
        order = np.argsort(np.linalg.norm(grid - current, axis=1), kind="stable")
        candidates = []
        for values in grid[order]:
            candidate = q.copy()
            self.hand.finger_part(candidate)[finger.coordinates] = values
            # A candidate fails at its first pair closer than the margin: cheap rejections.
            distance = self._finger_distance(candidate, finger, T_world_object, margin_m, True)
            if distance >= margin_m:
                return candidate, distance
            candidates.append(candidate)
        exact = [self._finger_distance(c, finger, T_world_object, margin_m) for c in candidates]
        best = int(np.argmax(exact))
        return candidates[best], exact[best]

    def _finger_distance(
        self,
        q: NDArray[np.float64],
        finger: _FreeFinger,
        T_world_object: FloatArray | None,
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
        T = self._place(q, T_world_object)
        near = self._screen(T, limits, finger.geometries)
        pairs = self._pairs(T, limits, True, near, stop)
        distance = min((p.distance_m for p in pairs), default=math.inf)
        if distance < stop:
            return distance
        placements = self._geometry_data.oMg
        objects = self._geometry_model.geometryObjects
        centres = np.array([M.act(c) for M, c in zip(placements, self._link_centres, strict=True)])
        a, b = finger.pairs.T
        bounds = np.linalg.norm(centres[a] - centres[b], axis=1)
        bounds -= self._link_radii[a] + self._link_radii[b]
        for k in np.argsort(bounds):
            if bounds[k] >= min(distance, limit_m):
                break
            a, b = (int(i) for i in finger.pairs[k])
            Ma, Mb = placements[a], placements[b]
            signed = coal.distance(
                objects[a].geometry, coal.Transform3s(Ma.rotation, Ma.translation),
                objects[b].geometry, coal.Transform3s(Mb.rotation, Mb.translation),
                self._request, coal.DistanceResult(),
            )  # fmt: skip
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
        geometries = tuple(
            g for g, joint in enumerate(self._joints) if joints & set(model.supports[joint])
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

    def _thresholds(
        self, contacts: Iterable[str], margin_m: float, allowance_m: float
    ) -> NDArray[np.float64]:
        """Smallest accepted signed distance [m] per hand geometry."""
        for name, value in (("margin_m", margin_m), ("allowance_m", allowance_m)):
            if not (math.isfinite(value) and value >= 0.0):
                raise InvalidSettingsError(f"{name} must be a finite length >= 0 m, got {value}")
        tips = set()
        for finger in contacts:
            if finger not in self._tips:
                raise InvalidTargetError(
                    f"unknown contact finger {finger!r} for hand {self.hand.description.name}; "
                    f"valid: {list(self._tips)}"
                )
            tips.add(self._tips[finger])
        return np.array([-allowance_m if link in tips else margin_m for link in self._links])

    def _place(self, q: NDArray[np.float64], T_world_object: FloatArray | None) -> FloatArray:
        """Place the hand geometries at ``q``; return the object placement to use."""
        pin.updateGeometryPlacements(
            self._model, self._data, self._geometry_model, self._geometry_data, self.hand.check_q(q)
        )
        H = np.array([M.homogeneous for M in self._geometry_data.oMg])  # once per query
        self._link_R, self._link_t = H[:, :3, :3], H[:, :3, 3]
        if T_world_object is None:
            return self.object.T_world_object
        return as_placement(T_world_object)

    def _pose_links(self, T: FloatArray, geometries: Iterable[int]) -> None:
        """Place the coal objects of hand ``geometries`` in the frame of the object at ``T``.

        The piece tree stays in the object frame, built once, whatever the object's placement.
        """
        T_object_world = pin.SE3(T).inverse()
        for g in geometries:
            M = T_object_world * self._geometry_data.oMg[g]
            link = self._link_objects[g]
            link.setTransform(coal.Transform3s(M.rotation, M.translation))
            link.computeAABB()

    def _screen(
        self, T: FloatArray, thresholds: NDArray[np.float64], geometries: Iterable[int]
    ) -> list[int]:
        """The ``geometries`` that may have a piece closer than their threshold [m].

        Every geometry left out has none (exact, from the piece tree), so only the ones returned
        need the pair-by-pair search of :meth:`_pairs`.
        """
        chosen = list(geometries)
        self._pose_links(T, chosen)
        tree, links = self._tree, self._link_objects
        return [g for g in chosen if not tree.clear_of(links[g], float(thresholds[g]))]

    def _coarse_bounds(self, T: FloatArray) -> FloatArray:
        """Lower bounds [m] of each hand geometry's signed distance to each coarse hull: (G, K).

        The larger of two bounds: the link's own shape against the hull's ball, and their boxes'
        gap (object at ``T``). Numpy only.
        """
        tree = self._tree
        coarse = tree.coarse_centres_m @ T[:3, :3].T + T[:3, 3]  # world
        balls = self._shape_gaps(np.arange(len(self._links)), coarse) - tree.coarse_radii_m
        return np.maximum(balls, self._link_box_gaps(T, tree.coarse_boxes_m))

    def _closest_links(self, T: FloatArray, thresholds: NDArray[np.float64]) -> dict[int, float]:
        """Signed distances [m] of the hand geometries that may hold the smallest one.

        Geometries are taken by increasing lower bound (:meth:`_coarse_bounds`) until the bound
        exceeds the smallest distance found. A contact tip the
        piece tree finds within its allowance is excepted; the others are measured against the
        pieces whose bounds are below that distance, so a far link costs no GJK call. Only the
        geometries taken are posed in the object frame.
        """
        if not self._shapes:
            return {}
        tree = self._tree
        every = np.arange(len(self._links))
        cell_bounds = self._coarse_bounds(T)
        bounds = cell_bounds.min(axis=1)
        measured: dict[int, float] = {}
        smallest = math.inf
        for g in (int(i) for i in np.argsort(bounds, kind="stable")):
            if bounds[g] > smallest:
                break
            self._pose_links(T, (g,))
            tip = thresholds[g] < 0.0  # counts only deeper than its allowance
            limit = float(thresholds[g]) if tip else smallest
            if limit < math.inf and tree.clear_of(self._link_objects[g], limit):
                continue  # one C++ query instead of bounding every piece in numpy
            pieces = self._candidates(T, g, cell_bounds[g], smallest)
            for pair in self._pairs(T, np.full(len(every), smallest), True, [g], pieces=pieces):
                if pair.distance_m < smallest:  # exact below the limit
                    measured[g] = smallest = pair.distance_m
        return measured

    def _candidates(
        self, T: FloatArray, g: int, cell_bounds: FloatArray, limit_m: float
    ) -> NDArray[np.intp]:
        """The pieces that may be the nearest to geometry ``g``, by the coarse hulls' bounds.

        The pieces of the hull with the smallest bound give an upper bound of the distance
        (a piece's centre lies inside it); only hulls bounded below that, and ``limit_m``, can
        hold the nearest piece.
        """
        members = self._tree.members
        if not self._other[g]:
            first = members[int(np.argmin(cell_bounds))]
            centres, _ = self._placed_pieces(T)
            limit_m = min(limit_m, float(self._shape_gaps(np.array([g]), centres[first]).min()))
        cells = np.flatnonzero(cell_bounds <= limit_m)
        return np.concatenate([members[c] for c in cells]) if len(cells) else cells

    def _pairs(
        self,
        T: FloatArray,
        thresholds: NDArray[np.float64],
        nearest_only: bool,
        geometries: Sequence[int],
        stop_below_m: float = -math.inf,
        pieces: NDArray[np.intp] | None = None,
        per_link: int | None = None,
    ) -> list[_Pair]:
        """Signed distances of hand geometries to the object pieces that may matter.

        The hand is placed (:meth:`_place`), its ``geometries`` posed (:meth:`_pose_links`) and
        the object at ``T``. ``nearest_only``: one pair per geometry, its nearest piece if closer
        than the geometry's threshold (else some pair at least that far, or none). Otherwise
        every pair whose bounds come closer than the threshold, or the first ``per_link`` of
        them found closer than it. The search ends at the first pair closer than
        ``stop_below_m``. ``pieces``: only these pieces (default: all).
        """
        placements = self._geometry_data.oMg
        piece_centres, transforms = self._placed_pieces(T)
        out: list[_Pair] = []
        for g in geometries:
            M = placements[g]
            geometry = self._geometry_model.geometryObjects[g].geometry
            chosen = self._all_pieces if pieces is None else pieces
            to_centres = self._shape_gaps(np.array([g]), piece_centres[chosen])[0]
            bounds = to_centres - self._piece_radii[chosen]
            limit = thresholds[g]
            if nearest_only and not self._other[g] and len(chosen):
                # A piece's centre lies inside it, so the link is no farther from the object
                # than from the nearest centre: no piece bounded above that can be the nearest.
                limit = min(limit, float(to_centres.min()))
            kept = bounds <= limit  # no other piece can be kept
            near, bounds = chosen[kept], bounds[kept]
            bounds = np.maximum(bounds, self._box_gaps(g, near))
            at_link = coal.Transform3s(M.rotation, M.translation)
            best: _Pair | None = None
            found = 0
            order = np.argsort(bounds)
            for i, bound in zip(near[order].tolist(), bounds[order].tolist(), strict=True):
                limit = thresholds[g] if best is None else min(best.distance_m, thresholds[g])
                if bound >= limit:
                    break
                if transforms[i] is None:
                    transforms[i] = self._shapes[i].transform(T)
                pair = self._distance(g, geometry, at_link, i, transforms[i])
                if pair.distance_m < stop_below_m:
                    return [*out, pair]
                if nearest_only:
                    best = pair if best is None or pair.distance_m < best.distance_m else best
                else:
                    out.append(pair)
                    found += pair.distance_m < thresholds[g]
                    if per_link is not None and found >= per_link:
                        break
            if best is not None:
                out.append(best)
        return out

    def _shape_gaps(self, geometries: NDArray[np.intp], points_m: FloatArray) -> FloatArray:
        """Signed distances [m] from hand geometries, placed, to world points: (G, N).

        Exact for a sphere, box or cylinder (negative inside); for another shape, the distance
        to its bounding ball. A piece within a ball of radius r about a point is then at least
        this minus r from the link, inside as well (its penetration is at most the ball's): a
        much tighter bound than the link's own ball when the pieces are small.
        """
        R, t = self._link_R[geometries], self._link_t[geometries]
        local = np.matmul(points_m[None] - t[:, None], R)  # R^T (p - t), per geometry
        coords = np.abs(local)  # box (a sphere is a box of no size, rounded)
        cylinder = self._cylinder[geometries]
        if cylinder.any():  # axis z: (radial, axial); the third half extent is infinite
            axial = local[cylinder]
            coords[cylinder, :, 0] = np.hypot(axial[..., 0], axial[..., 1])
            coords[cylinder, :, 1] = coords[cylinder, :, 2]
        excess = coords - self._half_m[geometries][:, None]
        outside = np.maximum(excess, 0.0)
        gaps = np.sqrt(np.einsum("gni,gni->gn", outside, outside))
        gaps += np.minimum(excess.max(axis=2), 0.0) - self._rounding_m[geometries][:, None]
        other = self._other[geometries]
        if other.any():
            ball = local[other] - self._link_centres[geometries[other]][:, None]
            gaps[other] = (
                np.linalg.norm(ball, axis=2) - self._link_radii[geometries[other]][:, None]
            )
        return gaps

    def _link_box_gaps(self, T: FloatArray, boxes_m: FloatArray) -> FloatArray:
        """Gaps [m] between every hand geometry's box and ``boxes_m`` (K, 2, 3): (G, K).

        Boxes in the object frame at placement ``T``, the links' from their local boxes and
        their placements at the last :meth:`_place` (no coal call). Disjoint boxes bound the
        distance from below; overlapping ones bound nothing (-inf).
        """
        R_object = T[:3, :3]
        R = np.matmul(R_object.T, self._link_R)  # link frame -> object frame
        centres = np.einsum("gij,gj->gi", R, self._link_centres)
        centres += (self._link_t - T[:3, 3]) @ R_object
        halves = np.einsum("gij,gj->gi", np.abs(R), self._link_halves)
        low, high = (centres - halves)[:, None], (centres + halves)[:, None]
        gaps = np.maximum(low - boxes_m[None, :, 1], boxes_m[None, :, 0] - high)
        gaps = np.linalg.norm(np.maximum(gaps, 0.0), axis=2)
        return np.where(gaps > 0.0, gaps, -np.inf)

    def _box_gaps(self, g: int, pieces: NDArray[np.intp]) -> FloatArray:
        """Per piece in ``pieces``, the gap [m] between its box and the posed link's box.

        Both boxes in the object frame. Disjoint boxes bound the distance from below;
        overlapping ones bound nothing (-inf).
        """
        box = self._link_objects[g].getAABB()
        boxes = self._tree.boxes_m[pieces]
        gaps = np.maximum(np.asarray(box.min_) - boxes[:, 1], boxes[:, 0] - np.asarray(box.max_))
        gaps = np.linalg.norm(np.maximum(gaps, 0.0), axis=1)
        return np.where(gaps > 0.0, gaps, -np.inf)

    def _placed_pieces(self, T: FloatArray) -> tuple[FloatArray, list[coal.Transform3s | None]]:
        """The pieces' centres (N, 3) in the world and coal transforms (built on first use).

        Kept while the object stays at placement ``T``: every query of a solve reuses them.
        """
        key = T.tobytes()
        if self._transforms_key != key:
            self._transforms_key = key
            self._centres_world = self._piece_centres @ T[:3, :3].T + T[:3, 3]
            self._transforms: list[coal.Transform3s | None] = [None] * len(self._shapes)
        return self._centres_world, self._transforms

    def _distance(
        self,
        g: int,
        geometry: coal.ShapeBase,
        at_link: coal.Transform3s,
        piece: int,
        at_piece: coal.Transform3s,
    ) -> _Pair:
        result = coal.DistanceResult()
        distance = coal.distance(
            self._shapes[piece].geometry, at_piece, geometry, at_link, self._request, result
        )
        normal = np.asarray(result.normal, dtype=np.float64)
        return _Pair(
            g,
            float(distance),
            np.asarray(result.getNearestPoint1(), dtype=np.float64),
            np.asarray(result.getNearestPoint2(), dtype=np.float64),
            normal / max(float(np.linalg.norm(normal)), 1e-12),
        )
