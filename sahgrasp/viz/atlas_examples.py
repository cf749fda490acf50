"""The grasp optimisations of atlas-grasp-optimization Section V: run, report, show.

The planar three-finger hand (Figs. 8-9, ``sahgrasp.planar.optimize_planar``) and the SAH holding a
can (Fig. 10a) or an oil bottle (Fig. 10b, ``sahgrasp.optimization.run_experiment``). Each run is
reported beside the paper's figures and drawn as the paper's figures draw it: the atlas's chart
centres coloured by the quality index, the best grasp and the worst one. The SAH runs also report
and draw (purple) the chart centres where the hand collides with itself or with the object.
``examples/optimize_{planar,can,bottle}.py`` wrap :func:`run_planar_example` and
:func:`run_optimize_example`.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from sahgrasp.atlas import Atlas
from sahgrasp.objects import load_object
from sahgrasp.optimization import GraspOptimizationResult, run_experiment
from sahgrasp.planar import PlanarHand, PlanarResult, make_planar_problem, optimize_planar
from sahgrasp.quality import INDICES, SINGULAR_THRESHOLDS
from sahgrasp.viz.atlas_view import AtlasPlot, ChartGrasp, show_atlas_grasps, show_atlas_scene
from sahgrasp.viz.planar_view import show_planar_grasp, upright
from sahgrasp.viz.present import add_html_argument, present
from sahgrasp.viz.viewer import Viewer, translation

__all__ = [
    "PAPER_ATLAS_REPORT",
    "AtlasFigures",
    "AtlasReport",
    "add_atlas_arguments",
    "collision_notes",
    "format_atlas_report",
    "planar_drawing",
    "run_optimize_example",
    "run_planar_example",
    "show_optimization",
    "show_planar_optimization",
]


class AtlasReport(NamedTuple):
    """What the atlas paper reports for an experiment (None: not reported).

    Attributes:
        figure: The figure showing it.
        charts: Number of charts of the atlas.
        n: Number of variables of F.
        t: Dimension of F.
        k: Dimension of the explored set R.
        r: Chart radius.
        epsilon: Threshold of Eqs. (17)-(18).
        atlas_seconds: Atlas time [s].
        quality_seconds: Quality-index time [s].
        total_seconds: Whole optimisation time [s].
    """

    figure: str
    charts: int
    n: int | None
    t: int
    k: int
    r: float
    epsilon: float
    atlas_seconds: float | None
    quality_seconds: float | None
    total_seconds: float


PAPER_ATLAS_REPORT: dict[str, AtlasReport] = {
    "planar": AtlasReport("Fig. 9", 750, None, 3, 2, 0.125, 0.4, 0.1, 1.5, 1.6),
    "can": AtlasReport("Fig. 10a", 4800, 134, 8, 2, 1.0, 0.5, 140.0, 10.0, 150.0),
    "bottle": AtlasReport("Fig. 10b", 1400, 142, 9, 2, 1.0, 0.5, None, None, 45.0),
}
"""atlas-grasp-optimization Section V (C and Matlab on an Intel Core 2 Duo at 3 GHz)."""

_SAH_GEOMETRY = (0.1, 0.5)
"""Our chart radius and epsilon for the SAH experiments (x mixes radians and metres)."""


@dataclass(frozen=True)
class AtlasFigures:
    """Our figures of one optimisation, in the terms of the paper's report.

    Attributes:
        name: Experiment (``planar``, ``can``, ``bottle``).
        index: Quality index name.
        atlas: The atlas.
        t: Dimension of F.
        values: Index per chart (NaN: no candidate grasp).
        best: Chart of the best grasp.
        worst: Chart of the worst grasp.
        atlas_seconds: Atlas time [s].
        quality_seconds: Quality-index time [s].
        notes: Further report lines (e.g. the collision counts).
    """

    name: str
    index: str
    atlas: Atlas
    t: int
    values: NDArray[np.float64]
    best: int
    worst: int
    atlas_seconds: float
    quality_seconds: float
    notes: tuple[str, ...] = ()


def add_atlas_arguments(parser: argparse.ArgumentParser, r: float, epsilon: float) -> None:
    """Add ``--k``, ``--r``, ``--eps``, ``--index``."""
    parser.add_argument("--k", type=int, default=2, help="dimension of the relevant-grasp set")
    parser.add_argument("--r", type=float, default=r, help=f"chart radius (default {r})")
    parser.add_argument("--eps", type=float, default=epsilon, help=f"epsilon (default {epsilon})")
    parser.add_argument("--index", choices=INDICES, default="volume", help="quality index")


def _cell(value: Any) -> str:
    if value is None:
        return "-"
    return f"{value:.3g}" if isinstance(value, float) else str(value)


def format_atlas_report(figures: AtlasFigures) -> str:
    """Our atlas figures beside the paper's, then the best and worst grasps."""
    paper = PAPER_ATLAS_REPORT[figures.name]
    atlas = figures.atlas
    rows = [
        ("charts", atlas.n_charts, paper.charts),
        ("n (variables)", atlas.ambient_dim, paper.n),
        ("t = dim F", figures.t, paper.t),
        ("k = dim R", atlas.dim, paper.k),
        ("chart radius r", atlas.radius, paper.r),
        ("epsilon", atlas.epsilon, paper.epsilon),
        ("atlas time [s]", figures.atlas_seconds, paper.atlas_seconds),
        ("quality time [s]", figures.quality_seconds, paper.quality_seconds),
        ("total time [s]", figures.atlas_seconds + figures.quality_seconds, paper.total_seconds),
    ]
    singular = np.count_nonzero(figures.values < SINGULAR_THRESHOLDS[figures.index])
    lines = [
        f"{figures.name} (atlas paper Section V, {paper.figure}), index {figures.index}",
        f"{'':18}{'ours':>10}{'paper':>10}",
        *(f"{label:18}{_cell(ours):>10}{_cell(theirs):>10}" for label, ours, theirs in rows),
        f"atlas complete: {'yes' if atlas.complete else 'no (chart cap reached)'}; "
        f"{singular} singular, {np.count_nonzero(np.isnan(figures.values))} no candidate",
    ]
    for which, chart in (("best", figures.best), ("worst", figures.worst)):
        lines.append(f"{which} grasp: chart {chart}, {figures.index} = {figures.values[chart]:.4g}")
    return "\n".join([*lines, *figures.notes])


