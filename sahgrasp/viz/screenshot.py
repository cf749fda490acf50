"""PNG screenshots of exported scenes with headless Chromium (software WebGL, no GPU, no display).

``sahgrasp screenshot SCENE.html OUT.png [--size 1200x800]`` does the same from the command line.

Headless Chromium now and then hangs at start or after writing the image, under load. Each run
therefore has its own process group and a fresh profile, is bounded by a timeout, and is killed
whole afterwards; a run that hangs or fails is retried, and only the last failure is reported, as
one :class:`ScreenshotError`. The image is written beside the profile and moved into place once
complete, so a failed run never leaves a partial or stale PNG at the output path.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import tempfile
import time
from contextlib import suppress
from pathlib import Path

from sahgrasp.core.errors import SahGraspError

__all__ = [
    "CHROMIUM_NAMES",
    "MAX_SIDE_PX",
    "MIN_SIDE_PX",
    "ScreenshotError",
    "chromium_flags",
    "find_chromium",
    "screenshot",
]

CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome")
"""Executables tried, in order, by :func:`find_chromium`."""

INSTALL_HINT = "install Chromium (Debian/Ubuntu: apt-get install -y chromium)"

_ATTEMPTS = 3
_TIMEOUT_S = 60.0  # measured: 3-5 s for a small scene, 15-50 s for the demo on a loaded machine
_POLL_S = 0.2
_SETTLED_S = 1.0  # an image unchanged this long is complete even if Chromium has not exited
MIN_SIDE_PX = 16
"""Smallest window width or height [px]."""
MAX_SIDE_PX = 8192
"""Largest window width or height [px]: an 8K screen's width; Chromium's software renderer
needs some 4 bytes per pixel per buffer, so larger images cost gigabytes for no use."""

_FLAGS = (
    "--headless",
    "--disable-gpu",
    "--disable-background-networking",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--hide-scrollbars",
    # Every frame fully drawn before virtual time moves on: without it, heavy scenes stalled in
    # 2 of 3 runs (no image after 60 s); with it 3 of 3 finished.
    "--run-all-compositor-stages-before-draw",
)


class ScreenshotError(SahGraspError):
    """No Chromium, or Chromium failed or hung on every attempt to render a page."""


def chromium_flags(as_root: bool | None = None) -> tuple[str, ...]:
    """The flags of every headless Chromium run.

    Chromium's sandbox stays on, except for root, for whom Chromium refuses to start with it
    (containers and CI usually run as root).

    Args:
        as_root: Whether the browser runs as root (default: whether this process does).
    """
    if as_root is None:
        as_root = hasattr(os, "geteuid") and os.geteuid() == 0
    return (*_FLAGS, "--no-sandbox") if as_root else _FLAGS


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
    timeout_s: float = _TIMEOUT_S,
    attempts: int = _ATTEMPTS,
    chromium: str | None = None,
) -> Path:
    """Render an exported scene to a PNG in headless Chromium.

    Args:
        html: The scene's HTML file.
        png: The image to write.
        size: Window width and height [px], each in ``MIN_SIDE_PX .. MAX_SIDE_PX`` (16 .. 8192).
        settle_ms: Virtual time the page runs before the shot [ms] (animations play meanwhile).
        timeout_s: Wall time one Chromium run may take [s] before it is killed.
        attempts: Chromium runs tried before giving up.
        chromium: The browser executable; the first of :data:`CHROMIUM_NAMES` on ``PATH`` if None.

    Returns:
        The absolute path of the image.

    Raises:
        ScreenshotError: No Chromium, a missing page, bad sizes or counts, or every run failed
            or hung (the message gives the last reason and the install hint).
    """
    page = Path(html)
    _check(page, size, settle_ms, timeout_s, attempts)
    browser = chromium or find_chromium()
    if browser is None or shutil.which(browser) is None:
        tried = browser or ", ".join(CHROMIUM_NAMES)
        raise ScreenshotError(f"no Chromium found (tried {tried}); {INSTALL_HINT}")
    out = Path(png).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    reason = ""
    for _ in range(attempts):
        reason = _run_chromium(browser, page.resolve(), out, size, settle_ms, timeout_s)
        if not reason:
            return out
    raise ScreenshotError(
        f"Chromium failed {attempts} times to render {page}: {reason}; {INSTALL_HINT}, or retry"
    )


def _check(page: Path, size: tuple[int, int], settle_ms: int, timeout_s: float, n: int) -> None:
    """Refuse a missing page, sizes out of range, and non-positive times and counts."""
    if not page.is_file():
        raise ScreenshotError(f"no page to render: {page} is not a file")
    sides_ok = (
        isinstance(size, tuple) and len(size) == 2
        and all(isinstance(v, int) and MIN_SIDE_PX <= v <= MAX_SIDE_PX for v in size)
    )  # fmt: skip
    if not sides_ok or settle_ms < 0 or not timeout_s > 0 or n < 1:
        raise ScreenshotError(
            f"size must be (width, height) in {MIN_SIDE_PX}..{MAX_SIDE_PX} px, settle_ms >= 0, "
            f"timeout_s > 0 and attempts >= 1; got size={size}, settle_ms={settle_ms}, "
            f"timeout_s={timeout_s}, attempts={n}"
        )


def _run_chromium(
    chromium: str, html: Path, png: Path, size: tuple[int, int], settle_ms: int, timeout_s: float
) -> str:
    """One Chromium run in its own process group, killed whole afterwards (no stray children).

    Returns:
        An empty string once ``png`` is written, else why the run failed.
    """
    with tempfile.TemporaryDirectory(prefix="sahgrasp-chromium-") as work:
        shot = Path(work) / "shot.png"
        command = [
            chromium, *chromium_flags(), f"--user-data-dir={Path(work) / 'profile'}",
            f"--screenshot={shot}", f"--window-size={size[0]},{size[1]}",
            f"--virtual-time-budget={settle_ms}", html.as_uri(),
        ]  # fmt: skip
        log = Path(work) / "stderr.txt"
        with log.open("wb") as errors:
            proc = subprocess.Popen(
                command, stdout=subprocess.DEVNULL, stderr=errors, start_new_session=True
            )
            try:
                written = _wait_for_image(proc, shot, timeout_s)
            finally:
                with suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()  # reaps the group leader, killed above: returns at once
        if written:
            os.replace(shot, png)
            return ""
        if proc.returncode not in (0, -signal.SIGKILL):
            last = log.read_text(errors="replace").strip().splitlines()
            return f"exit code {proc.returncode}" + (f" ({last[-1][:200]})" if last else "")
        return f"no image after {timeout_s:g} s (Chromium hung)"


def _wait_for_image(proc: subprocess.Popen[bytes], shot: Path, timeout_s: float) -> bool:
    """Wait until Chromium exits or its image stops growing; True when the image is there."""
    deadline = time.monotonic() + timeout_s
    size, since = -1, time.monotonic()
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            return proc.returncode == 0 and _size(shot) > 0
        now, current = time.monotonic(), _size(shot)
        if current != size:
            size, since = current, now
        elif size > 0 and now - since >= _SETTLED_S:
            return True  # written and complete; Chromium hangs on exit now and then
        time.sleep(_POLL_S)
    return False


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except FileNotFoundError:
        return 0
