"""The grasp optimisations of the atlas paper's Section V: run, report, show.

Rosales, Porta and Ros, "Global optimization of robotic grasps", RSS 2011: the planar three-finger
hand (Figs. 8-9) and the SAH holding a can (Fig. 10a) or an oil bottle (Fig. 10b), run by
:func:`sahgrasp.experiments.setups.run_experiment`. Each run is reported beside the paper's figures
and drawn as the paper's figures draw it: the atlas's chart centres coloured by the quality index,
the best grasp and the worst one. The SAH runs also draw (purple) the chart centres where the hand
collides with itself or with the object.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from sahgrasp.core.errors import OptimizationError
from sahgrasp.objects import load_object
from sahgrasp.optimization.grasp import HandGraspManifold
from sahgrasp.optimization.optimizer import OptimizationResult
from sahgrasp.optimization.planar import PlanarGraspProblem, PlanarHand
from sahgrasp.quality.ellipsoids import SINGULAR_THRESHOLDS
from sahgrasp.viz.atlas_view import AtlasPlot, ChartGrasp, show_atlas_grasps, show_atlas_scene
from sahgrasp.viz.planar_view import show_planar_grasp, upright
from sahgrasp.viz.viewer import Viewer, translation

__all__ = ["planar_drawing", "show_optimization"]


def planar_drawing(
    hand: PlanarHand, x: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Finger chains (3, 3, 2) (anchor, joint, tip) and circle centres (3, 2) of a planar grasp.

    ``x`` is laid out as ``sahgrasp.optimization.planar`` documents it: phalanx unit vectors
    ``x[0:12]``, object position ``x[12:14]``, object orientation ``(s_o, c_o) = x[14:16]`` (Eqs.
    (21), (23)).
    """
    v = x[:12].reshape(3, 2, 2)
    joints = hand.anchors + hand.phalanges[:, :1] * v[:, 0]
    tips = joints + hand.phalanges[:, 1:] * v[:, 1]
    s, c = x[14], x[15]
    rotation = np.array([[c, -s], [s, c]])
    return np.stack([hand.anchors, joints, tips], axis=1), x[12:14] + hand.centres @ rotation.T


def _show_planar(
    viewer: Viewer, result: OptimizationResult, problem: PlanarGraspProblem
) -> AtlasPlot:
    hand, centres = problem.hand, result.atlas.centres

    def draw(path: str, chart: int, T_scene: NDArray[np.float64]) -> NDArray[np.float64]:
        fingers, circles = planar_drawing(hand, centres[chart])
        T = T_scene @ translation(-upright(circles).mean(axis=0))
        return show_planar_grasp(viewer, path, fingers, circles, hand.radii, T)

    return show_atlas_scene(
        viewer, centres, result.values, SINGULAR_THRESHOLDS[result.index], draw, result.best,
        result.worst,
    )  # fmt: skip


def _show_sah(viewer: Viewer, result: OptimizationResult, problem: HandGraspManifold) -> AtlasPlot:
    system = problem.system

    def grasp(chart: int) -> ChartGrasp:
        x = problem.x_of(result.atlas.centres[chart])
        T = system.object_pose(x)  # palm at the origin: palm = world
        obj = problem.obj.placed(T) if problem.obj else load_object(system.patches.name, T)
        return ChartGrasp(chart, result.configurations[chart], obj)

    return show_atlas_grasps(
        viewer, system.hand, result.atlas.centres, result.values,
        SINGULAR_THRESHOLDS[result.index], grasp(result.best), grasp(result.worst), ~result.valid,
    )  # fmt: skip


def show_optimization(viewer: Viewer, result: OptimizationResult) -> AtlasPlot:
    """Draw an optimisation: the atlas coloured by its index, best (right) and worst (left) grasps.

    Colliding chart centres are purple; the SAH's grasps show the free fingers as placed.

    Raises:
        OptimizationError: The result is of a user index (no singularity threshold to colour by)
            or of a grasp manifold other than the planar hand and the SAH.
    """
    if result.index not in SINGULAR_THRESHOLDS:
        raise OptimizationError(f"cannot colour the atlas by a {result.index!r} index")
    problem = result.problem
    if isinstance(problem, PlanarGraspProblem):
        return _show_planar(viewer, result, problem)
    if isinstance(problem, HandGraspManifold):
        return _show_sah(viewer, result, problem)
    raise OptimizationError(f"no drawing for a {type(problem).__name__}")