# ----- the SAH experiments --------------------------------------------------------------------
def collision_notes(result: GraspOptimizationResult) -> tuple[str, ...]:
    """Report lines: colliding charts, and the best grasp over all charts if it collides."""
    n = result.atlas.n_charts
    notes = [
        f"colliding charts: {int((~result.valid).sum())} of {n} "
        f"({int(result.self_collision.sum())} self, "
        f"{int(result.object_collision.sum())} hand-object); {int(result.valid.sum())} valid"
    ]
    if result.best_overall != result.best:
        value = result.all_values[result.best_overall]
        notes.append(
            f"best grasp over all charts (colliding): chart {result.best_overall}, "
            f"{result.index} = {value:.4g}"
        )
    return tuple(notes)


def _sah_figures(name: str, result: GraspOptimizationResult) -> AtlasFigures:
    return AtlasFigures(
        name, result.index, result.atlas, result.system.t, result.values, result.best,
        result.worst, result.atlas_seconds, result.quality_seconds, collision_notes(result),
    )  # fmt: skip


def show_optimization(viewer: Viewer, result: GraspOptimizationResult) -> AtlasPlot:
    """Draw an SAH optimisation: the atlas coloured by its index, best and worst grasps.

    Colliding chart centres are purple; the grasps show the free fingers as placed.
    """
    system = result.system
    name = system.patches.name

    def grasp(chart: int) -> ChartGrasp:
        T = system.object_pose(result.atlas.centres[chart])  # palm at the origin: palm = world
        obj = load_object(name, T) if result.obj is None else result.obj.placed(T)
        return ChartGrasp(chart, result.configurations[chart], obj)

    return show_atlas_grasps(
        viewer, system.hand, result.atlas.centres, result.values,
        SINGULAR_THRESHOLDS[result.index], grasp(result.best), grasp(result.worst), ~result.valid,
    )  # fmt: skip


