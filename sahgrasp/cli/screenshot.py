"""``sahgrasp screenshot SCENE.html OUT.png``: a PNG of an exported scene, in headless Chromium."""

from __future__ import annotations

import argparse
from typing import Any

from sahgrasp.cli.common import add_command, check_outputs, positive_int

__all__ = ["add_parser", "run", "window_size"]


MIN_SIDE_PX = 16
"""Smallest width or height [px] (:data:`sahgrasp.viz.screenshot.MIN_SIDE_PX`, not imported:
the parser imports nothing heavy)."""
MAX_SIDE_PX = 8192
"""Largest width or height [px] (:data:`sahgrasp.viz.screenshot.MAX_SIDE_PX`)."""


def window_size(text: str) -> tuple[int, int]:
    """``WIDTHxHEIGHT`` as two integers [px], each in 16 .. 8192."""
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected WIDTHxHEIGHT like 1200x800, got {text!r}"
        ) from None
    if not (MIN_SIDE_PX <= width <= MAX_SIDE_PX and MIN_SIDE_PX <= height <= MAX_SIDE_PX):
        raise argparse.ArgumentTypeError(
            f"width and height must be in {MIN_SIDE_PX}..{MAX_SIDE_PX} px, got {text!r}"
        )
    return width, height


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    p = add_command(
        sub, "screenshot", "PNG of an exported scene (needs Chromium: apt-get install chromium)"
    )
    p.add_argument("html", help="the scene's HTML file (sahgrasp demo, examples --html)")
    p.add_argument("png", help="the PNG to write")
    p.add_argument(
        "--size",
        type=window_size,
        default="1200x800",
        help=f"window size WIDTHxHEIGHT [px], each side in {MIN_SIDE_PX}..{MAX_SIDE_PX}",
    )
    p.add_argument(
        "--settle-ms", type=positive_int, default=5000, help="virtual time before the shot [ms]"
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp screenshot``; a missing or failing Chromium is one line, exit 2."""
    from sahgrasp.viz.screenshot import screenshot

    check_outputs([args.png], inputs=[args.html])
    print(f"wrote {screenshot(args.html, args.png, args.size, args.settle_ms)}")
    return 0
