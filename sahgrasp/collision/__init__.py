"""Collision geometry and queries: the hand's self-collision and an object's convex pieces.

:mod:`~sahgrasp.collision.hand_self` checks a hand against itself (coal through Pinocchio);
:mod:`~sahgrasp.collision.shapes` holds an object's convex pieces and their signed distances. The
GJK of the compiled kernels is ``sahgrasp/collision/_gjk.h``. The names of the hand's
self-collision are loaded on first use.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

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
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}

__all__ = [
    "CollisionPair",
    "Penetration",
    "SelfCollision",
    "copied_placements",
    "geometry_placement_views",
    "settle_box_support",
    "stateless_requests",
]


def __getattr__(name: str) -> Any:
    # Loaded on first use: importing one submodule does not load its siblings' dependencies.
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
