"""Global grasp optimization: Algorithm 1 of the atlas paper on a grasp manifold.

:mod:`~sahgrasp.optimization.optimizer` runs the optimization on any
:class:`~sahgrasp.optimization.optimizer.GraspManifold`; :mod:`~sahgrasp.optimization.grasp` builds
the SAH's feasible-grasp system and manifold, :mod:`~sahgrasp.optimization.planar` the planar
hand's, :mod:`~sahgrasp.optimization.motions` the principal hand motions. Names are loaded on first
use.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

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
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}

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
