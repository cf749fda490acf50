"""``sahgrasp demo``: solve grasps and write them side by side into one scene.

Without ``--targets``, the paper's example grasps, compared with the paper. With ``--targets
FILE``, every problem of a targets file (``docs/how-to/file-formats.md``), each with the object it
names
(``"object"``, per problem or the file's default) as the IK's obstacle, drawn at its placement
beside the hand. The problems are solved as ``sahgrasp solve`` solves them (the same starts,
``--init learned`` by default, and the same solutions); a problem that is invalid is reported
and left out of the scene, and the exit status is 1. Needs no server and installs nothing: the
scene is recorded in-process and written as a standalone HTML file, hands animated from the
initial configuration.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from sahgrasp.cli.common import (
    add_command,
    add_mesh_path_argument,
    check_json_inputs,
    check_outputs,
    printable,
)
from sahgrasp.experiments.arguments import add_ik_arguments, ik_settings, nonnegative_int
from sahgrasp.model.hands import DEFAULT_HAND

if TYPE_CHECKING:
    from sahgrasp.experiments.ik_examples import SolvedGrasp
    from sahgrasp.ik import IKSettings
    from sahgrasp.model.hand import Hand

__all__ = ["DEFAULT_HTML", "add_parser", "run"]

DEFAULT_HTML = "sahgrasp_demo.html"
"""Where the scene goes without ``--html`` (in the current folder)."""


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    p = add_command(sub, "demo", "solve the IK paper's example grasps, show them in one HTML scene")
    add_ik_arguments(p)
    p.set_defaults(hand=None)  # with --targets, the file's hand unless --hand names one
    hand = next(a for a in p._actions if a.dest == "hand")
    hand.help = f"{hand.help} (default: {DEFAULT_HAND}; with --targets, the file's hand)"
    p.add_argument(
        "--init",
        choices=("learned", "sequence", "random"),
        default=None,
        help="initial configurations (default: learned with --targets, as `sahgrasp solve`; "
        "the sequence for the paper's examples, as in the paper)",
    )
    p.add_argument(
        "--seed", type=nonnegative_int, default=0, help="random seed (>= 0), as `sahgrasp solve`"
    )
    p.add_argument(
        "--targets",
        default=None,
        metavar="FILE",
        help="solve and show every problem of this targets file instead, each with its object",
    )
    add_mesh_path_argument(p)
    p.add_argument(
        "--html", default=DEFAULT_HTML, metavar="OUT", help="write the scene to this HTML file"
    )
    p.set_defaults(run=run)


def _settings(args: argparse.Namespace, init: Literal["learned", "sequence"]) -> IKSettings:
    from dataclasses import replace

    chosen: Literal["learned", "sequence", "random"] = args.init or init
    return replace(ik_settings(args), init=chosen, seed=args.seed, record_history=True)


def _solve_targets(args: argparse.Namespace) -> tuple[Hand, list[SolvedGrasp], list[str]]:
    """Solve every problem of ``--targets`` as ``sahgrasp solve`` does; invalid ones apart."""
    from tqdm import tqdm

    from sahgrasp.cli.solve import hand_inputs, solve_items
    from sahgrasp.experiments.ik_examples import SolvedGrasp
    from sahgrasp.ik.batch import solve_stream, worker_obstacle
    from sahgrasp.ik.solver import IKResult
    from sahgrasp.ik.stream import open_targets
    from sahgrasp.model.contacts import GraspTarget
    from sahgrasp.model.hand import load_hand

    targets = open_targets(args.targets, allow_outside_paths=args.allow_any_mesh_path)
    hand_name = args.hand or targets.hand
    inputs = [args.targets, *targets.files, *hand_inputs(hand_name)]
    check_outputs([args.html], inputs=inputs)
    check_json_inputs(hand_name)
    hand = load_hand(hand_name)
    check_outputs([args.html], inputs=hand_inputs(hand_name, hand))
    named: list[str] = []
    items = list(solve_items(targets.problems, [Path(args.html)], named))
    results = solve_stream(hand, items, _settings(args, "learned"), output="result")
    grasps, invalid = [], []
    for (problem, spec, key), result in zip(
        items, tqdm(results, total=len(items), desc="solving", unit="problem", disable=None),
        strict=True,
    ):  # fmt: skip
        assert isinstance(result, IKResult)
        obj = None if spec is None else worker_obstacle(spec, key)
        if not isinstance(problem, GraspTarget):
            invalid.append(f"{printable(problem.name)}: invalid input: {printable(problem.detail)}")
        elif isinstance(obj, str) or result.reason == "invalid_input":
            detail = obj if isinstance(obj, str) else "refused by the solver"
            invalid.append(f"{printable(problem.name)}: invalid input: {printable(detail)}")
        else:
            grasps.append(SolvedGrasp(problem.name, obj, problem, result))
    return hand, grasps, invalid


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp demo``; returns 0 if every grasp was solved, 1 otherwise."""
    if args.targets is None:
        check_outputs([args.html], inputs=[args.hand])
        check_json_inputs(args.hand)
    from tqdm import tqdm

    from sahgrasp.experiments.ik_examples import (
        EXAMPLE_NAMES,
        format_report,
        format_solved,
        show_examples,
        solve_example,
    )
    from sahgrasp.model.hand import load_hand
    from sahgrasp.viz import Viewer

    invalid: list[str] = []
    if args.targets is None:
        hand = load_hand(args.hand or DEFAULT_HAND)
        settings = _settings(args, "sequence")  # the paper's Algorithm 1: the sequence's starts
        names = tqdm(EXAMPLE_NAMES, desc="solving", unit="grasp", disable=None)
        examples = [solve_example(hand, name, settings) for name in names]
        print(format_report(examples))
        print("(paper: Claret & Suárez, Section 4.1, d_min = 1.5 mm; times are ours)")
        grasps: list[SolvedGrasp] = list(examples)
    else:
        hand, grasps, invalid = _solve_targets(args)
        if grasps:
            print(format_solved(grasps))
        for line in invalid:
            print(line)
    if not grasps:
        print(f"no valid problem to show: {args.html} not written")
        return 1
    with Viewer(title="sahgrasp demo") as viewer:
        show_examples(viewer, hand, grasps, facing=args.targets is None)
        out = viewer.save_html(args.html)
    print(f"wrote {out}: {len(grasps)} grasps side by side (open it in a web browser)")
    return 0 if not invalid and all(g.result.success for g in grasps) else 1
