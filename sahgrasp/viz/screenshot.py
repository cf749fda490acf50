"""PNG screenshots of exported scenes with headless Chromium (software WebGL, no GPU, no display).

``python -m sahgrasp.viz.screenshot SCENE.html OUT.png [--size 1200x800]`` does the same from the
command line.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from contextlib import suppress
from pathlib import Path

__all__ = ["CHROMIUM_NAMES", "find_chromium", "screenshot"]

CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome")
"""Executables tried, in order, by :func:`find_chromium`."""

_ATTEMPTS = 2
_TIMEOUT_S = 90.0
_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--hide-scrollbars",
)


def find_chromium() -> str | None:
    """Path of a Chromium executable on ``PATH``, or None."""
    for name in CHROMIUM_NAMES:
        found = shutil.which(name)
        if found:
            return found
    return None


def screenshot(
    html: str | os.PathLike[str],
    png: str | os.PathLike[str],
    size: tuple[int, int] = (1200, 800),
    settle_ms: int = 5000,
) -> Path:
    """Render an exported scene to a PNG in headless Chromium.

    Args:
        html: The scene's HTML file.
        png: The image to write.
        size: Window width and height [px].
        settle_ms: Virtual time the page runs before the shot [ms] (animations play meanwhile).

    Raises:
        FileNotFoundError: No Chromium on ``PATH`` (install Debian's ``chromium``).
        subprocess.CalledProcessError: Chromium failed.
        subprocess.TimeoutExpired: Chromium hung twice in a row.
    """
    chromium = find_chromium()
    if chromium is None:
        raise FileNotFoundError(f"no Chromium found (tried {', '.join(CHROMIUM_NAMES)})")
    out = Path(png).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    for _ in range(_ATTEMPTS - 1):
        try:
            _run_chromium(chromium, Path(html), out, size, settle_ms)
            return out
        except subprocess.TimeoutExpired:
            pass  # headless Chromium hangs now and then under load: once more
    _run_chromium(chromium, Path(html), out, size, settle_ms)
    return out


def _run_chromium(
    chromium: str, html: Path, png: Path, size: tuple[int, int], settle_ms: int
) -> None:
    """One Chromium run in its own process group, killed whole afterwards (no stray children)."""
    with tempfile.TemporaryDirectory(prefix="sahgrasp-chromium-") as profile:
        command = [
            chromium, *_FLAGS, f"--user-data-dir={profile}", f"--screenshot={png}",
            f"--window-size={size[0]},{size[1]}", f"--virtual-time-budget={settle_ms}",
            html.resolve().as_uri(),
        ]  # fmt: skip
        proc = subprocess.Popen(
            command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True
        )
        try:
            _, errors = proc.communicate(timeout=_TIMEOUT_S)
        finally:
            with suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    if proc.returncode != 0:
        raise subprocess.CalledProcessError(proc.returncode, command, stderr=errors)


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: ``SCENE.html OUT.png [--size WxH] [--settle-ms MS]``."""
    parser = argparse.ArgumentParser(description="Screenshot an exported sahgrasp scene.")
    parser.add_argument("html")
    parser.add_argument("png")
    parser.add_argument("--size", default="1200x800", help="window size WIDTHxHEIGHT [px]")
    parser.add_argument("--settle-ms", type=int, default=5000, help="virtual time before the shot")
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.size.lower().split("x"))
    print(f"wrote {screenshot(args.html, args.png, (width, height), args.settle_ms)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
