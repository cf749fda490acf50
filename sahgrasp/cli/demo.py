"""``sahgrasp demo``: solve the paper's example grasps, compare with the paper, write one scene.

Needs no server and installs nothing: the scene is recorded in-process and written as a standalone
HTML file with every grasp side by side, hands animated from the initial configuration.
"""

from __future__ import annotations

import argparse
from typing import Any

from tqdm import tqdm

from sahgrasp.hand import load_hand
from sahgrasp.viz import (
    EXAMPLE_NAMES,
    Viewer,
    add_html_argument,
    add_ik_arguments,
    format_report,
    ik_settings,
    show_examples,
    solve_example,
)

__all__ = ["DEFAULT_HTML", "add_parser", "run"]

DEFAULT_HTML = "sahgrasp_demo.html"
"""Where the scene goes without ``--html`` (in the current folder)."""


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "demo", help="solve the paper's example grasps and write them as one HTML scene"
    )
    add_ik_arguments(p)
    add_html_argument(p, default=DEFAULT_HTML)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp demo``; returns 0 if every grasp was solved, 1 otherwise."""
    hand = load_hand(args.hand)
    settings = ik_settings(args)
    examples = [
        solve_example(hand, name, settings)
        for name in tqdm(EXAMPLE_NAMES, desc="solving", unit="grasp")
    ]
    print(format_report(examples))
    print("(paper: ik-initial-sequence Section 4.1, d_min = 1.5 mm; times are ours)")
    with Viewer(title="sahgrasp demo") as viewer:
        show_examples(viewer, hand, examples)
        out = viewer.save_html(args.html)
    print(f"wrote {out}: {len(examples)} grasps side by side (open it in a web browser)")
    return 0 if all(ex.result.success for ex in examples) else 1
