"""Summaries of grasp optimizations: JSON for ``sahgrasp atlas``, text beside the paper's figures.

One summary for every :class:`~sahgrasp.optimization.optimizer.OptimizationResult`, whatever the
grasp manifold; each grasp is described in the manifold's own terms (the planar hand's joint angles
and object pose, the SAH's joint values).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sahgrasp.optimization.grasp import HandGraspManifold
from sahgrasp.optimization.optimizer import OptimizationResult
from sahgrasp.optimization.planar import PlanarGraspProblem
from sahgrasp.quality.ellipsoids import QUALITY_INDICES, SINGULAR_THRESHOLDS

__all__ = ["collision_notes", "describe_grasp", "result_lines", "summary"]


def describe_grasp(result: OptimizationResult, chart: int) -> dict[str, Any]:
    """JSON-able description of the grasp at ``chart`` (SI units, angles in radians)."""
    x = result.atlas.centres[chart]
    value = float(result.all_values[chart])
    threshold = SINGULAR_THRESHOLDS.get(result.index)
    out: dict[str, Any] = {
        "chart": chart,
        "value": value,
        "singular": None if threshold is None else bool(value < threshold),
        "collision_free": bool(result.valid[chart]),
        "x": x.tolist(),
    }
    problem = result.problem
    if isinstance(problem, PlanarGraspProblem):
        out["configuration"] = {
            "joint_angles_rad": problem.joint_angles(x).tolist(),
            "object_position_m": x[12:14].tolist(),
            "object_angle_rad": float(np.arctan2(x[14], x[15])),
            "contact_params_rad": x[16:19].tolist(),
        }
    elif isinstance(problem, HandGraspManifold):
        out["joints"] = problem.system.hand.joint_values(result.configurations[chart])
        out["x"] = problem.x_of(x).tolist()
    return out


def summary(name: str, result: OptimizationResult) -> dict[str, Any]:
    """JSON-able summary: sizes, settings, times, collisions, best and worst grasps.

    With the ellipsoids (a built-in index), ``indices`` gives per index the best and worst
    collision-free grasps and the number of singular charts.
    """
    atlas, valid, problem = result.atlas, result.valid, result.problem
    checks = result.checks
    out: dict[str, Any] = {
        "problem": name,
        "charts": atlas.n_charts,
        "complete": atlas.complete,
        "stop_reason": atlas.stop_reason,
        "max_charts": result.settings.max_charts,
        "n": atlas.ambient_dim,
        "t": problem.t,
        "k": atlas.dim,
        "s": problem.t - atlas.dim,
        "radius": atlas.radius,
        "epsilon": atlas.epsilon,
        "index": result.index,
        "valid_charts": int(valid.sum()),
        "colliding_charts": int((~valid).sum()),
        "self_collision_charts": int(checks.self_collision.sum()),
        "object_collision_charts": int(checks.object_collision.sum()),
        "atlas_seconds": result.atlas_seconds,
        "quality_seconds": result.quality_seconds,
        "best": describe_grasp(result, result.best),
        "worst": describe_grasp(result, result.worst),
        "best_overall": describe_grasp(result, result.best_overall),
    }
    if isinstance(problem, HandGraspManifold):
        out["retained_variance"] = problem.retained_variance
    if result.quality is not None:
        out["indices"] = {name: _index_summary(result, name) for name in QUALITY_INDICES}
    return out


def _index_summary(result: OptimizationResult, index: str) -> dict[str, Any]:
    ranked = result.ranked_by(index)
    singular = ranked.values < SINGULAR_THRESHOLDS[index]
    return {
        "best": {"chart": ranked.best, "value": float(ranked.values[ranked.best])},
        "worst": {"chart": ranked.worst, "value": float(ranked.values[ranked.worst])},
        "singular_charts": int(singular.sum()),
    }


def collision_notes(result: OptimizationResult) -> tuple[str, ...]:
    """Report lines: colliding charts, and the best grasp over all charts if it collides."""
    checks = result.checks
    notes = [
        f"colliding charts: {int((~result.valid).sum())} of {result.atlas.n_charts} "
        f"({int(checks.self_collision.sum())} self, "
        f"{int(checks.object_collision.sum())} hand-object); {int(result.valid.sum())} valid"
    ]
    if result.best_overall != result.best:
        value = result.all_values[result.best_overall]
        notes.append(
            f"best grasp over all charts (colliding): chart {result.best_overall}, "
            f"{result.index} = {value:.4g}"
        )
    return tuple(notes)


def result_lines(result: OptimizationResult) -> tuple[str, ...]:
    """Report lines of an example: valid and colliding charts, times, best and worst grasps."""
    atlas, checks = result.atlas, result.checks  # a chart centre is valid when nothing collides
    return (
        f"valid: {int(result.valid.sum())} of {atlas.n_charts} charts; colliding: "
        f"{int(checks.self_collision.sum())} self, "
        f"{int(checks.object_collision.sum())} hand-object",
        f"time: atlas {result.atlas_seconds:.1f} s, quality {result.quality_seconds:.1f} s",
        *(
            f"{which} grasp: chart {chart}, {result.index} = {result.values[chart]:.4g}"
            for which, chart in (("best", result.best), ("worst", result.worst))
        ),
    )
