"""``sahgrasp learn``: build the grasp database of the learned IK start (``init="learned"``)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from sahgrasp.cli.common import (
    HAND_HELP,
    add_command,
    check_outputs,
    nonnegative_int,
    positive_int,
    scheduler_address,
)

__all__ = ["LEARN_DEFAULTS", "add_parser", "run"]

LEARN_DEFAULTS = {"samples": 2_500, "grasp_sets": 1_600, "seed": 61803398}
"""The shipped SAH database's sizes and seed, spelled out so that ``--help`` need not import the
IK (the Allegro hand's has no grasp entries: its reach is not known)."""


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    d = LEARN_DEFAULTS
    p = add_command(
        sub, "learn", "build the grasp database of the learned IK start",
        "Build a database of solved grasps keyed by the contacts' rigid-invariant features. "
        "Finished chunks are kept in FILE.parts, so an interrupted build continues when rerun; "
        "FILE is locked while it is built (FILE.lock), a second build of it is refused.",
    )  # fmt: skip
    p.add_argument("--hand", default="sah", help=HAND_HELP)
    p.add_argument(
        "--samples", type=positive_int, default=d["samples"],
        help="random entries (collision-free configurations)",
    )  # fmt: skip
    p.add_argument(
        "--grasps", type=nonnegative_int, default=None, metavar="SETS",
        help=f"contact sets to draw on random primitive solids (5 per solid) and solve: the "
        f"grasp entries (default: {d['grasp_sets']} for the SAH, 0 for a hand whose reach is "
        "not known)",
    )  # fmt: skip
    p.add_argument("--seed", type=nonnegative_int, default=d["seed"], help="seed (>= 0)")
    p.add_argument("--out", required=True, metavar="FILE", help="the .npz file to write")
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--workers", type=positive_int, default=None,
        help="local worker processes (default: one per core)",
    )  # fmt: skip
    where.add_argument(
        "--scheduler", type=scheduler_address, default=None, metavar="ADDR",
        help="Dask scheduler address, tcp://HOST:PORT or HOST:PORT",
    )  # fmt: skip
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Build (or resume building) the database."""
    from sahgrasp.cli.solve import hand_inputs
    from sahgrasp.core.executors import open_executor
    from sahgrasp.core.fileio import check_output_path, side_files
    from sahgrasp.core.parallel import check_workers
    from sahgrasp.core.progress import StderrProgress
    from sahgrasp.ik.learning import build_database, primitive_chunks
    from sahgrasp.model.hand import load_hand

    # Every file the run reads is an input: the hand description and its URDF. The database's
    # side files (FILE.parts, FILE.lock) are outputs too.
    side = side_files(args.out, (".parts", ".lock"))
    check_output_path(args.out, hand_inputs(args.hand), side=side)
    check_outputs([args.out])
    if args.workers is not None:
        check_workers(args.workers)
    hand = load_hand(args.hand)
    check_output_path(args.out, hand_inputs(args.hand, hand), side=side)
    grasp_sets = args.grasps
    if grasp_sets is None:
        grasp_sets = LEARN_DEFAULTS["grasp_sets"] if hand.description.name == "sah" else 0
    solids = sum(primitive_chunks(grasp_sets))
    start = time.perf_counter()
    with StderrProgress() as bar, open_executor(args.scheduler, args.workers) as executor:
        db = build_database(
            hand, args.samples, args.out, args.seed, executor,
            lambda done, total: bar("learn: chunks", done, total), grasp_sets,
        )  # fmt: skip
    size_mb = Path(args.out).stat().st_size / 1e6
    print(
        f"{args.out}: {len(db.configurations)} entries of hand {db.hand} ({db.grasp_entries} "
        f"solved grasps of contact sets on {solids} primitive solids), {size_mb:.1f} MB, "
        f"built in {time.perf_counter() - start:.1f} s"
    )
    return 0
