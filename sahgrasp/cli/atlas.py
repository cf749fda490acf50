"""``sahgrasp atlas planar|can|bottle``: global grasp optimization on an atlas (Rosales et al.).

``--paper`` runs an experiment at the paper's own settings (k, r, epsilon, in the coordinates that
reproduce its atlas sizes) and prints the paper's figures beside ours. ``--checkpoint FILE`` saves
the atlas build as it goes (and on Ctrl-C); ``--resume`` goes on from that file.
"""

from __future__ import annotations

import argparse
import json
import sys
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
from sahgrasp.model.hands import DEFAULT_HAND

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    p = add_command(sub, "atlas", "global grasp optimization on an atlas of feasible grasps")
    p.add_argument(
        "experiment",
        nargs="?",
        choices=sorted(ATLAS_DEFAULTS),
        help="the paper's experiment to run (or --mesh and --start)",
    )
    add_atlas_arguments(p, list(ATLAS_DEFAULTS))
    p.add_argument(
        "--paper",
        action="store_true",
        help="the paper's settings (k = 2, or --k 3 for the bottle; r = 1, eps = 0.5 for the "
        "SAH in the paper's units, planar r = 0.125, eps = 0.4; --max-charts 250000 unless "
        "given) and its figures beside ours",
    )
    p.add_argument(
        "--checkpoint",
        default=None,
        metavar="FILE",
        help="save the atlas build to FILE (.npz) every minute and on Ctrl-C",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="go on from --checkpoint FILE (the same experiment and options)",
    )
    p.add_argument(
        "--mesh",
        default=None,
        metavar="FILE",
        help="optimize grasps of this mesh (STL, OBJ, PLY in metres) around --start's grasps",
    )
    p.add_argument(
        "--start",
        default=None,
        metavar="FILE",
        help="the starting grasps on --mesh: sahgrasp plan's JSON ('grasps') or a targets file "
        "('problems'); one atlas per connected component they reach",
    )
    add_json_argument(p, "the summary")
    p.add_argument(
        "--plot",
        type=image_path,
        default=None,
        metavar="PNG",
        help="atlas coloured by the index, PNG (planar: Fig. 9, every index and the grasps)",
    )
    # None: 20,000 charts, or with --paper enough for the paper's largest atlas (95,000).
    p.set_defaults(run=run, usage_error=p.error, on_interrupt=_interrupted, max_charts=None)


MAX_CHARTS = 20_000
"""The cap on the atlas unless ``--max-charts`` says otherwise."""
PAPER_MAX_CHARTS = 250_000
"""The cap with ``--paper``: room for the paper's bottle with k = 3 (95,000 charts)."""


def _interrupted(args: argparse.Namespace) -> str:
    if args.checkpoint:
        return f"interrupted; the atlas so far is in {args.checkpoint}: run again with --resume"
    return "interrupted"


def _paper_settings(args: argparse.Namespace) -> Any:
    """The paper's settings of the experiment at ``args.k`` (None without ``--paper``)."""
    from sahgrasp.experiments.setups import PAPER_SETTINGS

    if not args.paper:
        return None
    key = (args.experiment, args.k)
    if key not in PAPER_SETTINGS:
        known = ", ".join(f"{name} --k {k}" for name, k in sorted(PAPER_SETTINGS))
        args.usage_error(f"--paper: the paper reports no {args.experiment} atlas with k = "
                         f"{args.k}; it reports {known}")  # fmt: skip
    return PAPER_SETTINGS[key]


def _summary(
    args: argparse.Namespace, plot: str | None, geometry: tuple[float, float], paper: Any
) -> tuple[dict[str, Any], tuple[str, ...]]:
    """Run the experiment and write the plot to ``plot`` if given.

    Returns:
        The summary and the report lines on colliding charts.
    """
    from sahgrasp.atlas import AtlasCheckpoint
    from sahgrasp.core.progress import StderrProgress
    from sahgrasp.experiments.plotting import plot_index_map, plot_planar
    from sahgrasp.experiments.report import collision_notes, summary
    from sahgrasp.experiments.setups import run_experiment

    radius, epsilon = geometry
    length, unit = (None, None) if paper is None else (paper.length_scale_m, paper.unit_m)
    checkpoint = None
    if args.checkpoint:
        key = {
            "experiment": args.experiment, "k": args.k, "radius": radius, "epsilon": epsilon,
            "length_scale_m": length, "unit_m": unit, "hand": DEFAULT_HAND, "motions": "random",
        }  # fmt: skip
        checkpoint = AtlasCheckpoint(
            args.checkpoint, key=json.dumps(key, sort_keys=True), resume=args.resume
        )
    with StderrProgress() as bar:
        result = run_experiment(
            args.experiment, k=args.k, radius=radius, epsilon=epsilon, index=args.index,
            max_charts=args.max_charts or (MAX_CHARTS if paper is None else PAPER_MAX_CHARTS),
            progress=bar if sys.stderr.isatty() else None,
            workers=args.workers, length_scale_m=length, unit_m=unit, checkpoint=checkpoint,
        )  # fmt: skip
    if plot is not None and args.experiment == "planar":
        plot_planar(result, plot)
    elif plot is not None:
        title = f"{args.experiment}: {args.index} over {result.atlas.n_charts} charts"
        plot_index_map(result, plot, title)
    out = summary(args.experiment, result)
    if length is not None:
        out["coordinates"] = {"length_scale_m": length, "unit_m": unit}
    return out, collision_notes(result)


