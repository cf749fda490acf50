"""sahgrasp: precision-grasp IK and global grasp optimization for anthropomorphic hands.

The names below are loaded on first use, so that ``import sahgrasp`` (and ``sahgrasp --help``)
stays fast: Pinocchio and coal are imported only when a hand is needed.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from sahgrasp import _moved

if TYPE_CHECKING:
    from sahgrasp.core.errors import (
        AtlasError,
        HandModelError,
        InvalidConfigurationError,
        InvalidTargetError,
        SahGraspError,
        SequenceFileError,
    )
    from sahgrasp.ik import IKResult, IKSettings, solve_ik, solve_many
    from sahgrasp.model.contacts import ContactTarget, GraspTarget, load_targets, save_targets
    from sahgrasp.model.hand import Hand, HandDescription, load_hand
    from sahgrasp.planner import GraspPlan, PlanSettings, plan_grasps

_EXPORTS = {
    "sahgrasp.model.contacts": ("ContactTarget", "GraspTarget", "load_targets", "save_targets"),
    "sahgrasp.core.errors": (
        "AtlasError",
        "HandModelError",
        "InvalidConfigurationError",
        "InvalidTargetError",
        "SahGraspError",
        "SequenceFileError",
    ),
    "sahgrasp.model.hand": ("Hand", "HandDescription", "load_hand"),
    "sahgrasp.ik": ("IKResult", "IKSettings", "solve_ik", "solve_many"),
    "sahgrasp.planner": ("GraspPlan", "PlanSettings", "plan_grasps"),
}
_moved.install()  # old module paths import for one release, with a DeprecationWarning

_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}

__all__ = [
    "AtlasError",
    "ContactTarget",
    "GraspPlan",
    "GraspTarget",
    "Hand",
    "HandDescription",
    "HandModelError",
    "IKResult",
    "IKSettings",
    "InvalidConfigurationError",
    "InvalidTargetError",
    "PlanSettings",
    "SahGraspError",
    "SequenceFileError",
    "load_hand",
    "load_targets",
    "plan_grasps",
    "save_targets",
    "solve_ik",
    "solve_many",
]


def __getattr__(name: str) -> Any:
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module 'sahgrasp' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
