"""``sahgrasp demo``: solve the paper's example grasps, compare with the paper, write one scene.

Needs no server and installs nothing: the scene is recorded in-process and written as a standalone
HTML file with every grasp side by side, hands animated from the initial configuration.
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
    p.add_argument(
        "--html", default=DEFAULT_HTML, metavar="OUT", help="write the scene to this HTML file"
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp demo``; returns 0 if every grasp was solved, 1 otherwise."""
    check_outputs([args.html], inputs=[args.hand])
    check_json_inputs(args.hand)
    from tqdm import tqdm

    from sahgrasp.experiments.ik_examples import (
        EXAMPLE_NAMES,
        format_report,
        show_examples,
        solve_example,
    )
    from sahgrasp.hand import load_hand
    from sahgrasp.viz import Viewer

    hand = load_hand(args.hand)
    settings = ik_settings(args)
    examples = [
        solve_example(hand, name, settings)
        for name in tqdm(EXAMPLE_NAMES, desc="solving", unit="grasp")
    ]
    print(format_report(examples))
    print("(paper: Claret & Suárez, Section 4.1, d_min = 1.5 mm; times are ours)")
    with Viewer(title="sahgrasp demo") as viewer:
        show_examples(viewer, hand, examples)
        out = viewer.save_html(args.html)
    print(f"wrote {out}: {len(examples)} grasps side by side (open it in a web browser)")
    return 0 if all(ex.result.success for ex in examples) else 1
