"""``sahgrasp atlas planar|can|bottle``: global grasp optimization on an atlas (Rosales et al.)."""

from __future__ import annotations

import argparse
from typing import Any

from sahgrasp.cli.common import (
    add_command,
    add_json_argument,
    check_outputs,
    emit_json,
    human_stream,
    image_path,
    output_file,
)
from sahgrasp.experiments.arguments import ATLAS_DEFAULTS, add_atlas_arguments, atlas_geometry

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    p = add_command(sub, "atlas", "global grasp optimization on an atlas of feasible grasps")
    p.add_argument("experiment", choices=sorted(ATLAS_DEFAULTS), help="the experiment to run")
    add_atlas_arguments(p, list(ATLAS_DEFAULTS))
    add_json_argument(p, "the summary")
    p.add_argument(
        "--plot",
        type=image_path,
        default=None,
        metavar="PNG",
        help="atlas coloured by the index, PNG (planar: Fig. 9, every index and the grasps)",
    )
    p.set_defaults(run=run)


def _summary(args: argparse.Namespace, plot: str | None) -> tuple[dict[str, Any], tuple[str, ...]]:
    """Run the experiment and write the plot to ``plot`` if given.

    Returns:
        The summary and the report lines on colliding charts.
    """
    from sahgrasp.experiments.plotting import plot_index_map, plot_planar
    from sahgrasp.experiments.report import collision_notes, summary
    from sahgrasp.experiments.setups import run_experiment
    from sahgrasp.progress import StderrProgress

    radius, epsilon = atlas_geometry(args.experiment, args)
    with StderrProgress() as progress:
        result = run_experiment(
            args.experiment, k=args.k, radius=radius, epsilon=epsilon, index=args.index,
            max_charts=args.max_charts, progress=progress, workers=args.workers,
        )  # fmt: skip
    if plot is not None and args.experiment == "planar":
        plot_planar(result, plot)
    elif plot is not None:
        title = f"{args.experiment}: {args.index} over {result.atlas.n_charts} charts"
        plot_index_map(result, plot, title)
    return summary(args.experiment, result), collision_notes(result)


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp atlas``."""
    check_outputs([args.json, args.plot])
    with output_file(args.plot) as plot:
        summary, notes = _summary(args, plot)
    out = human_stream(args.json)
    print(
        f"{args.experiment}: {summary['charts']} charts, t = {summary['t']}, k = {summary['k']}, "
        f"atlas {summary['atlas_seconds']:.2f} s, quality {summary['quality_seconds']:.2f} s",
        file=out,
    )
    if summary["stop_reason"] == "max_charts":
        print(f"  the atlas stopped at --max-charts {summary['max_charts']}: it is incomplete",
              file=out)  # fmt: skip
    for which in ("best", "worst"):
        print(f"  {which}: chart {summary[which]['chart']}, {args.index} = "
              f"{summary[which]['value']:.4g}", file=out)  # fmt: skip
    for line in notes:
        print(f"  {line}", file=out)
    if args.plot:
        print(f"wrote {args.plot}", file=out)
    if args.json:
        emit_json(summary, args.json)
    return 0