def _paper_lines(args: argparse.Namespace, summary: dict[str, Any], paper: Any) -> list[str]:
    """The paper's figures beside ours, one line per figure."""
    from sahgrasp.experiments.reference import PAPER_ATLAS_RUNS

    report = PAPER_ATLAS_RUNS[(args.experiment, args.k)]
    unit = ""
    if paper.unit_m is not None:
        turn = paper.unit_m / paper.length_scale_m
        unit = f" in units of {paper.unit_m * 1e3:g} mm (a joint turn of {turn:g} rad)"
    summary["paper"] = report._asdict()

    def show(value: Any, digits: str = "") -> str:
        if value is None:
            return "not reported"
        return f"{value:{digits}}" if digits else str(value)

    ours_variance = summary.get("retained_variance")
    paper_variance = None if report.retained_variance is None else f"> {report.retained_variance}"
    rows = [
        ("charts", show(summary["charts"]), show(report.charts)),
        ("atlas [s]", show(summary["atlas_seconds"], ".1f"), show(report.atlas_seconds)),
        ("evaluation [s]", show(summary["quality_seconds"], ".1f"), show(report.quality_seconds)),
        ("whole [s]", show(summary["atlas_seconds"] + summary["quality_seconds"], ".1f"),
         show(report.total_seconds)),
        ("t", show(summary["t"]), show(report.t)),
        ("retained variance", show(ours_variance, ".3f"), show(paper_variance)),
    ]  # fmt: skip
    lines = [
        f"{args.experiment}, the paper's settings: k = {args.k}, r = {summary['radius']:g}, "
        f"eps = {summary['epsilon']:g}{unit}",
        f"  {'':<18} {'ours':>12}  paper ({report.figure})",
    ]
    lines += [f"  {name:<18} {ours:>12}  {theirs}" for name, ours, theirs in rows]
    return lines


def _mesh_run(args: argparse.Namespace) -> int:
    """``sahgrasp atlas --mesh FILE --start FILE``: the best verified grasp of each component."""
    from sahgrasp.experiments.arguments import MESH_DEFAULTS, PAPER_RADIUS_RANGE

    if args.experiment is not None or not args.mesh or not args.start:
        args.usage_error("give an experiment (planar, can, bottle) or both --mesh FILE and "
                         "--start FILE, not both")  # fmt: skip
    if args.paper or args.checkpoint or args.resume or args.plot:
        args.usage_error("--paper, --checkpoint, --resume and --plot are for the experiments")
    low, high = PAPER_RADIUS_RANGE
    if args.r is not None and not low <= args.r <= high:
        args.usage_error(f"--r {args.r:g} is out of range for a mesh: valid {low:g}..{high:g} "
                         f"(units of {MESH_DEFAULTS['unit_m'] * 1e3:g} mm)")  # fmt: skip
    check_outputs([args.json], [args.mesh, args.start])
    return _mesh_report(args)


