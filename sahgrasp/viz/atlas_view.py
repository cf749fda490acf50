"""An atlas in a scene: chart centres coloured by a quality index, with the best and worst grasps.

As the atlas paper's Figs. 9-10: green for a large index, red for a small one, black for a singular
grasp (index below its threshold); chart centres that are no candidate grasp (NaN index) are grey,
and those marked as colliding (the hand with itself or with the object) purple. The centres are
plain arrays: 2-D or 3-D points are drawn as they are, higher-dimensional ones (configurations
``x``) on their three principal axes; either way scaled to ``size_m``. The best and the worst
grasps are drawn beside the atlas, right and left, each linked to its chart by a line.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import meshcat.geometry as mg
import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp.core.errors import VizError
from sahgrasp.model.hand import Hand
from sahgrasp.objects import GraspObject, transform_points
from sahgrasp.quality.ellipsoids import principal_projection
from sahgrasp.viz.colors import hex_color, quality_colors
from sahgrasp.viz.grasp_view import grasp_points, show_grasp
from sahgrasp.viz.viewer import Viewer, translation

__all__ = [
    "ATLAS_SIZE_M",
    "COLLIDING_RGB",
    "AtlasPlot",
    "ChartGrasp",
    "DrawExtreme",
    "display_points",
    "show_atlas",
    "show_atlas_grasps",
    "show_atlas_scene",
]

ATLAS_SIZE_M = 0.25
"""Largest extent of a drawn atlas [m] (hand-sized, to sit beside the grasps)."""

COLLIDING_RGB = (0.55, 0.25, 0.75)
"""Colour of the chart centres whose grasp collides (purple)."""

_INVALID_RGB = (0.6, 0.6, 0.6)
_LINK_RGB = (0.3, 0.3, 0.3)
_VIEW = (0.0, -1.0, 0.35)
_ASPECT = 1.5  # the row (atlas between two grasps) fits a 1200x800 window, and any wider
_POINT_SIZE_M = 0.035 * ATLAS_SIZE_M

DrawExtreme = Callable[[str, int, NDArray[np.float64]], NDArray[np.float64]]
"""``draw(path, chart, T_scene) -> extent``: draws chart ``chart``'s grasp under ``path`` placed
at ``T_scene`` (4x4), returns points spanning it in the scene (N, 3) [m]."""


@dataclass(frozen=True)
class AtlasPlot:
    """What :func:`show_atlas` drew.

    Attributes:
        positions_m: Display position of each chart centre in the atlas's frame, (N, 3) [m].
        best: Chart of the best grasp.
        worst: Chart of the worst grasp.
        colors_rgb: Colour of each chart centre, (N, 3), components in [0, 1].
    """

    positions_m: NDArray[np.float64]
    best: int
    worst: int
    colors_rgb: NDArray[np.float64]


def display_points(points: ArrayLike, size_m: float = ATLAS_SIZE_M) -> NDArray[np.float64]:
    """3-D display positions (N, 3) of chart centres (N, d), centred, largest extent ``size_m``.

    Points with d <= 3 are drawn as given (zero-padded to 3-D), higher-dimensional ones on their
    three principal axes.

    Raises:
        VizError: ``points`` is not a finite (N, d) array with N >= 1.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[0] == 0 or not np.all(np.isfinite(p)):
        raise VizError(f"chart centres must be a finite (N, d) array, got shape {p.shape}")
    p = principal_projection(p, 3) if p.shape[1] > 3 else p - p.mean(axis=0)
    p = np.pad(p, ((0, 0), (0, 3 - p.shape[1])))
    extent = float(np.ptp(p, axis=0).max())
    return p * (size_m / extent) if extent > 0 else p


def _extremes(values: NDArray[np.float64]) -> tuple[int, int]:
    candidates = np.flatnonzero(np.isfinite(values))
    if not candidates.size:
        raise VizError("no chart has a finite quality value")
    return (
        int(candidates[np.argmax(values[candidates])]),
        int(candidates[np.argmin(values[candidates])]),
    )


