"""Global grasp optimisation of the planar three-finger hand (Rosales, Porta & Ros, RSS 2011).

The paper's Figs. 8-9: the grasp manifold of the planar hand holding three circles, an atlas of
its relevant grasps (k = 2, r = 0.125, epsilon = 0.4), the volume of the manipulability ellipsoid
at every chart centre. Print the atlas beside the paper's and the best and worst grasps, and show
the atlas coloured by the index with the best grasp on its right and the worst on its left (a
finger fully extended: the singularity the paper describes). Run
`python examples/optimize_planar.py` to open the live viewer, or add `--html OUT` to write the
scene.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import cast

import numpy as np
from numpy.typing import NDArray

from sahgrasp.experiments.arguments import add_atlas_arguments, add_html_argument
from sahgrasp.experiments.atlas_examples import planar_drawing
from sahgrasp.experiments.reference import PAPER_ATLAS_REPORT
from sahgrasp.experiments.report import result_lines
from sahgrasp.experiments.setups import run_experiment
from sahgrasp.optimization.planar import PlanarGraspProblem
from sahgrasp.quality.ellipsoids import SINGULAR_THRESHOLDS
from sahgrasp.viz import Viewer, present, show_atlas_scene, translation
from sahgrasp.viz.planar_view import show_planar_grasp, upright


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_atlas_arguments(parser, ["planar"], workers=False)  # --k, --r, --eps, --index, --max-charts
    add_html_argument(parser)  # --html OUT
    args = parser.parse_args(argv)

    result = run_experiment(
        "planar", k=args.k, radius=args.r, epsilon=args.eps, index=args.index,
        max_charts=args.max_charts,
    )  # fmt: skip
    hand = cast(PlanarGraspProblem, result.problem).hand
    atlas, paper = result.atlas, PAPER_ATLAS_REPORT["planar"]
    print(f"planar: {atlas.n_charts} charts (paper about {paper.charts}), r = {atlas.radius:g}, "
          f"epsilon = {atlas.epsilon:g}, k = {atlas.dim}")  # fmt: skip
    print("\n".join(result_lines(result)))

    def draw(viewer: Viewer, path: str, chart: int, T: NDArray[np.float64]) -> NDArray[np.float64]:
        fingers, circles = planar_drawing(hand, atlas.centres[chart])  # drawn in the x-z plane
        T_centred = T @ translation(-upright(circles).mean(axis=0))
        return show_planar_grasp(viewer, path, fingers, circles, hand.radii, T_centred)

    def build(viewer: Viewer) -> None:
        show_atlas_scene(
            viewer, atlas.centres, result.values, SINGULAR_THRESHOLDS[result.index],
            lambda path, chart, T: draw(viewer, path, chart, T), result.best, result.worst,
        )  # fmt: skip

    present(build, args.html, "sahgrasp planar")
    return 0


if __name__ == "__main__":
    sys.exit(main())
