"""JSON Lines targets and results: files larger than memory, written as they are solved, resumable.

A ``.jsonl`` targets file holds one problem per line, optionally after a header line (an object
without ``contacts``) that gives the ``hand`` and the default ``object``; :func:`open_targets`
reads it lazily, so the file may be larger than memory. A ``.jsonl`` results file
(:class:`ResultsWriter`) starts with a header line that names the settings (and their SHA-256
digest), then holds one result per line in the targets' order. Lines are written whole and
flushed as the results arrive, into ``OUT.part``; the finished file is renamed to ``OUT``, so an
existing ``OUT`` is replaced only by a complete run. ``--resume`` continues ``OUT.part`` (or a
finished ``OUT``): its complete lines are kept, a last line cut by a crash is dropped, and a file
written with other settings (or from a targets file whose hand or default object differ) is
refused, and the output stays where it was. Each result carries the :func:`problem_digest` of its
problem: a resumed run keeps the results whose problems are unchanged, in order, and solves the
rest again from the first changed one. The output is locked while it is written
(:func:`sahgrasp.core.fileio.lock_output`), so a second run writing it is refused at once. A targets
file may be a pipe: it is read once, as it comes. The format is documented in
docs/how-to/file-formats.md.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
from collections.abc import Generator, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from sahgrasp.core.errors import InvalidSettingsError, InvalidTargetError
from sahgrasp.core.fileio import (
    OutputPathError,
    file_digest,
    json_safe,
    lock_output,
    side_files,
    write_error,
)
from sahgrasp.model.contacts import GraspTarget, ObjectSpec
from sahgrasp.objects.targets import (
    InvalidProblem,
    object_spec,
    problem_from_line,
    read_targets_document,
    targets_hand,
)

__all__ = [
    "MAX_LINE_BYTES",
    "RESULTS_FORMAT",
    "ResultsWriter",
    "Targets",
    "is_jsonl",
    "open_targets",
    "problem_digest",
    "settings_header",
    "targets_digest",
]

RESULTS_FORMAT = "sahgrasp-results-jsonl-1"
"""The ``format`` of a JSON Lines results file's header line."""

MAX_LINE_BYTES = 1 << 20
"""Longest accepted line of a ``.jsonl`` targets file: a longer one is an invalid problem, read
past without holding it in memory (a problem of five contacts takes about 500 bytes)."""

_BLOCK_BYTES = 1 << 20
_BOM = b"\xef\xbb\xbf"


def is_jsonl(path: str | os.PathLike[str] | None) -> bool:
    """Whether ``path`` names a JSON Lines file (suffix ``.jsonl``)."""
    return path is not None and str(path).lower().endswith(".jsonl")


@dataclass
class Targets:
    """A targets file opened for reading.

    Attributes:
        hand: The hand (a registered hand's name or a description path).
        total: Number of problems (lines after the header for JSON Lines), None when the file is
            not a regular file (a pipe is read once, as the problems are consumed).
        problems: The problems in file order, read as they are consumed.
        digest: :func:`targets_digest` of the file's hand and default object.
        files: The files the targets file names that are known before its problems are read:
            every problem's mesh of a JSON document, the default object's mesh of a ``.jsonl``
            file (a line's own mesh is known when the line is read).
    """

    hand: str
    total: int | None
    problems: Iterator[GraspTarget | InvalidProblem]
    digest: str = ""
    files: tuple[Path, ...] = ()


def open_targets(path: str | os.PathLike[str], *, allow_outside_paths: bool = False) -> Targets:
    """Open a targets file: a JSON document (read whole) or a ``.jsonl`` file (read lazily).

    A ``.jsonl`` file is read once, from its start to its end: a named pipe loses no line. A
    UTF-8 byte order mark before its first line is skipped. ``allow_outside_paths``: accept object
    meshes outside the file's folder (:func:`sahgrasp.objects.targets.read_problems`).

    Raises:
        InvalidTargetError: The file cannot be read, or its header (first line of a ``.jsonl``
            file, or the document's ``hand`` / ``object``) is invalid.
    """
    path = Path(path)
    if not is_jsonl(path):
        hand, default, problems = read_targets_document(
            path, allow_outside_paths=allow_outside_paths
        )
        meshes = {Path(m) for p in problems if (m := _mesh_of(p)) is not None}
        return Targets(
            hand, len(problems), iter(problems), targets_digest(hand, default), tuple(meshes)
        )
    try:
        stream = path.open("rb")
    except OSError as exc:
        raise InvalidTargetError(f"cannot read targets file {path}: {exc.strerror}") from None
    first = _read_line(stream)
    if first is not None and first.startswith(_BOM):
        first = first[len(_BOM) :]
    header = _header(first, path)
    pending = [] if header is not None or first is None else [first]
    # Counting the lines is a second pass: only a regular file can be read twice.
    lines = _count_lines(path) - (header is not None) if path.is_file() else None
    hand = targets_hand(header or {}, path)
    default = (
        object_spec(header.get("object"), path.parent, allow_outside_paths=allow_outside_paths)
        if header
        else None
    )
    files = (Path(default.mesh),) if default is not None and default.mesh else ()
    lazy = _problems(stream, pending, path.parent, default, allow_outside_paths)
    return Targets(hand, lines, lazy, targets_digest(hand, default), files)


