"""JSON Lines targets and results: files larger than memory, written as they are solved, resumable.

A ``.jsonl`` targets file holds one problem per line, optionally after a header line (an object
without ``contacts``) that gives the ``hand`` and the default ``object``; :func:`open_targets`
reads it lazily, so the file may be larger than memory. A ``.jsonl`` results file
(:class:`ResultsWriter`) starts with a header line that names the settings (and their SHA-256
digest), then holds one result per line in the targets' order. Lines are written whole and
flushed as the results arrive, into ``OUT.part``; the finished file is renamed to ``OUT``, so an
existing ``OUT`` is replaced only by a complete run. ``--resume`` continues ``OUT.part`` (or a
finished ``OUT``): its complete lines are kept, a last line cut by a crash is dropped, and a file
written with other settings is refused. The format is documented in docs/formats.md.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from sahgrasp.contacts import (
    GraspTarget,
    InvalidProblem,
    ObjectSpec,
    object_spec,
    problem_from_line,
    read_problems,
    targets_hand,
)
from sahgrasp.errors import InvalidSettingsError, InvalidTargetError
from sahgrasp.fileio import json_safe

__all__ = [
    "MAX_LINE_BYTES",
    "RESULTS_FORMAT",
    "ResultsWriter",
    "Targets",
    "is_jsonl",
    "open_targets",
    "settings_header",
]

RESULTS_FORMAT = "sahgrasp-results-jsonl-1"
"""The ``format`` of a JSON Lines results file's header line."""

MAX_LINE_BYTES = 1 << 20
"""Longest accepted line of a ``.jsonl`` targets file: a longer one is an invalid problem, read
past without holding it in memory (a problem of five contacts takes about 500 bytes)."""

_BLOCK_BYTES = 1 << 20


def is_jsonl(path: str | os.PathLike[str] | None) -> bool:
    """Whether ``path`` names a JSON Lines file (suffix ``.jsonl``)."""
    return path is not None and str(path).lower().endswith(".jsonl")


@dataclass
class Targets:
    """A targets file opened for reading.

    Attributes:
        hand: The hand (``"sah"``, ``"allegro"`` or a description path).
        total: Number of problems (lines after the header for JSON Lines).
        problems: The problems in file order, read as they are consumed.
    """

    hand: str
    total: int
    problems: Iterator[GraspTarget | InvalidProblem]


def open_targets(path: str | os.PathLike[str], *, allow_outside_paths: bool = False) -> Targets:
    """Open a targets file: a JSON document (read whole) or a ``.jsonl`` file (read lazily).

    ``allow_outside_paths``: accept object meshes outside the file's folder
    (:func:`sahgrasp.contacts.read_problems`).

    Raises:
        InvalidTargetError: The file cannot be read, or its header (first line of a ``.jsonl``
            file, or the document's ``hand`` / ``object``) is invalid.
    """
    path = Path(path)
    if not is_jsonl(path):
        hand, problems = read_problems(path, allow_outside_paths=allow_outside_paths)
        return Targets(hand, len(problems), iter(problems))
    try:
        stream = path.open("rb")
    except OSError as exc:
        raise InvalidTargetError(f"cannot read targets file {path}: {exc.strerror}") from None
    first = _read_line(stream)
    header = _header(first, path)
    if header is None:
        stream.seek(0)
    lines = _count_lines(path) - (header is not None)
    hand = targets_hand(header or {}, path)
    default = (
        object_spec(header.get("object"), path.parent, allow_outside_paths=allow_outside_paths)
        if header
        else None
    )
    return Targets(hand, lines, _problems(stream, path.parent, default, allow_outside_paths))


def _read_line(stream: IO[bytes]) -> bytes | None:
    """The next line without its newline (None at the end of the file).

    A line longer than :data:`MAX_LINE_BYTES` is read past to its end; only its beginning is
    returned, and it is refused as too long.
    """
    line = stream.readline(MAX_LINE_BYTES + 1)
    if not line:
        return None
    if len(line) > MAX_LINE_BYTES and not line.endswith(b"\n"):
        while (rest := stream.readline(_BLOCK_BYTES)) and not rest.endswith(b"\n"):
            pass
    return line.rstrip(b"\r\n")


def _header(line: bytes | None, path: Path) -> dict[str, Any] | None:
    """The header of a ``.jsonl`` targets file: a first line that is an object without contacts."""
    try:
        data = json.loads(line) if line else None
    except (ValueError, RecursionError):
        return None
    if not isinstance(data, dict) or "contacts" in data:
        return None
    unknown = sorted(str(k) for k in data.keys() - {"hand", "object"})
    if unknown:
        raise InvalidTargetError(
            f"targets file {path}: the header line has unknown key(s) {unknown}; it holds only "
            "'hand' and 'object' (a problem line has 'contacts')"
        )
    return data


def _count_lines(path: Path) -> int:
    """Lines of ``path`` (a last line without newline counted), read in blocks."""
    count, last = 0, b"\n"
    with path.open("rb") as stream:
        while block := stream.read(_BLOCK_BYTES):
            count += block.count(b"\n")
            last = block[-1:]
    return count + (last != b"\n")


def _problems(
    stream: IO[bytes], folder: Path, default: ObjectSpec | None, allow_outside_paths: bool
) -> Iterator[GraspTarget | InvalidProblem]:
    with stream:
        index = 0
        while (line := _read_line(stream)) is not None:
            yield _parse_line(line, index, folder, default, allow_outside_paths)
            index += 1


