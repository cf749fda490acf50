"""``sahgrasp check [TARGETS] RESULTS``: does each grasp hold? The physics test in MuJoCo."""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path
from typing import Any

from sahgrasp.cli.common import (
    HAND_OVERRIDE_HELP,
    add_command,
    add_json_argument,
    add_mesh_path_argument,
    check_json_inputs,
    check_outputs,
    emit_json,
    human_stream,
    positive_float,
    positive_int,
    printable,
)
from sahgrasp.model.hands import DEFAULT_HAND

__all__ = ["add_parser", "run"]

_DESCRIPTION = (
    'Hold-test every solved grasp in MuJoCo (needs pip install "sahgrasp[sim]"): the wrist '
    "fixed at the grasp, the contact fingers squeeze, then a pull of the object's weight in "
    "each of +-x, +-y, +-z for 1 s; a grasp holds if the object moves less than 20 mm and turns "
    "less than 15 deg every time (BODex's 50 mm / 15 deg verdict is reported too). Give the "
    "targets file and the results of 'sahgrasp solve', or a planner's results (which name their "
    "object) alone. Exit status 0: every grasp holds; 1: some do not, or some were not solved; "
    "2: bad input. docs/methods/physics.md describes the model and every setting."
)


def _nonnegative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0.0 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text!r}")
    return value


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    p = add_command(sub, "check", "physics hold test of solved grasps (MuJoCo)", _DESCRIPTION)
    p.add_argument(
        "targets", type=Path, metavar="TARGETS",
        help="the targets file the results were solved from (JSON or .jsonl); alone: a "
        "planner's results, which name their object",
    )  # fmt: skip
    p.add_argument("results", type=Path, nargs="?", metavar="RESULTS",
                   help="the results of 'sahgrasp solve' (JSON or .jsonl)")  # fmt: skip
    p.add_argument("--hand", default=None, help=HAND_OVERRIDE_HELP)
    p.add_argument("--friction", type=_nonnegative_float, default=0.6,
                   help="Coulomb friction coefficient of the hand-object contacts")  # fmt: skip
    squeeze = p.add_mutually_exclusive_group()
    squeeze.add_argument("--squeeze", type=positive_float, default=None, metavar="N",
                         help="mean normal force per contact finger [N] (default 10)")  # fmt: skip
    squeeze.add_argument("--light", action="store_true",
                         help="the light squeeze, 1 N per contact finger")  # fmt: skip
    mass = p.add_mutually_exclusive_group()
    mass.add_argument("--mass-kg", type=positive_float, default=None,
                      help="object mass [kg] (default: from --density)")  # fmt: skip
    mass.add_argument("--density", type=positive_float, default=1000.0,
                      help="object density [kg/m^3]")  # fmt: skip
    p.add_argument("--soft-friction", action="store_true",
                   help="MuJoCo's soft friction that creeps under a load (impratio 1, no no-slip "
                   "solver, 10 ms steps): a stricter verdict than the default "
                   "(docs/methods/physics.md)")  # fmt: skip
    add_mesh_path_argument(p)
    p.add_argument("--workers", type=positive_int, default=1, help="worker processes (>= 1)")
    add_json_argument(p, "every grasp's verdicts, per-direction motion and the summary")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=run)


def _settings(args: argparse.Namespace) -> Any:
    from sahgrasp.sim import LIGHT_SQUEEZE_N, HoldSettings, soft_friction

    settings = HoldSettings(friction=args.friction, density_kg_m3=args.density,
                            mass_kg=args.mass_kg)  # fmt: skip
    if args.soft_friction:
        settings = soft_friction(settings)
    if args.light or args.squeeze is not None:
        squeeze = LIGHT_SQUEEZE_N if args.light else args.squeeze
        settings = dataclasses.replace(settings, squeeze_n=squeeze)
    return settings


def _hand_name(args: argparse.Namespace, targets: Path | None) -> str:
    if args.hand is not None:
        return str(args.hand)
    if targets is None:
        return DEFAULT_HAND
    from sahgrasp.objects.targets import read_problems

    return read_problems(targets)[0]


