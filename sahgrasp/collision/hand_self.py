"""Self-collision of a hand: coal geometry of the URDF collision shapes and the pairs to check.

Adjacent bodies touch by design (a phalanx and its parent), so pairs whose bodies hang from the
same joint or from a parent/child pair of joints are not checked; a hand description may exclude
more pairs by link name (e.g. the SAH finger bases with the palm). Every other pair is checked.

Queries are stateless: Pinocchio's ``GeometryData`` enables coal's GJK warm start on every
request, which starts each query of a pair from the guess the previous query of that pair left
behind. The witnesses and normals then depend (in the last bits, which the IK's collision repair
amplifies) on what was queried before, so the same problem could give different joints on a
fresh hand and on a hand that had solved others. :func:`stateless_requests` turns the warm start
off once per ``GeometryData``; for the primitive shapes of the hand URDFs (boxes, cylinders,
spheres) nothing else is carried between queries but one process-wide rule of coal's, which
importing this module settles (:func:`settle_box_support`).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

__all__ = [
    "CollisionPair",
    "Penetration",
    "SelfCollision",
    "copied_placements",
    "geometry_placement_views",
    "settle_box_support",
    "stateless_requests",
]


@dataclass(frozen=True)
class CollisionPair:
    """Two links whose collision shapes are checked against each other."""

    link_a: str
    link_b: str


@dataclass(frozen=True)
class Penetration:
    """Two bodies closer than a margin: witness points and the direction that separates them.

    Attributes:
        joint_a: Pinocchio joint carrying the first body.
        joint_b: Pinocchio joint carrying the second body.
        point_a: Witness point on the first body, world frame [m].
        point_b: Witness point on the second body, world frame [m].
        normal: Unit vector from the first body towards the second (moving b along it separates).
        depth_m: How far b must move along ``normal`` to reach the margin [m].
    """

    joint_a: int
    joint_b: int
    point_a: NDArray[np.float64]
    point_b: NDArray[np.float64]
    normal: NDArray[np.float64]
    depth_m: float


def stateless_requests(geometry_data: pin.GeometryData) -> pin.GeometryData:
    """Turn off coal's GJK warm start on every request of ``geometry_data`` and return it.

    Each query then starts from coal's default guess, so its result depends only on the shapes
    and their placements, not on earlier queries. It is a one-time change of two request fields
    (no per-query cost); the warm start saved no measurable time on these small primitives.
    """
    requests = [*geometry_data.collisionRequests, *geometry_data.distanceRequests]
    with warnings.catch_warnings():
        # ``enable_cached_gjk_guess`` is deprecated in coal but still honoured, and Pinocchio
        # sets it: it must be cleared too.
        warnings.simplefilter("ignore", DeprecationWarning)
        for request in requests:
            request.gjk_initial_guess = coal.GJKInitialGuess.DefaultGuess
            request.enable_cached_gjk_guess = False
    return geometry_data


def settle_box_support() -> bool:
    """Settle coal's box support rule the same way in every process; True if it holds.

    coal 3 decides once per process whether the negative side of every box is pushed out by a
    relative 1e-10 (the tie-breaker of its box support function is a function-local ``static``,
    set from the first direction that function is ever asked about: pushed out if that direction
    has a zero component). Whichever box query came first would then change all later box
    queries in the last bits, which the IK's collision repair amplifies: the same problem gave
    different joints in a fresh process and in one that had already queried a box. A first query
    along an axis fixes the pushed-out rule in every process that imports this module before
    asking coal about a box; it costs one GJK call.

    Returns:
        True if the pushed-out rule holds; False if a box query ran before this module was
        imported and settled the other rule (results then match only processes that did the same).
    """
    box = coal.Box(1.0, 1.0, 1.0)
    beside = coal.Transform3s(np.eye(3), np.array([3.0, 0.0, 0.0]))
    gap_m = coal.distance(
        box, coal.Transform3s(), box, beside, coal.DistanceRequest(), coal.DistanceResult()
    )
    return bool(gap_m < 2.0)  # 2.0 exactly without the push; 2.0 - 5e-11 with it


if not settle_box_support():
    warnings.warn(
        "coal answered a box query before sahgrasp.collision.hand_self was imported, so its box "
        "support rule differs from a fresh process's: results may differ from other processes in "
        "the last bits (import sahgrasp before querying coal for bit-identical results)",
        RuntimeWarning,
        stacklevel=2,
    )


class SelfCollision:
    """Self-collision queries on one Pinocchio model and its coal collision geometry.

    Args:
        model: The hand's Pinocchio model (any root joint).
        geometry_model: Collision geometry built from the same URDF (pairs are replaced here).
        excluded_links: Pairs of link names never to check, in either order.
    """

    def __init__(
        self,
        model: pin.Model,
        geometry_model: pin.GeometryModel,
        excluded_links: Iterable[tuple[str, str]] = (),
    ) -> None:
        self.model = model
        self.geometry_model = geometry_model
        excluded = {frozenset(p) for p in excluded_links}
        geometry_model.removeAllCollisionPairs()
        objects = geometry_model.geometryObjects
        for a in range(len(objects)):
            for b in range(a + 1, len(objects)):
                if self._checked(objects[a], objects[b], excluded):
                    geometry_model.addCollisionPair(pin.CollisionPair(a, b))
        self.geometry_data = stateless_requests(pin.GeometryData(geometry_model))
        self.data = model.createData()
        # The yes/no query goes through coal's sweep-and-prune broad phase: on a collision-free
        # hand (the IK's converged starts) it skips the pairs whose bounding boxes are apart,
        # about half the time of querying all pairs (docs/methods/ik.md). Its own GeometryData: the
        # manager keeps the shapes' boxes there between queries.
        self._broadphase = pin.BroadPhaseManager_SSaPCollisionManager(
            model, geometry_model, stateless_requests(pin.GeometryData(geometry_model))
        )
        # A second set of requests computes contact witnesses, needed only to resolve collisions.
        self._witness_data = stateless_requests(pin.GeometryData(geometry_model))
        self._witness_margin_m: float | None = None
        # The "any pair within the margin?" gate of penetrations() through the broad phase too:
        # Pinocchio inflates each box by half the requests' security margin, so no pair within
        # the margin is pruned.
        self._witness_broadphase = pin.BroadPhaseManager_SSaPCollisionManager(
            model, geometry_model, self._witness_data
        )
        # The result objects, listed once: each reads its pair's entry of the (fixed-size)
        # results vector, and indexing that vector anew costs more than the query (~1 us a pair).
        self._witness_results = list(self._witness_data.collisionResults)
        self._pair_joints = [
            (int(objects[p.first].parentJoint), int(objects[p.second].parentJoint))
            for p in geometry_model.collisionPairs
        ]
        # Bounding spheres (each shape's local box's) sort out the pairs that may be within a
        # margin before any exact query: penetrations() queries only those.
        for obj in objects:
            obj.geometry.computeLocalAABB()
        self._centres_local = np.array([obj.geometry.aabb_center for obj in objects])
        radii_m = np.array([float(obj.geometry.aabb_radius) for obj in objects])
        pairs = geometry_model.collisionPairs
        self._first = np.array([p.first for p in pairs], dtype=np.intp)
        self._second = np.array([p.second for p in pairs], dtype=np.intp)
        self._reach_m = radii_m[self._first] + radii_m[self._second]
        self._placements = geometry_placement_views(self._witness_data)

    def _link(self, obj: pin.GeometryObject) -> str:
        return str(self.model.frames[obj.parentFrame].name)

    def _checked(
        self, a: pin.GeometryObject, b: pin.GeometryObject, excluded: set[frozenset[str]]
    ) -> bool:
        ja, jb = a.parentJoint, b.parentJoint
        parents = self.model.parents
        if ja == jb or parents[ja] == jb or parents[jb] == ja:
            return False
        return frozenset((self._link(a), self._link(b))) not in excluded

    @property
    def pairs(self) -> tuple[CollisionPair, ...]:
        """The link pairs that are checked."""
        objs = self.geometry_model.geometryObjects
        return tuple(
            CollisionPair(self._link(objs[p.first]), self._link(objs[p.second]))
            for p in self.geometry_model.collisionPairs
        )

    def in_collision(self, q: NDArray[np.float64]) -> bool:
        """Return True if any checked pair of shapes intersects at configuration ``q``."""
        return bool(pin.computeCollisions(self.model, self.data, self._broadphase, q, True))

    def colliding_pairs(self, q: NDArray[np.float64]) -> tuple[CollisionPair, ...]:
        """Return every checked pair that intersects at ``q``."""
        pin.computeCollisions(
            self.model, self.data, self.geometry_model, self.geometry_data, q, False
        )
        return tuple(
            pair
            for pair, result in zip(self.pairs, self.geometry_data.collisionResults, strict=True)
            if result.isCollision()
        )

    def min_distance(self, q: NDArray[np.float64]) -> float:
        """Smallest signed distance [m] over the checked pairs (negative: penetration)."""
        pin.computeDistances(self.model, self.data, self.geometry_model, self.geometry_data, q)
        return float(min(r.min_distance for r in self.geometry_data.distanceResults))

    def penetrations(
        self, q: NDArray[np.float64], margin_m: float, pairs: NDArray[np.intp] | None = None
    ) -> list[Penetration]:
        """Every checked pair closer than ``margin_m`` [m] at ``q``, with coal's witnesses.

        A first pass stops at the first pair within the margin, so the usual answer of the IK's
        repair loop, "none", costs one cheap query; the witnesses are read only when needed.

        Args:
            q: Configuration.
            margin_m: Distance [m] below which a pair is reported.
            pairs: Indices into :attr:`pairs` of the only pairs to ask coal about, e.g. those
                the IK's compiled verdict found within the margin (no first pass then); None:
                every checked pair.
        """
        gd = self._witness_data
        if margin_m != self._witness_margin_m:  # ~1 us per request: set once per margin
            for request in gd.collisionRequests:
                request.enable_contact = True
                request.security_margin = margin_m
            self._witness_margin_m = margin_m
        if pairs is not None:
            if not len(pairs):
                return []
            pin.updateGeometryPlacements(self.model, self.data, self.geometry_model, gd, q)
            near = pairs.tolist()
        elif not pin.computeCollisions(self.model, self.data, self._witness_broadphase, q, True):
            return []
        else:
            near = self._near_pairs(margin_m)
        return [
            _penetration(self._pair_joints[k], self._witness_results[k].getContact(0), margin_m)
            for k in near
            if pin.computeCollision(self.geometry_model, gd, k)
        ]

    def _near_pairs(self, margin_m: float) -> list[int]:
        """The pairs whose bounding spheres come within ``margin_m`` [m].

        At the placements the witness data hold. An exact query of every pair read the same
        witnesses at about 3x the cost of querying only these.
        """
        R, t = self._placements or copied_placements(self._witness_data)
        centres = np.matmul(R, self._centres_local[:, :, None])[:, :, 0] + t
        gap = centres[self._first] - centres[self._second]
        reach = self._reach_m + margin_m
        return np.flatnonzero(np.einsum("ij,ij->i", gap, gap) < reach * reach).tolist()


def geometry_placement_views(
    data: pin.GeometryData,
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """Read-only views (G, 3, 3) and (G, 3) of the rotations and translations in ``data.oMg``.

    Pinocchio keeps ``oMg`` as one ``std::vector`` of SE3 (a column-major rotation, then the
    translation: 12 doubles each), written in place by ``updateGeometryPlacements``: strided
    views read every placement without a call per geometry. Checked address by address; None
    if the layout differs (then the placements must be copied after each update).
    """
    placements = data.oMg
    first = placements[0]
    size = first.rotation.itemsize
    step = 12 * size
    start = first.rotation.__array_interface__["data"][0]
    adjacent = all(
        M.rotation.__array_interface__["data"][0] == start + k * step
        and M.translation.__array_interface__["data"][0] == start + k * step + 9 * size
        and M.rotation.flags.f_contiguous
        for k, M in enumerate(placements)
    )
    if not adjacent:
        return None
    as_strided = np.lib.stride_tricks.as_strided
    R = as_strided(first.rotation, (len(placements), 3, 3), (step, size, 3 * size), writeable=False)
    t = as_strided(first.translation, (len(placements), 3), (step, size), writeable=False)
    return R, t


def copied_placements(
    data: pin.GeometryData,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The placements of ``data.oMg`` as arrays (G, 3, 3) and (G, 3), copied.

    The fallback of :func:`geometry_placement_views` when the views cannot be made.
    """
    return (
        np.array([M.rotation for M in data.oMg]),
        np.array([M.translation for M in data.oMg]),
    )


def _penetration(joints: tuple[int, int], contact: coal.Contact, margin_m: float) -> Penetration:
    """The :class:`Penetration` of one of coal's contacts between the bodies of ``joints``."""
    normal = np.asarray(contact.normal, dtype=np.float64)
    signed = float(contact.penetration_depth)
    return Penetration(
        joints[0],
        joints[1],
        np.asarray(contact.getNearestPoint1(), dtype=np.float64),
        np.asarray(contact.getNearestPoint2(), dtype=np.float64),
        normal / max(math.sqrt(float(normal.dot(normal))), 1e-12),
        max(-signed, 0.0) + margin_m if signed < 0 else margin_m - signed,
    )
