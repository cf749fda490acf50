"""``sahgrasp demo``: solve grasps and write them side by side into one scene.

Without ``--targets``, the paper's example grasps, compared with the paper. With ``--targets
FILE``, every problem of a targets file (``docs/formats.md``), each with the object it names
(``"object"``, per problem or the file's default) as the IK's obstacle, drawn at its placement
beside the hand. Needs no server and installs nothing: the scene is recorded in-process and
written as a standalone HTML file, hands animated from the initial configuration.
"""

from __future__ import annotations

import argparse
from typing import Any

from sahgrasp.cli.common import add_command, check_json_inputs, check_outputs
from sahgrasp.experiments.arguments import add_ik_arguments, ik_settings

__all__ = ["DEFAULT_HTML", "add_parser", "run"]

DEFAULT_HTML = "sahgrasp_demo.html"
"""Where the scene goes without ``--html`` (in the current folder)."""


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    p = add_command(sub, "demo", "solve the IK paper's example grasps, show them in one HTML scene")
    add_ik_arguments(p)
    p.set_defaults(hand=None)  # with --targets, the file's hand unless --hand names one
    hand = next(a for a in p._actions if a.dest == "hand")
    hand.help = f"{hand.help} (default: sah; with --targets, the file's hand)"
    p.add_argument(
        "--targets",
        default=None,
        metavar="FILE",
        help="solve and show every problem of this targets file instead, each with its object",
    )
    p.add_argument(
        "--html", default=DEFAULT_HTML, metavar="OUT", help="write the scene to this HTML file"
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp demo``; returns 0 if every grasp was solved, 1 otherwise."""
    check_outputs([args.html], inputs=[args.hand, args.targets])
    check_json_inputs(args.hand)
    from tqdm import tqdm

    from sahgrasp.experiments.ik_examples import (
        EXAMPLE_NAMES,
        SolvedGrasp,
        format_report,
        format_solved,
        show_examples,
        solve_example,
        solve_problems,
    )
    from sahgrasp.hand import load_hand
    from sahgrasp.viz import Viewer

    settings = ik_settings(args)
    grasps: list[SolvedGrasp]
    if args.targets is None:
        hand = load_hand(args.hand or "sah")
        examples = [
            solve_example(hand, name, settings)
            for name in tqdm(EXAMPLE_NAMES, desc="solving", unit="grasp")
        ]
        print(format_report(examples))
        print("(paper: Claret & Suárez, Section 4.1, d_min = 1.5 mm; times are ours)")
        grasps = list(examples)
    else:
        from sahgrasp.contacts import load_targets

        targets = load_targets(args.targets)
        hand = load_hand(args.hand or targets.hand)
        problems = tqdm(targets.problems, desc="solving", unit="problem")
        grasps = solve_problems(hand, problems, settings)
        print(format_solved(grasps))
    with Viewer(title="sahgrasp demo") as viewer:
        show_examples(viewer, hand, grasps, facing=args.targets is None)
        out = viewer.save_html(args.html)
    print(f"wrote {out}: {len(grasps)} grasps side by side (open it in a web browser)")
    return 0 if all(g.result.success for g in grasps) else 1
