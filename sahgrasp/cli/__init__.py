"""The ``sahgrasp`` command: parses arguments, calls the API, prints.

Each subcommand lives in its own module with ``add_parser(subparsers)`` and ``run(args) -> int``.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from sahgrasp.errors import SahGraspError

__all__ = ["main"]

COMMANDS = ("info", "solve", "bench", "atlas", "sequence", "learn", "demo")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="sahgrasp", description="Precision grasps for anthropomorphic robot hands."
    )
    sub = parser.add_subparsers(dest="command", required=True)
    for name in COMMANDS:
        module = importlib.import_module(f"sahgrasp.cli.{name}")
        module.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the process exit code."""
    args = _parser().parse_args(argv)
    try:
        return int(args.run(args))
    except SahGraspError as exc:
        print(f"sahgrasp: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
