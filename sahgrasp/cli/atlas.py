"""``sahgrasp atlas planar|can|bottle``: global grasp optimization on an atlas (atlas paper)."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from sahgrasp.cli.common import emit_json
from sahgrasp.quality import INDICES

__all__ = ["add_parser", "plot_index_map", "run"]

DEFAULTS = {"planar": (0.125, 0.4), "can": (0.1, 0.5), "bottle": (0.1, 0.5)}
"""Per experiment: chart radius r and epsilon (planar: the paper's values)."""


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    p = sub.add_parser("atlas", help="global grasp optimization on an atlas of feasible grasps")
    p.add_argument("experiment", choices=sorted(DEFAULTS))
    p.add_argument("--k", type=int, default=2, help="dimension of the relevant-grasp set")
    p.add_argument("--r", type=float, default=None, help="chart radius (default per experiment)")
    p.add_argument("--eps", type=float, default=None, help="epsilon of Eqs. (17)-(18)")
    p.add_argument("--index", choices=INDICES, default="volume")
    p.add_argument("--max-charts", type=int, default=20_000)
    p.add_argument("--json", default=None, metavar="OUT", help="write the summary JSON to OUT")
    p.add_argument("--plot", default=None, metavar="PNG", help="atlas coloured by the index")
    p.set_defaults(run=run)


def plot_index_map(
    centres: np.ndarray, values: np.ndarray, singular: float, path: str, title: str
) -> None:
    """Chart centres on their two main directions, green (large) to red (small), black singular."""
    import matplotlib

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


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp atlas``."""
    r, eps = DEFAULTS[args.experiment]
    r, eps = args.r or r, args.eps or eps
    if args.experiment == "planar":
        from sahgrasp.planar import run_planar

        summary = run_planar(k=args.k, r=r, eps=eps, index=args.index, plot_out=args.plot)
    else:
        from sahgrasp.optimization import run_experiment
        from sahgrasp.quality import SINGULAR_THRESHOLDS

        result = run_experiment(
            args.experiment, k=args.k, radius=r, epsilon=eps,
            index=args.index, max_charts=args.max_charts, progress=True,
        )  # fmt: skip
        summary = result.summary()
        if args.plot:
            title = f"{args.experiment}: {args.index} over {result.atlas.n_charts} charts"
            plot_index_map(result.atlas.centres, result.values,
                           SINGULAR_THRESHOLDS[args.index], args.plot, title)  # fmt: skip
    print(
        f"{args.experiment}: {summary['charts']} charts, t = {summary['t']}, k = {summary['k']}, "
        f"atlas {summary['atlas_seconds']:.2f} s, quality {summary['quality_seconds']:.2f} s"
    )
    for which in ("best", "worst"):
        print(f"  {which}: chart {summary[which]['chart']}, {args.index} = "
              f"{summary[which]['value']:.4g}")  # fmt: skip
    if args.json:
        emit_json(summary, args.json)
    return 0