def show_atlas(
    viewer: Viewer,
    path: str,
    points: ArrayLike,
    values: ArrayLike,
    singular_below: float,
    best: int | None = None,
    worst: int | None = None,
    colliding: ArrayLike | None = None,
) -> AtlasPlot:
    """Draw chart centres coloured by quality; mark the best and worst charts with spheres.

    Args:
        viewer: The scene.
        path: Scene path of the atlas (``path/charts``, ``path/best``, ``path/worst``).
        points: Chart centres, (N, d) (see :func:`display_points`).
        values: Quality index per chart, (N,); NaN marks a chart that is no candidate.
        singular_below: Index value below which a grasp is singular (drawn black).
        best: Chart of the best grasp (default: the largest finite value).
        worst: Chart of the worst grasp (default: the smallest finite value).
        colliding: Per chart, (N,) booleans: drawn purple whatever their value (default none).

    Raises:
        VizError: Shapes disagree, or no value is finite.
    """
    v = np.asarray(values, dtype=np.float64)
    positions = display_points(points)
    hit = np.zeros(len(v), dtype=bool) if colliding is None else np.asarray(colliding, dtype=bool)
    if v.shape != (len(positions),) or hit.shape != v.shape:
        raise VizError(
            f"{len(positions)} chart centres but values of shape {v.shape} and colliding "
            f"flags of shape {hit.shape}"
        )
    default_best, default_worst = _extremes(v)
    best = default_best if best is None else best
    worst = default_worst if worst is None else worst
    finite = np.isfinite(v)
    colors = np.tile(_INVALID_RGB, (len(v), 1))
    colors[finite] = quality_colors(v[finite], singular_below)
    colors[hit] = COLLIDING_RGB
    cloud = mg.PointCloud(
        positions.T.astype(np.float32), colors.T.astype(np.float32), size=_POINT_SIZE_M
    )
    viewer.meshcat[f"{path}/charts"].set_object(cloud)
    for name, chart in (("best", best), ("worst", worst)):
        node = viewer.meshcat[f"{path}/{name}"]
        node.set_object(
            mg.Sphere(1.5 * _POINT_SIZE_M), mg.MeshPhongMaterial(color=hex_color(colors[chart]))
        )
        node.set_transform(translation(positions[chart]))
    return AtlasPlot(positions, best, worst, colors)


def show_atlas_scene(
    viewer: Viewer,
    points: ArrayLike,
    values: ArrayLike,
    singular_below: float,
    draw_extreme: DrawExtreme,
    best: int | None = None,
    worst: int | None = None,
    colliding: ArrayLike | None = None,
) -> AtlasPlot:
    """The atlas at the origin (``atlas``), its best grasp right (``best``), worst left (``worst``).

    Args:
        viewer: The scene.
        points: Chart centres, (N, d).
        values: Quality index per chart, (N,) (NaN: no candidate).
        singular_below: Singularity threshold of the index.
        draw_extreme: Draws a chart's grasp (see :data:`DrawExtreme`).
        best: Chart of the best grasp (default: largest finite value).
        worst: Chart of the worst grasp (default: smallest finite value).
        colliding: Per chart, whether the grasp collides (drawn purple).
    """
    plot = show_atlas(viewer, "atlas", points, values, singular_below, best, worst, colliding)
    extents = [plot.positions_m]
    for name, chart, side in (("best", plot.best, 1.0), ("worst", plot.worst, -1.0)):
        T = translation((side * 1.6 * ATLAS_SIZE_M, 0.0, 0.0))
        extent = draw_extreme(name, chart, T)
        extents.append(extent)
        anchor = extent.mean(axis=0)
        line = np.array([plot.positions_m[chart], anchor], dtype=np.float32).T
        viewer.meshcat[f"links/{name}"].set_object(
            mg.Line(mg.PointsGeometry(line), mg.LineBasicMaterial(color=hex_color(_LINK_RGB)))
        )
    viewer.frame(np.concatenate(extents), _VIEW, aspect=_ASPECT)
    return plot


@dataclass(frozen=True)
class ChartGrasp:
    """A hand grasp at one chart of an atlas.

    Attributes:
        chart: The chart's index.
        q: Hand configuration.
        obj: The object placed as held (world frame), or None.
    """

    chart: int
    q: NDArray[np.float64]
    obj: GraspObject | None = None


def show_atlas_grasps(
    viewer: Viewer,
    hand: Hand,
    points: ArrayLike,
    values: ArrayLike,
    singular_below: float,
    best: ChartGrasp,
    worst: ChartGrasp,
    colliding: ArrayLike | None = None,
) -> AtlasPlot:
    """An atlas of a hand's grasps with its best and worst grasps (atlas paper Fig. 10).

    Each grasp is centred on its fingertip contacts beside the atlas.

    Args:
        viewer: The scene.
        hand: The hand.
        points: Chart centres, (N, d).
        values: Quality index per chart, (N,) (NaN: no candidate).
        singular_below: Singularity threshold of the index.
        best: The best grasp.
        worst: The worst grasp.
        colliding: Per chart, whether the grasp collides (drawn purple).
    """
    grasps = {"best": best, "worst": worst}

    def draw(path: str, chart: int, T_scene: NDArray[np.float64]) -> NDArray[np.float64]:
        grasp = grasps[path]
        T = T_scene @ translation(-hand.contact_state(grasp.q).points.mean(axis=0))
        show_grasp(viewer, path, hand, grasp.q, grasp.obj, T_scene=T)
        # The drawn shapes (each link's visual box, the object's vertices), not only the link
        # origins: framed on those, the palm and the object stood outside the view.
        return transform_points(T, grasp_points(hand, grasp.q, grasp.obj))

    return show_atlas_scene(
        viewer, points, values, singular_below, draw, best.chart, worst.chart, colliding
    )
