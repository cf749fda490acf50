"""``sahgrasp learn``: build the grasp database of the learned IK start (``init="learned"``)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from sahgrasp.cli.common import HAND_HELP, add_command, check_outputs, nonnegative_int, positive_int

__all__ = ["LEARN_DEFAULTS", "add_parser", "run"]

LEARN_DEFAULTS = {"samples": 20_000, "seed": 61803398}
"""The shipped databases' size and seed, spelled out so that ``--help`` need not import the IK."""


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    d = LEARN_DEFAULTS
    p = add_command(
        sub, "learn", "build the grasp database of the learned IK start",
        "Build a database of solved grasps keyed by the contacts' rigid-invariant features. "
        "Finished chunks are kept in FILE.parts, so an interrupted build continues when rerun.",
    )  # fmt: skip
    p.add_argument("--hand", default="sah", help=HAND_HELP)
    p.add_argument("--samples", type=positive_int, default=d["samples"], help="database entries")
    p.add_argument("--seed", type=nonnegative_int, default=d["seed"], help="seed (>= 0)")
    p.add_argument("--out", required=True, metavar="FILE", help="the .npz file to write")
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--workers", type=positive_int, default=None,
        help="local worker processes (default: one per core)",
    )  # fmt: skip
    where.add_argument(
        "--scheduler", default=None, metavar="ADDR",
        help="Dask scheduler address, e.g. tcp://host:8786",
    )  # fmt: skip
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Build (or resume building) the database."""
    from sahgrasp.hand import load_hand
    from sahgrasp.ik.learned import build_database
    from sahgrasp.parallel import check_workers
    from sahgrasp.progress import StderrProgress
    from sahgrasp.sequence.executors import open_executor

    check_outputs([args.out])
    if args.workers is not None:
        check_workers(args.workers)
    hand = load_hand(args.hand)
    start = time.perf_counter()
    with StderrProgress() as bar, open_executor(args.scheduler, args.workers) as executor:
        db = build_database(
            hand, args.samples, args.out, args.seed, executor,
            lambda done, total: bar("learn: chunks", done, total),
        )  # fmt: skip
    size_mb = Path(args.out).stat().st_size / 1e6
    print(
        f"{args.out}: {len(db.configurations)} grasps of hand {db.hand}, {size_mb:.1f} MB, "
        f"built in {time.perf_counter() - start:.1f} s"
    )
    return 0
