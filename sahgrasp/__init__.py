"""sahgrasp: precision-grasp IK and global grasp optimization for anthropomorphic hands.

The names below are loaded on first use, so that ``import sahgrasp`` (and ``sahgrasp --help``)
stays fast: Pinocchio and coal are imported only when a hand is needed.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sahgrasp import _moved
from sahgrasp.core.lazy import lazy_exports

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
    from sahgrasp.model.contacts import ContactTarget, GraspTarget
    from sahgrasp.model.hand import Hand, HandDescription, load_hand
    from sahgrasp.objects.targets import load_targets, save_targets
    from sahgrasp.planner import GraspPlan, PlanSettings, plan_grasps

_EXPORTS = {
    "sahgrasp.model.contacts": ("ContactTarget", "GraspTarget"),
    "sahgrasp.objects.targets": ("load_targets", "save_targets"),
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


__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
