"""Global grasp optimization: Algorithm 1 of the atlas paper on a grasp manifold.

:mod:`~sahgrasp.optimization.optimizer` runs the optimization on any
:class:`~sahgrasp.optimization.optimizer.GraspManifold`; :mod:`~sahgrasp.optimization.grasp` builds
the SAH's feasible-grasp system and manifold, :mod:`~sahgrasp.optimization.planar` the planar
hand's, :mod:`~sahgrasp.optimization.motions` the principal hand motions. Names are loaded on first
use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sahgrasp.core.lazy import lazy_exports

if TYPE_CHECKING:
    from sahgrasp.optimization.optimizer import (
        ChartChecks,
        ComponentSearch,
        GraspManifold,
        IndexFunction,
        OptimizationResult,
        OptimizationSettings,
        optimize,
        optimize_components,
    )

_EXPORTS = {
    "sahgrasp.optimization.optimizer": (
        "ChartChecks",
        "ComponentSearch",
        "GraspManifold",
        "IndexFunction",
        "OptimizationResult",
        "OptimizationSettings",
        "optimize",
        "optimize_components",
    ),
}

__all__ = [
    "ChartChecks",
    "ComponentSearch",
    "GraspManifold",
    "IndexFunction",
    "OptimizationResult",
    "OptimizationSettings",
    "optimize",
    "optimize_components",
]


__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
