"""Typed errors of sahgrasp.

Every error a user can trigger with bad input is a :class:`SahGraspError` subclass whose message
names what was wrong and what is valid. Unreachable grasps are *not* errors: the IK returns a result
with ``success=False``.
"""

from __future__ import annotations

__all__ = [
    "AtlasError",
    "GraspSystemError",
    "HandModelError",
    "InvalidConfigurationError",
    "InvalidSettingsError",
    "InvalidTargetError",
    "MissingExtraError",
    "OptimizationError",
    "PrincipalMotionsError",
    "QualityError",
    "SahGraspError",
    "SequenceFileError",
    "VizError",
]


class SahGraspError(Exception):
    """Base class of every error raised on purpose by sahgrasp."""


class HandModelError(SahGraspError):
    """A hand description or URDF is missing, malformed or inconsistent."""


class InvalidConfigurationError(SahGraspError):
    """A joint vector or configuration has the wrong size, or holds NaN/inf."""


class InvalidSettingsError(SahGraspError):
    """A solver or search parameter is out of its valid range."""


class InvalidTargetError(SahGraspError):
    """A contact target is malformed: unknown finger, NaN/inf, non-unit normal, ..."""


class SequenceFileError(SahGraspError):
    """A sequence or checkpoint file is corrupted, foreign, or made for another hand."""


class AtlasError(SahGraspError):
    """The atlas problem is ill-posed: shapes disagree, start point off the manifold, bad k."""


class GraspSystemError(SahGraspError):
    """A feasible-grasp system is ill-posed: bad symmetry axis, ``k`` out of ``[1, t]``."""


class PrincipalMotionsError(SahGraspError):
    """Principal hand motions asked for more constraints than they have directions."""


class QualityError(SahGraspError):
    """A quality index is unknown, or a user index gives the wrong number of values or only NaN."""


class OptimizationError(SahGraspError):
    """A grasp optimization cannot run: unknown experiment or index, no first grasp or candidate."""


class VizError(SahGraspError):
    """A drawing was given malformed data (shapes, non-finite points, no finite quality value)."""


class MissingExtraError(SahGraspError, ImportError):
    """An optional dependency is not installed; the message names the extra that installs it.

    Also an ``ImportError``, so that ``except ImportError`` around an optional import
    catches it. :func:`sahgrasp.core.extras.require_extra` raises it.

    Attributes:
        extra: The extra of pyproject.toml that installs the missing package (``cluster``...).
    """

    def __init__(self, extra: str, message: str) -> None:
        super().__init__(message)
        self.extra = extra
