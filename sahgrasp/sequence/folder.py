"""The search's output folder: one search at a time, and files that are whole or absent.

* :func:`locked_folder` takes an exclusive ``flock`` on ``DIR/.sahgrasp-search.lock`` for the
  whole run. The kernel releases it when the process ends, however it ends, so a killed search
  never leaves the folder locked; a second search (or a second ``--resume``) gets a
  :class:`SequenceFileError` naming the folder and the holder's pid. ``flock`` needs a POSIX
  system and a local file system (over NFS it may not exclude a run on another machine).
* Files are written with :mod:`sahgrasp.core.fileio`'s atomic writer, whose temporary files have a
  name no user file is mistaken for, so :func:`remove_stale_temporaries` (run by the lock holder,
  when no write of its own is in progress) deletes exactly the temporaries of killed writes.
"""

from __future__ import annotations

import fcntl
import os
import re
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from sahgrasp.core.errors import SequenceFileError
from sahgrasp.core.fileio import is_temporary

__all__ = [
    "CHECKPOINT",
    "FIGURE",
    "HEADER",
    "LOCK_NAME",
    "REPORT",
    "RESULTS",
    "SEQUENCE",
    "locked_folder",
    "remove_stale_temporaries",
]

CHECKPOINT = "checkpoint"
"""Subfolder of the checkpoint files."""

HEADER = "header.json"
"""The checkpoint file naming the hand, the settings and the PCA basis."""

SEQUENCE, REPORT, FIGURE = RESULTS = ("sequence.json", "search.json", "fig4.png")
"""The files a finished search writes in its folder."""

LOCK_NAME = ".sahgrasp-search.lock"
"""Lock file inside the output folder (kept after the run: deleting it would race a waiter)."""


def remove_stale_temporaries(folder: Path) -> list[Path]:
    """Delete the temporaries of killed atomic writes in ``folder``; never other files.

    Only call it while holding the folder's lock (then no write is in progress).

    Returns:
        The files deleted.
    """
    stale = [p for p in folder.glob(".*.sahgrasp.tmp*") if is_temporary(p.name) and p.is_file()]
    for path in stale:
        path.unlink(missing_ok=True)
    return stale


@contextmanager
def locked_folder(folder: Path) -> Iterator[Path]:
    """Create ``folder`` if needed and hold its exclusive lock until the block ends.

    Yields:
        ``folder``.

    Raises:
        SequenceFileError: ``folder`` cannot be created or locked, or another process holds it.
    """
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(
            folder / LOCK_NAME, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW, 0o666
        )
    except OSError as exc:
        raise SequenceFileError(
            f"cannot use {folder} as the search folder ({exc.strerror or exc}); give a "
            "writable folder path in --out"
        ) from exc
    try:
        _lock(fd, folder)
        yield folder
    finally:
        os.close(fd)  # releases the lock


def _lock(fd: int, folder: Path) -> None:
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = _holder(fd)
        raise SequenceFileError(
            f"{folder} is in use by another search (pid {holder}); wait for it to end, or "
            "choose another --out"
        ) from None
    except OSError as exc:
        raise SequenceFileError(
            f"cannot lock {folder / LOCK_NAME} ({exc.strerror or exc}); the search folder must "
            "be on a file system that supports flock"
        ) from exc
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()}\n".encode("ascii"), 0)


_HOLDER_WAIT_S = 1.0
"""How long a refused search waits for the lock's holder to write its pid [s]."""


def _holder(fd: int) -> str:
    """The pid the lock's holder wrote in the lock file, "unknown" if it wrote none.

    The holder writes it just after taking the lock, so a search refused in between reads an
    empty file: it waits for the pid a moment (polling) rather than name no holder.
    """
    deadline = time.monotonic() + _HOLDER_WAIT_S
    while True:
        pid = re.sub(r"\D", "", os.pread(fd, 32, 0).decode("ascii", "replace"))
        if pid or time.monotonic() > deadline:
            return pid or "unknown"
        time.sleep(0.002)
