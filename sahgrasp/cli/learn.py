"""``sahgrasp learn``: build the grasp database of the learned IK start."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from tqdm import tqdm

from sahgrasp.errors import InvalidSettingsError
from sahgrasp.hand import load_hand
from sahgrasp.ik.learned import LEARN_SEED, build_database
from sahgrasp.parallel import check_workers
from sahgrasp.sequence.executors import open_executor

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "learn",
        help="build the grasp database of init=learned",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--hand", default="sah", help="sah, allegro, or a hand-description JSON path")
    p.add_argument("--samples", type=int, default=20_000, help="database entries")
    p.add_argument("--seed", type=int, default=LEARN_SEED, help="seed of the entries")
    p.add_argument("--out", required=True, metavar="FILE", help="the .npz file to write")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None,
                       help="local worker processes (default: one per core)")  # fmt: skip
    where.add_argument("--scheduler", default=None, metavar="ADDR",
                       help="Dask scheduler address, e.g. tcp://host:8786")  # fmt: skip
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Build (or resume building) the database; finished chunks in ``FILE.parts`` are kept."""
    if isinstance(args.samples, bool) or args.samples < 1:
        raise InvalidSettingsError(f"--samples must be an integer >= 1, got {args.samples}")
    if args.seed < 0:
        raise InvalidSettingsError(f"--seed must be an integer >= 0, got {args.seed}")
    if args.workers is not None:
        check_workers(args.workers)
    hand = load_hand(args.hand)
    start = time.perf_counter()
    with tqdm(unit="chunk", desc="learn") as bar:

        def progress(done: int, total: int) -> None:
            bar.total = total
            bar.update(done - bar.n)

        with open_executor(args.scheduler, args.workers) as executor:
            db = build_database(hand, args.samples, args.out, args.seed, executor, progress)
    size_mb = Path(args.out).stat().st_size / 1e6
    print(
        f"{args.out}: {len(db.configurations)} grasps of hand {db.hand}, {size_mb:.1f} MB, "
        f"built in {time.perf_counter() - start:.1f} s"
    )
    return 0
