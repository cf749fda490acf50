"""``sahgrasp bench NAME``: run a benchmark and write its JSON."""

from __future__ import annotations

import argparse
import importlib
from typing import Any

from sahgrasp.cli.common import emit_json

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    """Register the subcommand and its benchmarks."""
    p = sub.add_parser("bench", help="run a benchmark, write JSON")
    benches = p.add_subparsers(dest="bench", required=True)
    k = benches.add_parser("kinematics", help="contact queries vs raw Pinocchio")
    k.add_argument("--calls", type=int, default=20_000)
    k.add_argument("--json", default=None, metavar="OUT", help="write JSON to OUT")
    k.set_defaults(run=run)
    ik = benches.add_parser("ik", help="Algorithm 1: success/time vs initial poses, with peers")
    ik.add_argument("--hand", default="sah")
    ik.add_argument("--problems", type=int, default=1000)
    ik.add_argument("--seed", type=int, default=0)
    ik.add_argument("--targets", default=None, help="targets file instead of random problems")
    ik.add_argument("--peers", nargs="*", default=["scipy", "pink"], choices=["scipy", "pink"])
    ik.add_argument("--peer-problems", type=int, default=200)
    ik.add_argument("--plot", default=None, metavar="PNG", help="write the Fig. 9 figure")
    ik.add_argument("--json", default=None, metavar="OUT", help="write JSON to OUT")
    ik.set_defaults(run=run)
    atlas = benches.add_parser("atlas", help="atlas on spheres and the planar hand vs CuikSuite")
    atlas.add_argument("--repeats", type=int, default=5)
    atlas.add_argument("--json", default=None, metavar="OUT", help="write JSON to OUT")
    atlas.set_defaults(run=run)
    seq = benches.add_parser("sequence", help="offline search: 1 vs 2 workers, cluster estimate")
    seq.add_argument("--hand", default="sah")
    seq.add_argument("--grid", type=int, default=5)
    seq.add_argument("--problems", type=int, default=60)
    seq.add_argument("--rounds", type=int, default=2)
    seq.add_argument("--seed", type=int, default=0)
    seq.add_argument("--method", choices=("auto", "paper"), default="auto")
    seq.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    seq.add_argument("--cluster-workers", type=int, default=16)
    seq.add_argument("--json", default=None, metavar="OUT", help="write JSON to OUT")
    seq.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp bench``."""
    module = importlib.import_module(f"sahgrasp.bench.{args.bench}")
    options = {k: v for k, v in vars(args).items() if k not in ("command", "bench", "json", "run")}
    emit_json(module.run(**options), args.json)
    return 0