def _mesh_of(problem: GraspTarget | InvalidProblem) -> str | None:
    spec = getattr(problem, "object_spec", None)
    return None if spec is None else spec.mesh


def targets_digest(hand: str, default: ObjectSpec | None) -> str:
    """SHA-256 of what a targets file sets for all its problems: its hand, its default object.

    The default object's mesh file is digested by content.
    """
    data = {"hand": hand, "object": None if default is None else _object_json(default)}
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode("utf-8")).hexdigest()


def _object_json(spec: ObjectSpec) -> dict[str, Any]:
    data = spec.to_dict()
    if spec.mesh is not None:
        data["mesh_digest"] = file_digest(spec.mesh)
    return data


def problem_digest(problem: GraspTarget | InvalidProblem) -> str:
    """SHA-256 of what a problem's result depends on: its name, contacts and object.

    The object's mesh file is digested by content (once per file and version), so a result
    stays matched to its problem only while the problem, its object and the mesh are unchanged.
    An invalid problem is digested by its name and the reason it is invalid.
    """
    if isinstance(problem, InvalidProblem):
        data: dict[str, Any] = {"invalid": problem.detail, "name": problem.name}
    else:
        data = problem.to_dict()
        if problem.object_spec is not None:
            data["object"] = _object_json(problem.object_spec)
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode("utf-8")).hexdigest()


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
    stream: IO[bytes],
    pending: list[bytes],
    folder: Path,
    default: ObjectSpec | None,
    allow_outside_paths: bool,
) -> Iterator[GraspTarget | InvalidProblem]:
    """The problems of the lines: ``pending`` ones (already read) first, then the stream's."""
    with stream:
        index = 0
        for first in pending:
            yield _parse_line(first, index, folder, default, allow_outside_paths)
            index += 1
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
    hand: Any,
    settings: Any,
    sequence: dict[str, Any] | None,
    targets: str | os.PathLike[str],
    targets_settings: str = "",
    database: str | None = None,
) -> dict[str, Any]:
    """The header line of a results file: what its results depend on, and its digest.

    Args:
        hand: The :class:`sahgrasp.model.hand.Hand`.
        settings: The :class:`sahgrasp.ik.IKSettings`.
        sequence: The JSON form of the pose sequence used.
        targets: The targets file (its name is recorded, not its content).
        targets_settings: :func:`targets_digest` of the targets file (its hand, default object).
        database: Content digest of the grasp database of the learned start, None for the
            shipped one.
    """
    solve = {
        "hand": hand.description.name,
        "hand_digest": hand.description.digest(),
        "settings": dataclasses.asdict(settings),
        "sequence_digest": hashlib.sha256(
            json.dumps(sequence, sort_keys=True).encode("utf-8")
        ).hexdigest(),
    }
    if database is not None:  # absent for the shipped database: older headers stay valid
        solve["database_digest"] = database
    digest = hashlib.sha256(json.dumps(solve, sort_keys=True).encode("utf-8")).hexdigest()
    return {"format": RESULTS_FORMAT, **solve, "targets": Path(targets).name,
            "targets_digest": targets_settings, "settings_digest": digest}  # fmt: skip


