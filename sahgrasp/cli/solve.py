"""``sahgrasp solve TARGETS.json``: IK for every problem of a targets file."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from statistics import mean, median
from typing import Any

from sahgrasp.cli.common import emit_json
from sahgrasp.contacts import GraspTarget
from sahgrasp.errors import InvalidTargetError
from sahgrasp.hand import Hand, load_hand
from sahgrasp.ik import IKResult, IKSettings, Sequence, invalid_result, solve_many

__all__ = ["add_parser", "results_document", "run"]


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    p = sub.add_parser("solve", help="inverse kinematics for a targets file")
    p.add_argument("targets", type=Path, help="targets JSON (docs/formats.md)")
    p.add_argument("--hand", default=None, help="override the file's hand (sah, allegro, PATH)")
    p.add_argument("--method", choices=("auto", "paper"), default="auto")
    p.add_argument("--init", choices=("sequence", "random"), default="sequence")
    p.add_argument("--inits", type=int, default=12, help="i_max, initial configurations")
    p.add_argument("--sequence", type=Path, default=None, help="sequence file (default: shipped)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--json", default=None, metavar="OUT", help="write the results JSON to OUT")
    p.set_defaults(run=run)


def _read_problems(path: Path) -> tuple[str, list[GraspTarget | str]]:
    """The file's hand and problems; a problem that fails validation is kept as its name."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise InvalidTargetError(f"cannot read targets file {path}: {exc}") from exc
    if not isinstance(data, dict) or not isinstance(data.get("problems"), list):
        raise InvalidTargetError(f"targets file {path} needs a 'problems' list")
    problems: list[GraspTarget | str] = []
    for i, raw in enumerate(data["problems"]):
        try:
            problems.append(GraspTarget.from_dict(raw))
        except InvalidTargetError as exc:
            name = raw.get("name", f"problem-{i}") if isinstance(raw, dict) else f"problem-{i}"
            print(f"{name}: invalid input: {exc}")
            problems.append(str(name))
    return str(data.get("hand", "sah")), problems


def results_document(hand: Hand, results: list[IKResult]) -> dict[str, Any]:
    """The results file of conventions.md."""
    times = [r.time_s * 1e3 for r in results if r.reason != "invalid_input"] or [0.0]
    solved = sum(r.success for r in results)
    return {
        "hand": hand.description.name,
        "results": [r.to_dict(hand) for r in results],
        "summary": {
            "problems": len(results),
            "solved": solved,
            "success_rate": solved / len(results) if results else 0.0,
            "median_time_ms": median(times),
            "mean_time_ms": mean(times),
        },
    }


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp solve``."""
    file_hand, problems = _read_problems(args.targets)
    hand = load_hand(args.hand or file_hand)
    settings = IKSettings(method=args.method, init=args.init, max_inits=args.inits, seed=args.seed)
    sequence = Sequence.load(args.sequence) if args.sequence else None
    valid = [p for p in problems if isinstance(p, GraspTarget)]
    solved = iter(solve_many(hand, valid, settings, sequence, workers=args.workers))
    results = [next(solved) if isinstance(p, GraspTarget) else invalid_result(hand, p)
               for p in problems]  # fmt: skip
    for r in results:
        status = "solved" if r.success else f"FAILED ({r.reason})"
        print(f"{r.name}: {status}, inits {r.inits_used}, iterations {r.iterations}, "
              f"{r.time_s * 1e3:.2f} ms, max error {r.max_error_m * 1e3:.3f} mm")  # fmt: skip
    document = results_document(hand, results)
    s = document["summary"]
    print(f"solved {s['solved']}/{s['problems']}, median {s['median_time_ms']:.2f} ms")
    if args.json:
        emit_json(document, args.json)
    return 0