def _table(grasps: list[Any], results: list[Any], summary: dict[str, Any]) -> str:
    from sahgrasp.core.tables import format_table

    rows = [
        (
            printable(name),
            str(row["checked"]),
            str(row["holds"]),
            f"{100 * row['hold_rate']:.0f}%",
            f"{100 * row['hold_rate_bodex']:.0f}%",
        )
        for name, row in summary["objects"].items()
    ]
    table = format_table(("object", "checked", "hold", "hold rate", "BODex hold rate"), rows)
    lines = [table]
    for g, r in zip(grasps, results, strict=True):
        if isinstance(r, str):
            lines.append(f"{printable(g.name)}: not checked, {printable(r)}")
        elif not r.holds:
            lines.append(f"{printable(g.name)}: does not hold ({r.reason}): {r.detail}")
    return "\n".join(lines)


def _named_inputs(targets: Path | None, results: Path, allow: bool) -> list[str]:
    """The mesh files the targets file or a planner's results name: inputs too."""
    from sahgrasp.core.errors import SahGraspError
    from sahgrasp.objects.targets import object_spec, read_problems
    from sahgrasp.sim.batch import ResultsFileError, read_documents

    specs = []
    try:
        if targets is not None:
            specs = [
                getattr(p, "object_spec", None)
                for p in read_problems(targets, allow_outside_paths=allow)[1]
            ]
        else:
            specs = [
                object_spec(
                    {k: v for k, v in document["object"].items() if k != "repairs"}
                    if isinstance(document.get("object"), dict)
                    else document.get("object"),
                    results.parent,
                    allow_outside_paths=allow,
                )
                for document in read_documents(results)
                if isinstance(document, dict) and "grasps" in document
            ]
    except (SahGraspError, ResultsFileError):
        return []  # reported with its reason when the grasps are read
    return sorted({s.mesh for s in specs if s is not None and s.mesh is not None})


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp check``; 0 if every grasp holds, 1 otherwise."""
    from sahgrasp.core.extras import require_extra

    require_extra("sim", "sahgrasp check")  # before any work: one line naming the extra
    files = [args.targets] if args.results is None else [args.targets, args.results]
    targets, results_path = (None, args.targets) if args.results is None else files
    hand_name = _hand_name(args, targets)
    named = _named_inputs(targets, results_path, args.allow_any_mesh_path)
    check_outputs([args.json], inputs=[*files, hand_name, *named])
    check_json_inputs(hand_name)

    from sahgrasp.model.hand import load_hand
    from sahgrasp.sim import HoldResult
    from sahgrasp.sim.batch import check_grasps, read_grasps, summarize

    settings = _settings(args)
    started = time.perf_counter()
    hand = load_hand(hand_name)
    grasps = read_grasps(hand, results_path, targets, allow_outside_paths=args.allow_any_mesh_path)
    checkable = sum(g.q is not None and not g.skipped for g in grasps)
    bar = None
    if not args.quiet and sys.stderr.isatty() and checkable:
        from tqdm import tqdm

        bar = tqdm(total=checkable, unit="grasp", file=sys.stderr, delay=2.0, leave=False)

    def progress(done: int) -> None:
        if bar is not None:
            bar.n = done
            bar.refresh()

    try:
        results = check_grasps(hand_name, grasps, settings, args.workers, progress)
    finally:
        if bar is not None:
            bar.close()
    summary = summarize(grasps, results)
    summary["time_s"] = time.perf_counter() - started
    out = human_stream(args.json)
    print(_table(grasps, results, summary), file=out)
    rate = summary["hold_rate"]
    print(
        f"{summary['holds']}/{summary['checked']} grasps hold"
        + (f" ({100 * rate:.0f}%)" if summary["checked"] else "")
        + f", BODex {summary['holds_bodex']}/{summary['checked']}"
        + (f"; {summary['not_checked']} not checked" if summary["not_checked"] else "")
        + f"; {summary['time_s']:.1f} s",
        file=out,
    )
    if args.json is not None:
        entries = []
        for g, r in zip(grasps, results, strict=True):
            if isinstance(r, HoldResult):
                entries.append({**r.to_dict(), "checked": True})
            else:
                entries.append({"name": g.name, "checked": False, "holds": False,
                                "holds_bodex": False, "detail": r})  # fmt: skip
        document = {
            "hand": hand_name,
            "settings": dataclasses.asdict(settings),
            "results": entries,
            "summary": summary,
        }
        emit_json(document, args.json)
    all_hold = summary["checked"] == len(grasps) and summary["holds"] == len(grasps)
    return 0 if all_hold else 1
