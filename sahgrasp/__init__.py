"""sahgrasp: precision-grasp IK and global grasp optimization for anthropomorphic hands."""

from sahgrasp.contacts import ContactTarget, GraspTarget, load_targets, save_targets
from sahgrasp.errors import (
    AtlasError,
    HandModelError,
    InvalidConfigurationError,
    InvalidTargetError,
    SahGraspError,
    SequenceFileError,
)
from sahgrasp.hand import Hand, HandDescription, load_hand
from sahgrasp.ik import IKResult, IKSettings, solve_ik, solve_many

__all__ = [
    "AtlasError",
    "ContactTarget",
    "GraspTarget",
    "Hand",
    "HandDescription",
    "HandModelError",
    "IKResult",
    "IKSettings",
    "InvalidConfigurationError",
    "InvalidTargetError",
    "SahGraspError",
    "SequenceFileError",
    "load_hand",
    "load_targets",
    "save_targets",
    "solve_ik",
    "solve_many",
]
