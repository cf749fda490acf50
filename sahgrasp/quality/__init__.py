"""Grasp quality: manipulability ellipsoids, the registry of their indices, wrench-space measures.

:mod:`~sahgrasp.quality.ellipsoids` evaluates manipulability indices at chart centres;
:mod:`~sahgrasp.quality.indices` registers the indices without numpy (the parsers list them);
:mod:`~sahgrasp.quality.wrench` gives force closure and the Ferrari-Canny epsilon;
:mod:`~sahgrasp.quality.weight` the weight support, the pull through the centre of mass a grasp
resists in six directions per newton of finger force. Names are loaded
on first use, so that importing :mod:`sahgrasp.quality.indices` does not import numpy.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sahgrasp.core.lazy import lazy_exports

if TYPE_CHECKING:
    from sahgrasp.quality.ellipsoids import (
        INDICES,
        QUALITY_INDICES,
        SINGULAR_THRESHOLDS,
        ChartCentres,
        IndexEvaluation,
        Manipulability,
        QualityIndex,
        ellipsoid_indices,
        evaluate_index,
        full_rank_null_space,
        manipulability,
        null_space,
        principal_projection,
        register_index,
        semi_axes,
    )
    from sahgrasp.quality.weight import WeightSupport, holds_weight, weight_support

_EXPORTS = {
    "sahgrasp.quality.ellipsoids": (
        "ChartCentres",
        "INDICES",
        "IndexEvaluation",
        "Manipulability",
        "QUALITY_INDICES",
        "QualityIndex",
        "SINGULAR_THRESHOLDS",
        "ellipsoid_indices",
        "evaluate_index",
        "full_rank_null_space",
        "manipulability",
        "null_space",
        "principal_projection",
        "register_index",
        "semi_axes",
    ),
    "sahgrasp.quality.weight": ("WeightSupport", "holds_weight", "weight_support"),
}

__all__ = [
    "INDICES",
    "QUALITY_INDICES",
    "SINGULAR_THRESHOLDS",
    "ChartCentres",
    "IndexEvaluation",
    "Manipulability",
    "QualityIndex",
    "WeightSupport",
    "ellipsoid_indices",
    "evaluate_index",
    "full_rank_null_space",
    "holds_weight",
    "manipulability",
    "null_space",
    "principal_projection",
    "register_index",
    "semi_axes",
    "weight_support",
]


__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