class ResultsWriter:
    """A JSON Lines results file, written line by line (module docstring).

    The output is locked from construction to :meth:`close` (:func:`lock_output`), and
    ``OUT.part`` is opened at construction, so that a bad place fails before any work. Resuming
    a finished ``OUT`` moves it back to ``OUT.part`` only when a line must change; a refused or
    fully finished resume leaves it where it was.

    Args:
        path: The results file ``OUT`` (a device or FIFO is written in place).
        header: Its header line (:func:`settings_header`).
        resume: Continue ``OUT.part`` (or ``OUT``) instead of starting afresh.

    Raises:
        InvalidSettingsError: ``resume`` and the file was written with other settings, or is not
            a results file.
        OutputLockedError: Another run is writing ``OUT``.
        OutputPathError: ``OUT.part`` is a symbolic link (when resuming) or cannot be created.
    """

    def __init__(self, path: str | os.PathLike[str], header: dict[str, Any], resume: bool) -> None:
        self.shown = str(path)
        self.path = Path(os.path.realpath(path))
        self.in_place = self.path.exists() and not self.path.is_file()
        self.part = self.path if self.in_place else side_files(self.path, (".part",))[0]
        self.header = header
        self._end = 0
        self._size = 0
        self._stream: IO[bytes] | None = None
        self._lock = contextlib.ExitStack()
        if not self.in_place:
            self._lock.enter_context(lock_output(self.path))
        try:
            self.source = self.part if os.path.lexists(self.part) else self.path
            self.resuming = resume and not self.in_place and os.path.lexists(self.source)
            if self.resuming:
                self._check_source()
            else:
                self._stream = self._create_part()
                self.source = self.part
                self._write_lines([self.header])
        except BaseException:
            self._lock.close()
            raise

    def _check_source(self) -> None:
        if self.source.is_symlink() or not self.source.is_file():
            raise OutputPathError(
                f"cannot resume {self.source}: it is not a regular file (a link or a folder); "
                "remove it or drop --resume"
            )
        with self.source.open("rb") as stream:
            self._check_header(stream.readline(MAX_LINE_BYTES), self.source)
            self._end = stream.tell()
            self._size = os.fstat(stream.fileno()).st_size

    def _create_part(self) -> IO[bytes]:
        """``OUT.part`` created afresh (a stale one, or a link left there, replaced)."""
        if self.in_place:
            return self.part.open("wb")
        self.part.parent.mkdir(parents=True, exist_ok=True)
        with contextlib.suppress(FileNotFoundError):
            self.part.unlink()  # a link is removed, never followed: its target stays
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
        try:
            return os.fdopen(os.open(self.part, flags, 0o666), "wb")
        except OSError as exc:
            raise write_error(self.part, exc) from exc

    def finished(self) -> Generator[dict[str, Any], None, None]:
        """The entries already in the file being resumed, in order (none unless resuming).

        The file is cut after the last entry the caller took before it stopped asking (an entry
        it stops at is not kept) or after the last complete one: consume them before
        :meth:`write`.
        """
        if not self.resuming:
            return
        with self.source.open("rb") as stream:
            stream.seek(self._end)
            for line in stream:
                try:
                    entry = json.loads(line) if line.endswith(b"\n") else None
                except ValueError:
                    entry = None
                if not isinstance(entry, dict):
                    return  # a line cut by a crash (or damaged): solved again
                yield entry
                self._end += len(line)  # reached when the caller asks for more: it kept this

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
            keys = ("hand_digest", "settings", "sequence_digest", "database_digest")
            changed = [k for k in keys if found.get(k) != self.header.get(k)]
            raise InvalidSettingsError(
                f"cannot resume {source}: it was written with other settings (differing: "
                f"{', '.join(changed) or 'settings digest'}); resume with the same hand, options "
                "and sequence, or write to another file"
            )
        if found.get("targets_digest") != self.header.get("targets_digest"):
            raise InvalidSettingsError(
                f"cannot resume {source}: it was written from a targets file with another hand "
                "or default object; resume with the same targets file, or write to another file"
            )

    def _open(self) -> IO[bytes]:
        if self._stream is None:
            if self.source != self.part:  # a finished run: continued (and renamed back) as a part
                os.replace(self.source, self.part)
                self.source = self.part
            self._stream = self.part.open("r+b")
            self._stream.seek(self._end)
            self._stream.truncate()
        return self._stream

    def _write_lines(self, entries: list[dict[str, Any]]) -> None:
        assert self._stream is not None
        text = "".join(json.dumps(e, allow_nan=False) + "\n" for e in entries)
        try:
            self._stream.write(text.encode("utf-8"))
            self._stream.flush()
        except OSError as exc:
            raise write_error(self.part, exc) from exc

    def write(self, entries: list[dict[str, Any]]) -> None:
        """Append whole lines and flush them (undefined numbers as ``null``).

        Raises:
            OutputWriteError: The write failed (a full disk); the message names the file.
        """
        self._open()
        try:
            self._write_lines(entries)
        except ValueError:  # NaN or inf somewhere: rare, so only then pay for a cleaned copy
            self._write_lines([json_safe(e) for e in entries])

    def close(self, complete: bool, publish: bool = True) -> None:
        """Close the file and release the lock; a ``complete`` run's ``OUT.part`` becomes ``OUT``.

        A resumed file that nothing was written to stays as it is unless ``complete`` (then it is
        cut after the kept entries): a refused or interrupted resume moves nothing.

        Args:
            complete: Every problem has its result in the file.
            publish: Rename a complete ``OUT.part`` to ``OUT`` (False: leave it as the part).
        """
        try:
            if self._stream is None and complete and self._end != self._size:
                self._open()  # the file is cut after the kept entries
            if self._stream is not None:
                try:
                    if not self.in_place:
                        os.fsync(self._stream.fileno())  # a rename must not publish unwritten data
                finally:
                    self._stream.close()
            if complete and publish and not self.in_place and self.source == self.part:
                os.replace(self.part, self.path)
        finally:
            self._lock.close()
