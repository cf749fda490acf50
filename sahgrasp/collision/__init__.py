"""Collision geometry and queries: the hand's self-collision and an object's convex pieces.

:mod:`~sahgrasp.collision.hand_self` checks a hand against itself (coal through Pinocchio);
:mod:`~sahgrasp.collision.shapes` holds an object's convex pieces and their signed distances. The
GJK of the compiled kernels is ``sahgrasp/collision/_gjk.h``. The names of the hand's
self-collision are loaded on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sahgrasp.core.lazy import lazy_exports

if TYPE_CHECKING:
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
    "CollisionPair",
    "Penetration",
    "SelfCollision",
    "copied_placements",
    "geometry_placement_views",
    "settle_box_support",
    "stateless_requests",
]


__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