def _parse_line(
    line: bytes, index: int, folder: Path, default: ObjectSpec | None, allow_outside_paths: bool
) -> GraspTarget | InvalidProblem:
    if len(line) > MAX_LINE_BYTES:
        return InvalidProblem(f"problem-{index}", f"line longer than {MAX_LINE_BYTES} bytes")
    return problem_from_line(line, index, folder, default, allow_outside_paths=allow_outside_paths)


def settings_header(
    hand: Any, settings: Any, sequence: dict[str, Any] | None, targets: str | os.PathLike[str]
) -> dict[str, Any]:
    """The header line of a results file: what its results depend on, and its digest.

    Args:
        hand: The :class:`sahgrasp.hand.Hand`.
        settings: The :class:`sahgrasp.ik.IKSettings`.
        sequence: The JSON form of the pose sequence used.
        targets: The targets file (its name is recorded, not its content).
    """
    solve = {
        "hand": hand.description.name,
        "hand_digest": hand.description.digest(),
        "settings": dataclasses.asdict(settings),
        "sequence_digest": hashlib.sha256(
            json.dumps(sequence, sort_keys=True).encode("utf-8")
        ).hexdigest(),
    }
    digest = hashlib.sha256(json.dumps(solve, sort_keys=True).encode("utf-8")).hexdigest()
    return {"format": RESULTS_FORMAT, **solve, "targets": Path(targets).name,
            "settings_digest": digest}  # fmt: skip


class ResultsWriter:
    """A JSON Lines results file, written line by line (module docstring).

    Args:
        path: The results file ``OUT`` (a device or FIFO is written in place).
        header: Its header line (:func:`settings_header`).
        resume: Continue ``OUT.part`` (or ``OUT``) instead of starting afresh.

    Raises:
        InvalidSettingsError: ``resume`` and the file was written with other settings, or is not
            a results file.
    """

    def __init__(self, path: str | os.PathLike[str], header: dict[str, Any], resume: bool) -> None:
        self.path = Path(os.path.realpath(path))
        self.in_place = self.path.exists() and not self.path.is_file()
        self.part = self.path if self.in_place else self.path.with_name(self.path.name + ".part")
        self.header = header
        self._end = 0
        self._stream: IO[bytes] | None = None
        source = self.part if self.part.exists() else self.path
        self.resuming = resume and not self.in_place and source.is_file()
        if self.resuming:
            with source.open("rb") as stream:
                self._check_header(stream.readline(MAX_LINE_BYTES), source)
            if source != self.part:  # a finished run: continued (and renamed back) as a part
                os.replace(source, self.part)

    def finished(self) -> Iterator[dict[str, Any]]:
        """The entries already in the file being resumed, in order (none unless resuming).

        Consume them all before :meth:`write`: the file is cut after the last complete one.
        """
        if not self.resuming:
            return
        with self.part.open("rb") as stream:
            stream.readline(MAX_LINE_BYTES)  # the header, checked on opening
            self._end = stream.tell()
            for line in stream:
                try:
                    entry = json.loads(line) if line.endswith(b"\n") else None
                except ValueError:
                    entry = None
                if not isinstance(entry, dict):
                    return  # a line cut by a crash (or damaged): solved again
                self._end += len(line)
                yield entry

    def _check_header(self, line: bytes, source: Path) -> None:
        try:
            found = json.loads(line)
        except ValueError:
            found = None
        if not isinstance(found, dict) or found.get("format") != RESULTS_FORMAT:
            raise InvalidSettingsError(
                f"cannot resume {source}: it is not a JSON Lines results file of sahgrasp "
                f"(first line must be a {RESULTS_FORMAT!r} header); remove it or drop --resume"
            )
        if found.get("settings_digest") != self.header["settings_digest"]:
            changed = [k for k in ("hand_digest", "settings", "sequence_digest")
                       if found.get(k) != self.header[k]]  # fmt: skip
            raise InvalidSettingsError(
                f"cannot resume {source}: it was written with other settings (differing: "
                f"{', '.join(changed) or 'settings digest'}); resume with the same hand, options "
                "and sequence, or write to another file"
            )

    def _open(self) -> IO[bytes]:
        if self._stream is None:
            if self.resuming:
                self._stream = self.part.open("r+b")
                self._stream.seek(self._end)
                self._stream.truncate()
            else:
                self._stream = self.part.open("wb")
                self._write_lines([self.header])
        return self._stream

    def _write_lines(self, entries: list[dict[str, Any]]) -> None:
        assert self._stream is not None
        text = "".join(json.dumps(e, allow_nan=False) + "\n" for e in entries)
        self._stream.write(text.encode("utf-8"))
        self._stream.flush()

    def write(self, entries: list[dict[str, Any]]) -> None:
        """Append whole lines and flush them (undefined numbers as ``null``)."""
        self._open()
        try:
            self._write_lines(entries)
        except ValueError:  # NaN or inf somewhere: rare, so only then pay for a cleaned copy
            self._write_lines([json_safe(e) for e in entries])

    def close(self, complete: bool) -> None:
        """Close the file; a ``complete`` run's ``OUT.part`` becomes ``OUT``."""
        self._open()
        assert self._stream is not None
        if not self.in_place:
            os.fsync(self._stream.fileno())  # the rename must not publish unwritten data
        self._stream.close()
        if complete and not self.in_place:
            os.replace(self.part, self.path)
