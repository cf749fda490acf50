"""Matplotlib figures of grasp optimizations (Agg renderer, PNG; matplotlib imported on use).

:func:`plot_index_map` draws any optimization's chart centres on their two principal axes coloured
by the index (green large, red small, black singular or colliding); :func:`plot_planar` draws the
planar hand's Fig. 9 of the atlas paper: one such map per index, then the best and worst grasps.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sahgrasp.core.errors import OptimizationError
from sahgrasp.core.extras import require_extra
from sahgrasp.optimization.optimizer import OptimizationResult
from sahgrasp.optimization.planar import PlanarGraspProblem, PlanarHand
from sahgrasp.quality.ellipsoids import INDICES, SINGULAR_THRESHOLDS, principal_projection

__all__ = ["plot_index_map", "plot_planar"]

_PANELS = ("(a) inverse condition number", "(b) volume", "(c) smallest semi-axis")


def _index_panel(
    ax: Any, xy: NDArray[np.float64], values: NDArray[np.float64], singular_below: float,
    best: int, worst: int, title: str,
) -> Any:  # fmt: skip
    """Centres ``xy`` coloured by ``values`` (NaN or singular: black); best star, worst cross."""
    ok = np.isfinite(values) & (values >= singular_below)
    points = ax.scatter(xy[ok, 0], xy[ok, 1], c=values[ok], cmap="RdYlGn", s=12)
    ax.scatter(xy[~ok, 0], xy[~ok, 1], c="black", s=12, label="singular or colliding")
    ax.plot(*xy[best], marker="*", color="blue", markersize=16)
    ax.plot(*xy[worst], marker="X", color="blue", markersize=12)
    ax.set(title=title, xlabel="principal component 1", ylabel="principal component 2")
    return points


def plot_index_map(result: OptimizationResult, path: str | Path, title: str) -> None:
    """The chart centres coloured by the optimised index, with a colour bar, as a PNG.

    Raises:
        MissingExtraError: matplotlib is not installed (the extra ``plot``).
    """
    require_extra("plot", f"the figure {path}")
    from matplotlib.figure import Figure

    xy = principal_projection(result.atlas.centres)
    threshold = SINGULAR_THRESHOLDS.get(result.index, -np.inf)
    fig = Figure(figsize=(6, 5), layout="constrained")
    ax = fig.add_subplot()
    points = _index_panel(ax, xy, result.values, threshold, result.best, result.worst, title)
    fig.colorbar(points, ax=ax)
    ax.legend(loc="lower right", fontsize=8)
    fig.savefig(Path(path), dpi=110)


def plot_planar(result: OptimizationResult, path: str | Path) -> None:
    """Fig. 9 of the atlas paper for a planar-hand optimization, as a PNG.

    Top row: the centres on their first two principal components, one panel per index; the best
    chart of each index is a star, the worst a cross. Bottom row: the best and worst grasps of
    the optimised index.

    Raises:
        OptimizationError: The result is not the planar hand's, or was ranked by a user index.
        MissingExtraError: matplotlib is not installed (the extra ``plot``).
    """
    require_extra("plot", f"the figure {path}")
    from matplotlib.figure import Figure

    problem = result.problem
    if not isinstance(problem, PlanarGraspProblem) or result.quality is None:
        raise OptimizationError("plot_planar needs a planar-hand optimization of a built-in index")
    xy = principal_projection(result.atlas.centres)
    fig = Figure(figsize=(15, 9), layout="constrained")
    grid = fig.add_gridspec(2, 6)
    for i, (name, title) in enumerate(zip(INDICES, _PANELS, strict=True)):
        ranked = result.ranked_by(name)
        singular = int(result.quality.singular(name).sum())
        _index_panel(
            fig.add_subplot(grid[0, 2 * i : 2 * i + 2]), xy, ranked.values,
            SINGULAR_THRESHOLDS[name], ranked.best, ranked.worst,
            f"{title}: {singular} singular of {result.atlas.n_charts}",
        )  # fmt: skip
    for column, (which, chart) in enumerate((("best", result.best), ("worst", result.worst))):
        ax = fig.add_subplot(grid[1, 3 * column : 3 * column + 3])
        title = f"{which} {result.index}: chart {chart}, {result.all_values[chart]:.3g}"
        _draw_planar_grasp(ax, problem.hand, result.atlas.centres[chart], title)
    fig.savefig(Path(path), dpi=90)


def _draw_planar_grasp(ax: Any, hand: PlanarHand, x: NDArray[np.float64], title: str) -> None:
    """The hand (blue), the object's circles (black) and contact arcs (red) at ``x``."""
    v = x[:12].reshape(3, 2, 2)
    joints = hand.anchors[:, None, :] + np.cumsum(hand.phalanges[:, :, None] * v, axis=1)
    for anchor, (knuckle, tip) in zip(hand.anchors, joints, strict=True):
        ax.plot(*np.array([anchor, knuckle, tip]).T, "-o", color="tab:blue", markersize=3)
    s, c = x[14], x[15]
    rotation = np.array([[c, -s], [s, c]])
    centres = x[12:14] + hand.centres @ rotation.T
    for centre, radius, arc in zip(centres, hand.radii, hand.arcs, strict=True):
        full = np.linspace(0.0, 2.0 * np.pi, 90)
        ax.plot(*(centre + radius * _circle(full)).T, color="black", linewidth=0.8)
        contact = _circle(np.linspace(arc[0], arc[1], 30))
        ax.plot(*(centre + radius * contact).T, color="tab:red", linewidth=2)
    ax.plot(*np.array([hand.anchors[0], hand.anchors[-1]]).T, color="black", linewidth=4)
    ax.set_title(title)
    ax.set_aspect("equal")


def _circle(angles: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.stack((np.cos(angles), np.sin(angles)), axis=-1)
