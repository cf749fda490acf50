"""``sahgrasp atlas planar|can|bottle``: global grasp optimization on an atlas (Rosales et al.)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from sahgrasp.cli.common import (
    add_command,
    add_json_argument,
    check_outputs,
    emit_json,
    human_stream,
    output_file,
    positive_float,
    positive_int,
)

if TYPE_CHECKING:
    import numpy as np

__all__ = ["DEFAULTS", "INDEX_CHOICES", "add_parser", "plot_index_map", "run"]

DEFAULTS = {"planar": (0.125, 0.4), "can": (0.1, 0.5), "bottle": (0.1, 0.5)}
"""Per experiment: chart radius r and epsilon (planar: the paper's values)."""

INDEX_CHOICES = ("inverse_condition", "volume", "min_semiaxis")
"""``sahgrasp.quality.INDICES``, spelled out so that ``--help`` need not import numpy."""


def _per_experiment(i: int) -> str:
    return ", ".join(f"{name} {values[i]:g}" for name, values in DEFAULTS.items())


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    p = add_command(sub, "atlas", "global grasp optimization on an atlas of feasible grasps")
    p.add_argument("experiment", choices=sorted(DEFAULTS), help="the experiment to run")
    p.add_argument("--k", type=positive_int, default=2, help="dimension of the relevant-grasp set")
    p.add_argument(
        "--r",
        type=positive_float,
        default=None,
        help=f"chart radius > 0 (default per experiment: {_per_experiment(0)})",
    )
    p.add_argument(
        "--eps",
        type=positive_float,
        default=None,
        help=f"epsilon > 0 of Eqs. (17)-(18) (default: {_per_experiment(1)})",
    )
    p.add_argument(
        "--index", choices=INDEX_CHOICES, default="volume", help="quality index to optimize"
    )
    p.add_argument(
        "--max-charts",
        type=positive_int,
        default=20_000,
        help="stop the atlas at this many charts (can and bottle)",
    )
    add_json_argument(p, "the summary")
    p.add_argument("--plot", default=None, metavar="PNG", help="atlas coloured by the index, PNG")
    p.set_defaults(run=run)


def plot_index_map(
    centres: np.ndarray, values: np.ndarray, singular: float, path: str, title: str
) -> None:
    """Chart centres on their two main directions, green (large) to red (small), black singular."""
    import matplotlib
    import numpy as np

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    centred = centres - centres.mean(axis=0)
    axes = np.linalg.svd(centred, full_matrices=False)[2][:2].T
    xy = centred @ axes
    fig, ax = plt.subplots(figsize=(6, 5))
    ok = np.isfinite(values) & (values >= singular)
    points = ax.scatter(xy[ok, 0], xy[ok, 1], c=values[ok], cmap="RdYlGn", s=12)
    ax.scatter(xy[~ok, 0], xy[~ok, 1], c="black", s=12, label="singular or invalid")
    fig.colorbar(points, ax=ax)
    ax.set(title=title, xlabel="main direction 1", ylabel="main direction 2")
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _summary(args: argparse.Namespace, r: float, eps: float, plot: str | None) -> dict[str, Any]:
    """Run the experiment; write the plot to ``plot`` if given."""
    if args.experiment == "planar":
        from sahgrasp.planar import run_planar

        return run_planar(k=args.k, r=r, eps=eps, index=args.index, plot_out=plot)
    from sahgrasp.optimization import run_experiment
    from sahgrasp.quality import SINGULAR_THRESHOLDS

    result = run_experiment(
        args.experiment, k=args.k, radius=r, epsilon=eps,
        index=args.index, max_charts=args.max_charts, progress=True,
    )  # fmt: skip
    if plot is not None:
        title = f"{args.experiment}: {args.index} over {result.atlas.n_charts} charts"
        plot_index_map(result.atlas.centres, result.values,
                       SINGULAR_THRESHOLDS[args.index], plot, title)  # fmt: skip
    return result.summary()


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp atlas``."""
    check_outputs([args.json, args.plot])
    r, eps = DEFAULTS[args.experiment]
    r = r if args.r is None else args.r
    eps = eps if args.eps is None else args.eps
    with output_file(args.plot) as plot:
        summary = _summary(args, r, eps, plot)
    out = human_stream(args.json)
    print(
        f"{args.experiment}: {summary['charts']} charts, t = {summary['t']}, k = {summary['k']}, "
        f"atlas {summary['atlas_seconds']:.2f} s, quality {summary['quality_seconds']:.2f} s",
        file=out,
    )
    for which in ("best", "worst"):
        print(f"  {which}: chart {summary[which]['chart']}, {args.index} = "
              f"{summary[which]['value']:.4g}", file=out)  # fmt: skip
    if args.plot:
        print(f"wrote {args.plot}", file=out)
    if args.json:
        emit_json(summary, args.json)
    return 0