def _mesh_report(args: argparse.Namespace) -> int:
    from sahgrasp.core.progress import StderrProgress
    from sahgrasp.experiments.arguments import MESH_DEFAULTS
    from sahgrasp.experiments.mesh_atlas import optimize_mesh_grasps, read_starts
    from sahgrasp.model.hand import load_hand
    from sahgrasp.objects import load_mesh
    from sahgrasp.objects.smooth_surface import MeshPatch
    from sahgrasp.optimization.optimizer import OptimizationSettings

    hand = load_hand(DEFAULT_HAND)
    obj = load_mesh(args.mesh)
    starts = read_starts(args.start, hand)
    settings = OptimizationSettings(
        args.r or MESH_DEFAULTS["radius"], args.eps or MESH_DEFAULTS["epsilon"], args.index,
        max_charts=args.max_charts or MAX_CHARTS, workers=args.workers,
    )  # fmt: skip
    with StderrProgress() as bar:
        search = optimize_mesh_grasps(hand, obj, starts, settings, k=args.k,
                                      progress=bar if sys.stderr.isatty() else None)  # fmt: skip
    out = human_stream(args.json)
    components = []
    for number, c in enumerate(search.components, 1):
        atlas = c.result.atlas
        entry: dict[str, Any] = {
            "starts": list(c.starts), "labels": [starts[i].label for i in c.starts],
            "charts": atlas.n_charts, "complete": atlas.complete,
            "valid_charts": int(c.result.valid.sum()), "start_value": c.start_value,
            "best_value": c.best_value, "improved": bool(c.best_value > c.start_value),
            "regions": {
                f: {"half_width_mm": r.half_width_m * 1e3, "fit_error_mm": r.fit_error_m * 1e3}
                for f, r in c.problem.system.patches.regions.items()
                if isinstance(r, MeshPatch)
            },
        }  # fmt: skip
        line = (f"component {number} (starts {', '.join(entry['labels'])}): {atlas.n_charts} "
                f"charts, {args.index} {c.start_value:.4g} at the start")  # fmt: skip
        if c.q_world is None or c.verification is None:
            entry["best"] = None
            print(f"{line}; no chart passed the verification on the mesh", file=out)
        else:
            v, q = c.verification, c.q_world
            entry["best"] = {
                "chart": c.best_chart,
                "wrist": {"xyz": q[:3].tolist(), "quat": q[3:7].tolist()},
                "joints": hand.joint_values(q),
                "contact_params": {f: list(p) for f, p in hand.contact_parameters(q).items()
                                   if f in v.contact_distances_m},
                "contacts": [t.to_dict() for t in c.contacts],
                "verification": {
                    "ok": v.ok, "contact_distance_mm": {f: d * 1e3 for f, d in
                                                        v.contact_distances_m.items()},
                    "penetrated": v.penetrated, "self_collision": v.self_collision,
                    "within_limits": v.within_limits, "d_min_mm": v.d_min_m * 1e3,
                },
            }  # fmt: skip
            worst = max(v.contact_distances_m.values()) * 1e3
            print(f"{line} -> {c.best_value:.4g} at chart {c.best_chart}; verified on the mesh: "
                  f"contacts within {worst:.3f} mm, no link inside, no self-collision",
                  file=out)  # fmt: skip
        components.append(entry)
    for error in search.start_errors:
        if error is not None:
            print(f"  not used: {error}", file=out)
    if args.json:
        emit_json({
            "mesh": args.mesh, "start": args.start, "index": args.index, "k": args.k,
            "radius": settings.radius, "epsilon": settings.epsilon,
            "unit_m": MESH_DEFAULTS["unit_m"], "components": components,
            "start_components": list(search.start_components),
            "start_errors": list(search.start_errors),
        }, args.json)  # fmt: skip
    failed = any(e is not None for e in search.start_errors) or any(
        c["best"] is None for c in components
    )
    return 1 if failed else 0


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp atlas``."""
    if args.mesh or args.start or args.experiment is None:
        return _mesh_run(args)
    if args.resume and not args.checkpoint:
        args.usage_error("--resume needs --checkpoint FILE (the file to go on from)")
    paper = _paper_settings(args)
    defaults = None if paper is None else (paper.radius, paper.epsilon)
    try:
        geometry = atlas_geometry(args.experiment, args, defaults)
    except argparse.ArgumentTypeError as exc:
        args.usage_error(str(exc))
    check_outputs([args.json, args.plot, args.checkpoint])
    if args.plot is not None:
        from sahgrasp.core.extras import require_extra

        require_extra("plot", f"--plot {args.plot}")  # before the work, not after it
    with output_file(args.plot) as plot:
        summary, notes = _summary(args, plot, geometry, paper)
    out = human_stream(args.json)
    if paper is not None:
        for line in _paper_lines(args, summary, paper):
            print(line, file=out)
    print(
        f"{args.experiment}: {summary['charts']} charts, t = {summary['t']}, k = {summary['k']}, "
        f"atlas {summary['atlas_seconds']:.2f} s, quality {summary['quality_seconds']:.2f} s",
        file=out,
    )
    if summary["stop_reason"] == "max_charts":
        print(f"  the atlas stopped at --max-charts {summary['max_charts']}: it is incomplete",
              file=out)  # fmt: skip
    elif summary["stop_reason"] == "stalled":
        print(f"  no chart could be added to the first one: --r {summary['radius']:g} is too "
              "large or too small for this experiment", file=out)  # fmt: skip
    for which in ("best", "worst"):
        print(f"  {which}: chart {summary[which]['chart']}, {args.index} = "
              f"{summary[which]['value']:.4g}", file=out)  # fmt: skip
    for line in notes:
        print(f"  {line}", file=out)
    if args.plot:
        print(f"wrote {args.plot}", file=out)
    if args.checkpoint:
        print(f"atlas state in {args.checkpoint}", file=out)
    if args.json:
        emit_json(summary, args.json)
    return 1 if summary["stop_reason"] == "stalled" else 0
