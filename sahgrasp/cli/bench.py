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


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp bench``."""
    module = importlib.import_module(f"sahgrasp.bench.{args.bench}")
    options = {k: v for k, v in vars(args).items() if k not in ("command", "bench", "json", "run")}
    emit_json(module.run(**options), args.json)
    return 0