def run_optimize_example(name: str, argv: Sequence[str] | None = None) -> int:
    """Main of ``examples/optimize_<name>.py`` (``can`` or ``bottle``)."""
    parser = argparse.ArgumentParser(
        description=f"Global grasp optimisation of the SAH holding the {name} "
        f"(atlas-grasp-optimization Section V, {PAPER_ATLAS_REPORT[name].figure})."
    )
    add_atlas_arguments(parser, *_SAH_GEOMETRY)
    parser.add_argument("--max-charts", type=int, default=20_000, help="cap on the atlas size")
    add_html_argument(parser)
    args = parser.parse_args(argv)
    result = run_experiment(
        name, k=args.k, radius=args.r, epsilon=args.eps, index=args.index,
        max_charts=args.max_charts, progress=True,
    )  # fmt: skip
    print(format_atlas_report(_sah_figures(name, result)))

    def build(viewer: Viewer) -> None:
        show_optimization(viewer, result)

    present(build, args.html, f"sahgrasp {name}")
    return 0


# ----- the planar hand ------------------------------------------------------------------------
def planar_drawing(
    hand: PlanarHand, x: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Finger chains (3, 3, 2) (anchor, joint, tip) and circle centres (3, 2) of a planar grasp.

    ``x`` is laid out as ``sahgrasp.planar`` documents it: phalanx unit vectors ``x[0:12]``,
    object position ``x[12:14]``, object orientation ``(s_o, c_o) = x[14:16]`` (Eqs. (21), (23)).
    """
    v = x[:12].reshape(3, 2, 2)
    joints = hand.anchors + hand.phalanges[:, :1] * v[:, 0]
    tips = joints + hand.phalanges[:, 1:] * v[:, 1]
    s, c = x[14], x[15]
    rotation = np.array([[c, -s], [s, c]])
    return np.stack([hand.anchors, joints, tips], axis=1), x[12:14] + hand.centres @ rotation.T


def show_planar_optimization(viewer: Viewer, result: PlanarResult, index: str) -> None:
    """Draw the planar optimisation: atlas coloured by ``index``, best and worst grasps."""
    hand = result.problem.hand
    centres = result.atlas.centres

    def draw(path: str, chart: int, T_scene: NDArray[np.float64]) -> NDArray[np.float64]:
        fingers, circles = planar_drawing(hand, centres[chart])
        T = T_scene @ translation(-upright(circles).mean(axis=0))
        return show_planar_grasp(viewer, path, fingers, circles, hand.radii, T)

    show_atlas_scene(
        viewer, centres, result.quality.index(index), SINGULAR_THRESHOLDS[index], draw,
        result.best[index].chart, result.worst[index].chart,
    )  # fmt: skip


def run_planar_example(argv: Sequence[str] | None = None) -> int:
    """Main of ``examples/optimize_planar.py``."""
    report = PAPER_ATLAS_REPORT["planar"]
    parser = argparse.ArgumentParser(
        description="Global grasp optimisation of the planar three-finger hand "
        "(atlas-grasp-optimization Section V, Figs. 8-9)."
    )
    add_atlas_arguments(parser, report.r, report.epsilon)
    add_html_argument(parser)
    args = parser.parse_args(argv)
    result = optimize_planar(make_planar_problem(args.k), args.r, args.eps, progress=True)
    figures = AtlasFigures(
        "planar", args.index, result.atlas, result.t, result.quality.index(args.index),
        result.best[args.index].chart, result.worst[args.index].chart,
        result.atlas_seconds, result.quality_seconds,
    )  # fmt: skip
    print(format_atlas_report(figures))
    present(lambda viewer: show_planar_optimization(viewer, result, args.index), args.html,
            "sahgrasp planar")  # fmt: skip
    return 0
