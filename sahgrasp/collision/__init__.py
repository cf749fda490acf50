"""Collision geometry and queries: the hand against itself and against an object.

:mod:`~sahgrasp.collision.hand_self` checks a hand against itself (coal through Pinocchio);
:mod:`~sahgrasp.collision.shapes` holds an object's convex pieces and their signed distances;
:mod:`~sahgrasp.collision.hand_object` measures the signed distances between a hand's links and
an object's pieces and places free fingers clear. The GJK of the compiled kernels is
``sahgrasp/collision/_gjk.h``. The names are loaded on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sahgrasp.core.lazy import lazy_exports

if TYPE_CHECKING:
    from sahgrasp.collision.hand_object import (
        CONTACT_ALLOWANCE_M,
        FREE_FINGER_MARGIN_M,
        Clearance,
        ClearanceHand,
        ClearanceObject,
        FreeFingerPlacement,
        HandObjectClearance,
    )
    from sahgrasp.collision.hand_self import (
        CollisionPair,
        Penetration,
        SelfCollision,
        copied_placements,
        geometry_placement_views,
        settle_box_support,
        stateless_requests,
    )

_EXPORTS = {
    "sahgrasp.collision.hand_object": (
        "CONTACT_ALLOWANCE_M",
        "FREE_FINGER_MARGIN_M",
        "Clearance",
        "ClearanceHand",
        "ClearanceObject",
        "FreeFingerPlacement",
        "HandObjectClearance",
    ),
    "sahgrasp.collision.hand_self": (
        "CollisionPair",
        "Penetration",
        "SelfCollision",
        "copied_placements",
        "geometry_placement_views",
        "settle_box_support",
        "stateless_requests",
    ),
}

__all__ = [
    "CONTACT_ALLOWANCE_M",
    "FREE_FINGER_MARGIN_M",
    "Clearance",
    "ClearanceHand",
    "ClearanceObject",
    "CollisionPair",
    "FreeFingerPlacement",
    "HandObjectClearance",
    "Penetration",
    "SelfCollision",
    "copied_placements",
    "geometry_placement_views",
    "settle_box_support",
    "stateless_requests",
]


__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
