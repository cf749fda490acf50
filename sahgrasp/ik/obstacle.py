"""The object a grasp must not pass through, as the IK sees it.

Every hand link must stay outside the object, except the fingertip sphere of each finger that has
a contact: it touches the object at its contact by design, and Eq. (9) accepts its contact point
up to ``d_min`` from the target, so that sphere alone may penetrate by up to ``d_min``. The
signed distances come from :class:`sahgrasp.collision.hand_object.HandObjectClearance` (coal GJK/EPA
between each link shape and the object's convex pieces); its penetration records have the object
as body ``a`` (joint 0, fixed), so the IK's separation rows push the links out along the normals.
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import NDArray

from sahgrasp.collision.hand_object import Clearance, HandObjectClearance
from sahgrasp.collision.hand_self import Penetration
from sahgrasp.core.errors import InvalidTargetError
from sahgrasp.ik._lm import Pieces
from sahgrasp.ik.compiled import CONVEX, TIE_M, compiled_tree, describe_shape
from sahgrasp.model.hand import Hand
from sahgrasp.objects.body import GraspObject

__all__ = [
    "REPAIR_PAIRS_PER_LINK",
    "Obstacle",
    "build_pieces",
    "check_obstacle",
    "checker_of",
    "pieces_of",
]

REPAIR_PAIRS_PER_LINK = 1
"""Most (link, piece) pairs one link adds to a collision-repair step.

