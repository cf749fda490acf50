"""Global grasp optimisation of the SAH holding a can or an oil bottle (Rosales, Porta & Ros, 2011).

The can is the paper's Fig. 10a, the bottle its Fig. 10b. Build the experiment (the IK's first
grasp of the object, the grasp manifold with its principal
motions, an atlas of the relevant grasps, k = 2), evaluate the volume of the manipulability
ellipsoid at every chart centre, print the atlas beside the paper's and the best and worst grasps,
and show the atlas coloured by the index with the best grasp on its right, the worst on its left.
Run `python examples/optimize_sah.py can` (or `bottle`) to open the live viewer, or add
`--html OUT` to write the scene; `--max-charts 200` gives a quick, partial atlas.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import cast

from sahgrasp.core.errors import SahGraspError
from sahgrasp.core.progress import StderrProgress
from sahgrasp.experiments.arguments import add_atlas_arguments, add_html_argument, atlas_geometry
from sahgrasp.experiments.reference import PAPER_ATLAS_REPORT
from sahgrasp.experiments.report import result_lines
from sahgrasp.experiments.setups import run_experiment
from sahgrasp.optimization.grasp import HandGraspManifold
from sahgrasp.quality.ellipsoids import SINGULAR_THRESHOLDS
from sahgrasp.viz import ChartGrasp, Viewer, present, show_atlas_grasps

EXPERIMENTS = ("can", "bottle")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("experiment", choices=EXPERIMENTS, help="the object held")
    add_atlas_arguments(parser, EXPERIMENTS)  # --k, --r, --eps, --index, --max-charts, --workers
    add_html_argument(parser)  # --html OUT
    args = parser.parse_args(argv)
    try:
        radius, epsilon = atlas_geometry(args.experiment, args)  # each object's own defaults
    except argparse.ArgumentTypeError as exc:  # --r out of the experiment's range
        parser.error(str(exc))

    try:
        with StderrProgress() as progress:
            result = run_experiment(
                args.experiment, k=args.k, radius=radius, epsilon=epsilon, index=args.index,
                max_charts=args.max_charts, progress=progress, workers=args.workers,
            )  # fmt: skip
    except SahGraspError as exc:  # e.g. a partial atlas with no collision-free chart
        print(f"{parser.prog}: {exc}", file=sys.stderr)
        return 1
    problem = cast(HandGraspManifold, result.problem)  # the SAH experiments' manifold
    atlas, paper = result.atlas, PAPER_ATLAS_REPORT[args.experiment]
    print(f"{args.experiment}: {atlas.n_charts} charts (paper {paper.charts}), "
          f"n = {atlas.ambient_dim} (paper {paper.n}), t = {problem.t} (paper {paper.t}), "
          f"k = {atlas.dim}")  # fmt: skip
    print("\n".join(result_lines(result)))

    def grasp(chart: int) -> ChartGrasp:
        x = problem.x_of(atlas.centres[chart])  # the chart centre in the system's variables
        obj = problem.obj.placed(problem.system.object_pose(x)) if problem.obj else None
        return ChartGrasp(chart, result.configurations[chart], obj)

    def build(viewer: Viewer) -> None:
        show_atlas_grasps(
            viewer, problem.system.hand, atlas.centres, result.values,
            SINGULAR_THRESHOLDS[result.index], grasp(result.best), grasp(result.worst),
            colliding=~result.valid,
        )  # fmt: skip

    present(build, args.html, f"sahgrasp {args.experiment}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
