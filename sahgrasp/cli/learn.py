"""``sahgrasp learn``: build the grasp database of the learned IK start (``init="learned"``)."""

from __future__ import annotations

import argparse
import dataclasses
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
from sahgrasp.model.hands import DEFAULT_HAND, HANDS, LearnDefaults, hand_entry

__all__ = ["LEARN_DEFAULTS", "add_parser", "run"]

LEARN_DEFAULTS = dataclasses.asdict(HANDS[DEFAULT_HAND].learn)
"""The default hand's database sizes and seed (its registry entry's), read without importing the
IK so that ``--help`` stays fast. Each hand's own are in its entry
(:class:`sahgrasp.model.hands.LearnDefaults`); a hand the registry does not list gets
``LearnDefaults()`` (no grasp entries: its reach is not measured)."""


def _learn_defaults(hand: str) -> LearnDefaults:
    entry = hand_entry(hand)
    return LearnDefaults() if entry is None else entry.learn


def _per_hand(field: str) -> str:
    """``field`` of every registered hand's defaults, for the help (``sah: 1600, ...``)."""
    return ", ".join(f"{name} {getattr(entry.learn, field)}" for name, entry in HANDS.items())


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    p = add_command(
        sub, "learn", "build the grasp database of the learned IK start",
        "Build a database of solved grasps keyed by the contacts' rigid-invariant features. "
        "Finished chunks are kept in FILE.parts, so an interrupted build continues when rerun; "
        "FILE is locked while it is built (FILE.lock), a second build of it is refused.",
    )  # fmt: skip
    p.add_argument("--hand", default=DEFAULT_HAND, help=HAND_HELP)
    p.add_argument(
        "--samples", type=positive_int, default=None,
        help=f"random entries (collision-free configurations; default per hand: "
        f"{_per_hand('samples')})",
    )  # fmt: skip
    p.add_argument(
        "--grasps", type=nonnegative_int, default=None, metavar="SETS",
        help=f"contact sets to draw on random primitive solids (5 per solid) and solve: the "
        f"grasp entries (default per hand: {_per_hand('grasp_sets')}; 0 for a hand whose reach "
        "is not measured)",
    )  # fmt: skip
    p.add_argument(
        "--seed", type=nonnegative_int, default=None,
        help=f"seed (>= 0; default per hand: {_per_hand('seed')})",
    )  # fmt: skip
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
    defaults = _learn_defaults(hand.description.name)
    grasp_sets = defaults.grasp_sets if args.grasps is None else args.grasps
    samples = defaults.samples if args.samples is None else args.samples
    seed = defaults.seed if args.seed is None else args.seed
    solids = sum(primitive_chunks(grasp_sets))
    start = time.perf_counter()
    with StderrProgress() as bar, open_executor(args.scheduler, args.workers) as executor:
        db = build_database(
            hand, samples, args.out, seed, executor,
            lambda done, total: bar("learn: chunks", done, total), grasp_sets,
        )  # fmt: skip
    size_mb = Path(args.out).stat().st_size / 1e6
    print(
        f"{args.out}: {len(db.configurations)} entries of hand {db.hand} ({db.grasp_entries} "
        f"solved grasps of contact sets on {solids} primitive solids), {size_mb:.1f} MB, "
        f"built in {time.perf_counter() - start:.1f} s"
    )
    return 0