A link deep in a finely cut object overlaps many pieces (the coffee cup's revolved sectors, a
mesh's joined prisms); a row per pair costs a GJK call and a Jacobian each, for normals that
mostly agree. With one pair per link the repair query is one coal collision test per link in
the piece tree (``HandObjectClearance.penetrations`` with ``per_link=1``), the first pair that
test finds. On the grasp benchmark's sets (``sahgrasp bench grasps``) one pair per link solves
as many sets as several pairs per link, with no claimed solution penetrating the object either
way, and makes the repair query several times cheaper on the finely cut objects.
"""


_KEPT_OBJECTS = 8
"""Objects per hand whose clearance checker and compiled pieces the hand's cache keeps."""


def checker_of(hand: Hand, obj: GraspObject | None) -> HandObjectClearance:
    """One clearance checker per (hand, object) pair (None: no object), kept in ``hand.cache``.

    The hand keeps those of its :data:`_KEPT_OBJECTS` most recently used objects.

    Building one (about 0.7 ms without an object, for placing free fingers) builds the piece
    tree (up to 0.04 s for the catalog objects) and, on the object's first use, its convex pieces
    (0.01 s for the can, 0.15 s for the coffee cup, 1.6-2.2 s for the shipped meshes, whose
    triangle prisms are merged): too much to repeat for every problem.
    """
    build = functools.partial(HandObjectClearance, hand, obj)
    return hand.cache.kept("clearance_checkers", obj, build, _KEPT_OBJECTS)


def pieces_of(checker: HandObjectClearance) -> Pieces | None:
    """:func:`build_pieces` of ``checker``, kept in its hand's cache (as :func:`checker_of`)."""
    build = functools.partial(build_pieces, checker)
    return checker.hand.cache.kept("object_pieces", checker, build, _KEPT_OBJECTS)


def build_pieces(checker: HandObjectClearance) -> Pieces | None:
    """The checker's object pieces for the compiled verdicts, None if they cannot be compiled.

    The compiled verdicts (``Tree.object_clearance``, ``Tree.shapes_near``: GJK in
    ``sahgrasp/collision/_gjk.h``) know the kinds of :func:`~sahgrasp.ik.compiled.describe_shape`; a
    piece of another kind, or a hand whose own shapes are not compiled, leaves every query to coal.
    """
    if not compiled_tree(checker.hand).shape_count:
        return None
    tree = checker.piece_tree
    shapes = checker.object.collision_shapes()
    described = [describe_shape(shape.geometry) for shape in shapes]
    if not shapes or any(d is None for d in described):
        return None
    kinds, sizes, vertices, neighbours = zip(*described, strict=True)
    counts = [len(v) for v in vertices]
    first, flat = _neighbour_offsets(kinds, neighbours)
    cells = np.hstack([tree.coarse_centres_m, tree.coarse_radii_m[:, None]])
    return Pieces(
        kinds=np.array(kinds, dtype=np.int64),
        placements=np.array(
            [np.concatenate([s.placement[:3, :3].ravel(), s.placement[:3, 3]]) for s in shapes]
        ),
        sizes=np.array(sizes, dtype=np.float64),
        balls=np.array(
            [
                [*shape.placement[:3, 3], shape.bounding_radius_m + size[3]]
                for shape, size in zip(shapes, sizes, strict=True)
            ]
        ),
        vertex_start=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
        vertices=np.concatenate([np.reshape(v, (-1, 3)) for v in vertices]).astype(np.float64),
        first=first,
        neighbours=flat,
        cell_balls=np.ascontiguousarray(cells, dtype=np.float64),
        cell_start=np.concatenate([[0], np.cumsum(tree.sizes)]).astype(np.int64),
        cell_members=np.concatenate(tree.members).astype(np.int64),
    )


def _neighbour_offsets(
    kinds: tuple[int, ...], neighbours: tuple[list[list[int]] | None, ...]
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The ``first`` and ``neighbours`` arrays of :class:`Pieces` (see ``sahgrasp/ik/_lm.c``)."""
    first: list[int] = []
    flat: list[int] = []
    for kind, piece in zip(kinds, neighbours, strict=True):
        if kind != CONVEX:
            continue
        if piece is None:  # its vertices are scanned
            first.append(-1)
            continue
        for adjacent in piece:
            first.append(len(flat))
            flat += adjacent
        first.append(len(flat))
    return np.array(first, dtype=np.int64), np.array(flat, dtype=np.int64)


def check_obstacle(obj: object) -> None:
    """Raise :class:`InvalidTargetError` unless ``obj`` is a GraspObject."""
    if not isinstance(obj, GraspObject):
        raise InvalidTargetError(
            f"obstacle must be a GraspObject (sahgrasp.objects: load_object(name) or a loaded "
            f"mesh), got {type(obj).__name__}"
        )


class Obstacle:
    """An object at its placement, the fingers in contact with it and their allowance.

    One definition decides whether a configuration is inside the object, for the solver's
    acceptance test and for the clearance it reports: :meth:`HandObjectClearance.clearance`
    with the contact fingers and the allowance. :meth:`penetrated` asks
    :meth:`HandObjectClearance.clearance_if_clear`, which gives a clear configuration's exact
    clearance and only the verdict for one inside; the clearance is kept, so the result's
    clearance of an accepted start costs no second query, and a rejected start's is measured
    only if the result reports it.

    Args:
        hand: The hand.
        obj: The object (a :class:`sahgrasp.objects.GraspObject`, placed in the world).
        contacts: Fingers whose fingertip spheres touch the object at their contacts.
        allowance_m: How deep those spheres may enter the object [m] (the IK's ``d_min``).

    Raises:
        InvalidTargetError: ``obj`` is not a GraspObject.
    """

    def __init__(
        self, hand: Hand, obj: GraspObject, contacts: tuple[str, ...], allowance_m: float
    ) -> None:
        check_obstacle(obj)
        self.checker = checker_of(hand, obj)
        self.contacts = contacts
        self.allowance_m = allowance_m
        self._tree = compiled_tree(hand)
        self._pieces = pieces_of(self.checker)
        self._near = np.empty(len(self.checker.links), dtype=np.int64)
        # The last q asked about and its exact clearance (None: only known to be inside).
        self._last: tuple[bytes, Clearance | None] = (b"", None)

    def penetrations(self, q: NDArray[np.float64], margin_m: float) -> list[Penetration]:
        """Links closer to the object than ``margin_m`` [m] (contact tips: deeper than allowed).

        At most :data:`REPAIR_PAIRS_PER_LINK` pairs per link: a separation row each in the repair.
        """
        near = None
        if self._pieces is not None:  # coal is asked about the links the compiled check finds
            thresholds = self.checker.thresholds(self.contacts, margin_m, self.allowance_m)
            T = self.checker.object.T_world_object
            count = self._tree.shapes_near(self._pieces, q, T, thresholds + TIE_M, self._near)
            near = self._near[:count].tolist()
        return self.checker.penetrations(
            q, margin_m, self.contacts, self.allowance_m, per_link=REPAIR_PAIRS_PER_LINK,
            geometries=near,
        )  # fmt: skip

    def penetrated(self, q: NDArray[np.float64]) -> bool:
        """True if a link is inside the object (contact tips: deeper than the allowance)."""
        # The inner solver, Algorithm 1's Step 8 and the result all ask about the accepted q.
        key = q.tobytes()
        if self._last[0] == key:
            return self._last[1] is None or not self._last[1].clear()
        found = (
            self.checker.clearance_if_clear(q, self.contacts, self.allowance_m)
            if self._pieces is None
            else self._compiled_clearance(q, self._pieces)
        )
        self._last = (key, found)
        return found is None

    def _compiled_clearance(self, q: NDArray[np.float64], pieces: Pieces) -> Clearance | None:
        """:meth:`HandObjectClearance.clearance_if_clear` by the compiled check (GJK).

        The same verdict and clearance up to GJK's tolerance (about 1e-12 of the distance);
        the closest link is the one geometry found at the smallest distance.
        """
        thresholds = self.checker.thresholds(self.contacts, 0.0, self.allowance_m)
        T = self.checker.object.T_world_object
        inside, distance_m, closest = self._tree.object_clearance(pieces, q, T, thresholds)
        if inside:
            return None
        link = self.checker.links[closest] if closest >= 0 else ""
        return Clearance(distance_m, link, {link: distance_m} if link else {})

    def clearance(self, q: NDArray[np.float64]) -> Clearance:
        """Smallest signed distance [m] of a link to the object and that link (kept for ``q``)."""
        key = q.tobytes()
        last = self._last[1]
        if self._last[0] != key or last is None:
            last = self.checker.clearance(q, self.contacts, self.allowance_m, all_links=False)
            self._last = (key, last)
        return last
