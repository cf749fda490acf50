"""``sahgrasp solve TARGETS.json``: IK for every problem of a targets file."""

from __future__ import annotations

import argparse
from pathlib import Path
from statistics import mean, median
from typing import TYPE_CHECKING, Any

from sahgrasp.cli.common import (
    HAND_OVERRIDE_HELP,
    INITS_HELP,
    MAX_INITS,
    METHOD_HELP,
    add_command,
    add_json_argument,
    check_json_inputs,
    check_outputs,
    emit_json,
    human_stream,
    int_in_range,
    nonnegative_int,
    positive_int,
    printable,
)

if TYPE_CHECKING:
    from collections.abc import Sequence

    from sahgrasp.contacts import GraspTarget, InvalidProblem

__all__ = ["add_parser", "results_document", "run"]

INVALID_ENTRY: dict[str, Any] = {
    "success": False, "reason": "invalid_input", "inits_used": 0, "iterations": 0, "time_ms": 0.0,
    "max_position_error_mm": None, "max_centre_error_mm": None, "collision_free": None,
    "wrist": None, "joints": None, "contact_params": None,
}  # fmt: skip
"""The results entry of a problem refused as invalid input, besides its name and detail."""


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    p = add_command(sub, "solve", "inverse kinematics for every problem of a targets file")
    p.add_argument("targets", type=Path, help="targets JSON file (format: docs/formats.md)")
    p.add_argument("--hand", default=None, help=HAND_OVERRIDE_HELP)
    p.add_argument("--method", choices=("auto", "paper"), default="auto", help=METHOD_HELP)
    p.add_argument(
        "--init",
        choices=("sequence", "random"),
        default="sequence",
        help="initial configurations: the searched sequence of poses, or random ones",
    )
    p.add_argument("--inits", type=int_in_range(1, MAX_INITS), default=12, help=INITS_HELP)
    p.add_argument(
        "--sequence",
        type=Path,
        default=None,
        help="sequence file of initial poses (default: the one shipped for the hand)",
    )
    p.add_argument("--seed", type=nonnegative_int, default=0, help="random seed (>= 0)")
    p.add_argument("--workers", type=positive_int, default=1, help="worker processes (>= 1)")
    add_json_argument(p, "the results")
    p.set_defaults(run=run)


def _check_fingers(
    problem: GraspTarget | InvalidProblem, fingers: Sequence[str]
) -> GraspTarget | InvalidProblem:
    """``problem``, or an :class:`InvalidProblem` if its fingers are not the hand's."""
    from sahgrasp.contacts import GraspTarget, InvalidProblem
    from sahgrasp.errors import InvalidTargetError

    if isinstance(problem, GraspTarget):
        try:
            problem.check_fingers(fingers)
        except InvalidTargetError as exc:
            return InvalidProblem(problem.name, str(exc))
    return problem


def _line(entry: dict[str, Any]) -> str:
    """One problem's line for the terminal."""
    name = printable(entry["name"])
    if entry["reason"] == "invalid_input":
        return f"{name}: invalid input: {printable(entry.get('detail', 'refused by the solver'))}"
    status = "solved" if entry["success"] else f"FAILED ({entry['reason']})"
    error_mm = max(entry["max_position_error_mm"], entry["max_centre_error_mm"])
    return (f"{name}: {status}, inits {entry['inits_used']}, iterations {entry['iterations']}, "
            f"{entry['time_ms']:.2f} ms, max error {error_mm:.3f} mm")  # fmt: skip


def results_document(hand_name: str, entries: list[dict[str, Any]]) -> dict[str, Any]:
    """The results file (``docs/formats.md``) from the results entries, in problem order."""
    times = [e["time_ms"] for e in entries if e["reason"] != "invalid_input"] or [0.0]
    solved = sum(e["success"] for e in entries)
    return {
        "hand": hand_name,
        "results": entries,
        "summary": {
            "problems": len(entries),
            "solved": solved,
            "invalid": sum(e["reason"] == "invalid_input" for e in entries),
            "success_rate": solved / len(entries) if entries else 0.0,
            "median_time_ms": median(times),
            "mean_time_ms": mean(times),
        },
    }


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp solve``; 0 if every problem was solved, 1 otherwise."""
    from sahgrasp.contacts import GraspTarget, read_problems

    file_hand, problems = read_problems(args.targets)
    hand_name = args.hand or file_hand
    check_outputs([args.json], inputs=[args.targets, args.sequence, hand_name])
    check_json_inputs(hand_name, args.sequence)

    from sahgrasp.hand import load_hand
    from sahgrasp.ik import IKSettings, Sequence, solve_many

    hand = load_hand(hand_name)
    settings = IKSettings(method=args.method, init=args.init, max_inits=args.inits, seed=args.seed)
    sequence = Sequence.load(args.sequence) if args.sequence else None
    problems = [_check_fingers(p, hand.fingers) for p in problems]
    targets = [p for p in problems if isinstance(p, GraspTarget)]
    solved = iter(solve_many(hand, targets, settings, sequence, workers=args.workers))
    entries = [
        next(solved).to_dict(hand) if isinstance(p, GraspTarget)
        else {"name": p.name, **INVALID_ENTRY, "detail": p.detail}
        for p in problems
    ]  # fmt: skip
    out = human_stream(args.json)
    for entry in entries:
        print(_line(entry), file=out)
    document = results_document(hand.description.name, entries)
    s = document["summary"]
    print(f"solved {s['solved']}/{s['problems']} ({s['invalid']} invalid input), "
          f"median {s['median_time_ms']:.2f} ms", file=out)  # fmt: skip
    if args.json:
        emit_json(document, args.json)
    return 0 if s["solved"] == s["problems"] else 1
