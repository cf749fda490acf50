"""Checkpoints of an atlas build: write its whole state, read it back, resume bit for bit.

A build that runs for minutes (the atlas paper's bottle with k = 3: about 95,000 charts) writes
its state every ``every_seconds`` and when it is interrupted (Ctrl-C, SIGTERM, SIGHUP arrive
between two waves of expansion, so the state written is always one the build passes through).
Resumed from the file, the build goes on from that state and gives the atlas an uninterrupted
build gives, array for array: the state holds every chart (centre, tangent basis, sign, parent,
neighbours, pending planes, polytope with its blocked vertices, flags), the queue, the singular
points and the counters; the neighbour index is rebuilt from the centres it had indexed.

The file is a NumPy ``.npz`` archive read with ``allow_pickle=False`` (no code runs on reading),
written atomically (:func:`sahgrasp.core.fileio.write_bytes_atomic`) while a lock file
(``FILE.lock``, ``flock``) keeps a second build from writing the same checkpoint. A checkpoint
names the problem it belongs to (``key``, chosen by the caller, and the start point, ``k``,
``n``, the radius, epsilon and the other settings that shape the atlas); resuming another
problem's checkpoint is an :class:`~sahgrasp.core.errors.AtlasError`.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import Any

import numpy as np

from sahgrasp.core.errors import AtlasError
from sahgrasp.core.fileio import write_bytes_atomic

__all__ = ["FORMAT", "AtlasCheckpoint", "checkpoint_lock", "deferred_interrupts"]

FORMAT = "sahgrasp-atlas-checkpoint-1"
"""The format tag of a checkpoint file (a file of another format is refused)."""


@dataclass(frozen=True)
class AtlasCheckpoint:
    """Where and how often :func:`~sahgrasp.atlas.build_atlas` saves its state.

    Attributes:
        path: The checkpoint file (``.npz``).
        key: What the caller's ``F`` and ``J`` are (an experiment's name and options, a digest):
            a checkpoint written for another key is not resumed.
        every_seconds: Write the state when this much wall time [s] passed since the last write
            (and on an interrupt, and at the end).
        resume: Start from the state in ``path`` when the file exists (else from the start).
    """

    path: str | os.PathLike[str]
    key: str = ""
    every_seconds: float = 60.0
    resume: bool = False

    def __post_init__(self) -> None:
        if not str(self.path):
            raise AtlasError("the checkpoint path is empty; give a file name")
        if not (np.isfinite(self.every_seconds) and self.every_seconds > 0):
            raise AtlasError(
                f"every_seconds must be a finite number of seconds > 0, got {self.every_seconds}"
            )


def encode(meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> bytes:
    """The ``.npz`` bytes of a state: ``meta`` as JSON plus the arrays."""
    buffer = io.BytesIO()
    header = json.dumps({"format": FORMAT, **meta}, sort_keys=True)
    arrays = {"meta": np.frombuffer(header.encode(), dtype=np.uint8), **arrays}
    np.savez(buffer, *(), **arrays)  # type: ignore[arg-type]  # numpy's stub types allow_pickle
    return buffer.getvalue()


def write(path: str | os.PathLike[str], meta: dict[str, Any], arrays: dict[str, Any]) -> None:
    """Write a state atomically (a reader sees the old file or the new one, never a part)."""
    write_bytes_atomic(path, encode(meta, arrays))


def read(path: str | os.PathLike[str]) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The meta data and arrays of a checkpoint file.

    Raises:
        AtlasError: The file is not a checkpoint of this format.
    """
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {name: archive[name] for name in archive.files}
        meta = json.loads(arrays.pop("meta").tobytes().decode())
    except (OSError, ValueError, KeyError, UnicodeDecodeError) as exc:
        if isinstance(exc, FileNotFoundError):
            raise
        raise AtlasError(f"{path} is not an atlas checkpoint ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise AtlasError(f"{path} is not an atlas checkpoint of format {FORMAT}")
    return meta, arrays


@contextlib.contextmanager
def checkpoint_lock(path: str | os.PathLike[str]) -> Iterator[None]:
    """Hold ``PATH.lock`` (an exclusive ``flock``) while a build writes ``path``.

    Raises:
        AtlasError: Another build holds the lock.
    """
    import fcntl

    lock = Path(f"{os.fspath(path)}.lock")
    fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise AtlasError(
                f"another build is writing the checkpoint {os.fspath(path)} (it holds {lock}); "
                "wait for it or choose another checkpoint file"
            ) from None
        yield
    finally:
        os.close(fd)  # closing releases the lock; the empty lock file stays, harmless


_DEFERRED_SIGNALS = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)
)


class _Flag:
    """Set by a deferred signal; read by the build between two waves."""

    __slots__ = ("raised",)

    def __init__(self) -> None:
        self.raised = False


@contextlib.contextmanager
def deferred_interrupts() -> Iterator[_Flag]:
    """While the build runs, Ctrl-C, SIGTERM and SIGHUP set a flag instead of raising at once.

    The build checks the flag between two waves, writes its checkpoint and raises
    KeyboardInterrupt itself. A second signal raises at once. Worker processes forked meanwhile
    restore the default action and re-raise the signal, so that they still die of it. Outside the
    main thread signals cannot be handled: the flag then stays down.
    """
    flag = _Flag()
    owner = os.getpid()

    def defer(signum: int, frame: FrameType | None) -> None:
        if os.getpid() != owner:
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
        if flag.raised:
            raise KeyboardInterrupt
        flag.raised = True

    if threading.current_thread() is not threading.main_thread():
        yield flag
        return
    previous = {s: signal.signal(s, defer) for s in _DEFERRED_SIGNALS}
    try:
        yield flag
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
