"""Safe file input and output for every command.

Output: a regular file is replaced atomically, so a reader (or a resumed run) never sees a
half-written file. The bytes go to a temporary file created with exclusive create (``O_EXCL``) in
the target's folder, named ``.NAME.PID-XXXXXXXX.sahgrasp.tmp`` (eight random hex digits;
:func:`atomic_path` appends the target's suffix, ``...sahgrasp.tmp.png``, for writers that pick
the format from it), a name no user file is mistaken for, so :func:`is_temporary` tells the
leftovers of a killed write from anything else. It is flushed to disk and renamed over the
target, and removed when the write or the rename fails. An existing file keeps its permission
bits, a new one gets the umask's. Other kinds of output path are handled as follows:

- a symbolic link is followed: the file it points to is replaced, the link stays;
- a file that is not a regular file (``/dev/null``, a named pipe, a terminal) is written through,
  opened and written in place like a shell redirection, never replaced by a regular file;
- a folder is refused with :class:`OutputPathError`;
- a command's own input file is refused by :func:`check_output_path`, which every command calls on
  its output paths before it starts working, so that a bad path fails at once. Every file a run
  reads is an input, named on the command line or inside another file (a mesh in a targets file,
  the URDF of a hand description); so are an output's side files (:func:`side_files`), which may
  not be an input either.

An output written over a long run (a ``.jsonl`` results file and its ``OUT.part``, a database and
its ``OUT.parts`` folder) is locked by :func:`lock_output`: a second run writing the same output
is refused at once instead of mixing its lines into the first one's. A write that fails (a full
disk) raises :class:`OutputWriteError`, which names the file.

Input: :func:`read_json` reads a UTF-8 JSON file and turns every way of failing (missing file, a
folder, binary or UTF-16 bytes, invalid or too deeply nested JSON) into one typed error.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import json
import math
import os
import re
import secrets
import stat
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from sahgrasp.core.errors import SahGraspError

__all__ = [
    "OutputLockedError",
    "OutputPathError",
    "OutputWriteError",
    "atomic_path",
    "check_output_path",
    "file_digest",
    "is_temporary",
    "json_safe",
    "lock_output",
    "read_json",
    "side_files",
    "write_bytes_atomic",
    "write_json_atomic",
]

_TEMPORARY = re.compile(r"\..+\.[0-9]+-[0-9a-f]{8}\.sahgrasp\.tmp(?:\.[^.]+)?")
_TEMPORARY_ATTEMPTS = 1000

PathLike = str | os.PathLike[str]


class OutputPathError(SahGraspError):
    """An output path cannot be written: a folder, the command's own input, an unwritable place."""


class OutputLockedError(OutputPathError):
    """Another run is writing the same output (:func:`lock_output`)."""


class OutputWriteError(OutputPathError):
    """Writing an output failed (a full disk, an I/O error); the message names the file."""


LOCK_SUFFIX = ".lock"
"""The lock file of output ``OUT`` is ``OUT.lock``, beside the file ``OUT`` resolves to."""


def side_files(path: PathLike, suffixes: Iterable[str] = (".part", LOCK_SUFFIX)) -> list[Path]:
    """The files a long write to ``path`` creates beside it (links followed): ``OUT.part`` ...

    They are outputs too: :func:`check_output_path` refuses them when they are an input.
    """
    target = Path(os.path.realpath(path))
    return [target.with_name(target.name + suffix) for suffix in suffixes]


def write_error(path: PathLike, exc: OSError) -> OutputWriteError:
    """The error of a failed write to ``path``, naming it (``cannot write OUT: No space...``)."""
    return OutputWriteError(f"cannot write {path}: {exc.strerror or exc}")


def is_temporary(name: str) -> bool:
    """Whether ``name`` is a file name this module gives its temporary files (see the module)."""
    return _TEMPORARY.fullmatch(name) is not None


def _stat(path: Path) -> os.stat_result | None:
    try:
        return path.stat()
    except (FileNotFoundError, NotADirectoryError):
        return None


def _is_special(info: os.stat_result | None) -> bool:
    """A device, pipe or socket: anything that exists and is neither a file nor a folder."""
    return info is not None and not stat.S_ISREG(info.st_mode) and not stat.S_ISDIR(info.st_mode)


def _same_file(a: Path, b: Path) -> bool:
    """Whether both exist and are one file (through links, hard links included)."""
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (or cannot be looked at): not one file
        return False


def _writable_folder(folder: Path, shown: PathLike) -> None:
    """Raise unless the nearest existing ancestor of ``folder`` is a folder we may write into."""
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise OutputPathError(f"cannot write {shown}: {folder} is not a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputPathError(f"cannot write {shown}: no permission to write into folder {folder}")


def check_output_path(
    path: PathLike,
    inputs: Iterable[PathLike | None] = (),
    *,
    folder: bool = False,
    side: Iterable[PathLike] = (),
) -> Path:
    """Check that ``path`` can be written, before any work is done.

    Args:
        path: An output file (or, with ``folder``, an output folder, created if missing).
        inputs: Every file the command reads (None entries are ignored): the output may not be
            one.
        folder: ``path`` is a folder rather than a file.
        side: The side files the write creates (:func:`side_files`): none may be an input.

    Returns:
        ``path`` as a Path.

    Raises:
        OutputPathError: ``path`` is empty, one of ``inputs`` (or a side file is), a folder (a
            file for ``folder``), or in a place that cannot be written.
    """
    if not str(path):
        raise OutputPathError("the output path is empty; give a file name")
    out = Path(path)
    extras = [Path(extra) for extra in side]
    for given in [Path(given) for given in inputs if given is not None and str(given)]:
        if _same_file(out, given):
            raise OutputPathError(
                f"output {out} is the input file {given}; choose another output path"
            )
        for extra in extras:
            if _same_file(extra, given):
                raise OutputPathError(
                    f"output {out} would write {extra}, which is the input file {given}; "
                    "choose another output path"
                )
    target = Path(os.path.realpath(out))
    info = _stat(target)
    if folder:
        if info is not None and not stat.S_ISDIR(info.st_mode):
            raise OutputPathError(f"output folder {out} exists and is not a folder")
        _writable_folder(target, out)
    elif info is not None and stat.S_ISDIR(info.st_mode):
        raise OutputPathError(f"output {out} is a folder; give a file name")
    elif _is_special(info):
        if not os.access(target, os.W_OK):
            raise OutputPathError(f"cannot write {out}: no permission")
    else:
        _writable_folder(target.parent, out)
    return out


def _target(path: PathLike) -> tuple[Path, os.stat_result | None]:
    """The file a write to ``path`` lands in (links followed) and its status if it exists."""
    target = Path(os.path.realpath(path))
    info = _stat(target)
    if info is not None and stat.S_ISDIR(info.st_mode):
        raise OutputPathError(f"output {path} is a folder; give a file name")
    return target, info


def _create_temporary(target: Path, info: os.stat_result | None, suffix: str) -> tuple[Path, int]:
    """Create and open a new temporary file beside ``target``, with ``target``'s permissions."""
    target.parent.mkdir(parents=True, exist_ok=True)
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
    for _ in range(_TEMPORARY_ATTEMPTS):
        tag = f"{os.getpid()}-{secrets.token_hex(4)}"
        tmp = target.with_name(f".{target.name}.{tag}.sahgrasp.tmp{suffix}")
        try:
            fd = os.open(tmp, flags, 0o666)
        except FileExistsError:
            continue
        if info is not None:
            os.fchmod(fd, stat.S_IMODE(info.st_mode))
        return tmp, fd
    raise OutputPathError(
        f"cannot create a temporary file beside {target}: {_TEMPORARY_ATTEMPTS} names are taken"
    )


def write_bytes_atomic(path: PathLike, payload: bytes) -> None:
    """Write ``payload`` to ``path``: atomically for a regular file (see the module).

    Raises:
        OutputPathError: ``path`` is a folder.
        OutputWriteError: Writing the bytes failed (the disk is full, ...); names ``path``.
        OSError: The folder cannot be created or written into.
    """
    target, info = _target(path)
    if _is_special(info):
        try:
            with open(target, "wb") as f:
                f.write(payload)
        except OSError as exc:
            raise write_error(path, exc) from exc
        return
    tmp, fd = _create_temporary(target, info, "")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(payload)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise write_error(path, exc) from exc
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def atomic_path(path: PathLike) -> Iterator[Path]:
    """Yield a temporary file name for a writer that needs one; it becomes ``path`` on success.

    For writers such as ``matplotlib``'s ``savefig`` that open the file themselves. The temporary
    name ends with ``path``'s suffix, from which such writers pick the format. On success the file
    is renamed over ``path`` (or copied into it if ``path`` is a device or pipe); on an exception
    it is removed and ``path`` is left as it was.

    Raises:
        OutputPathError: ``path`` is a folder.
    """
    target, info = _target(path)
    tmp, fd = _create_temporary(target, info, target.suffix)
    os.close(fd)
    try:
        yield tmp
        if _is_special(info):
            write_bytes_atomic(target, tmp.read_bytes())
        else:
            with open(tmp, "rb+") as f:
                os.fsync(f.fileno())
            os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)


@contextlib.contextmanager
def lock_output(path: PathLike) -> Iterator[Path]:
    """Hold the lock of output ``path`` (``OUT.lock``, beside the file it resolves to).

    The lock is an advisory ``flock`` on the lock file, released by the kernel when the process
    ends, however it ends: a killed run leaves at most an unlocked file, which the next run takes
    over. The file holds the holder's process id, for the message of a refused run, and is
    removed on release. A run that opens the file just as its holder removes it finds another
    file at the name and tries again, so two runs never both hold the lock.

    Yields:
        The lock file.

    Raises:
        OutputLockedError: Another process holds the lock.
        OutputPathError: The lock file is a symbolic link or cannot be created.
    """
    lock = side_files(path, (LOCK_SUFFIX,))[0]
    lock.parent.mkdir(parents=True, exist_ok=True)
    flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    while True:
        try:
            fd = os.open(lock, flags, 0o644)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                raise OutputPathError(
                    f"cannot lock {path}: its lock file {lock} is a symbolic link; remove it"
                ) from None
            raise OutputPathError(f"cannot lock {path}: {exc.strerror or exc}: {lock}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 32).decode("ascii", "replace").strip() or "unknown"
            os.close(fd)
            raise OutputLockedError(
                f"output {path} is being written by another sahgrasp run (process {holder}, "
                f"lock {lock}); wait for it to end or choose another output"
            ) from None
        try:
            now = os.stat(lock, follow_symlinks=False)
        except FileNotFoundError:
            now = None
        held = os.fstat(fd)
        if now is not None and (now.st_dev, now.st_ino) == (held.st_dev, held.st_ino):
            break
        os.close(fd)  # removed by its holder since we opened it: lock the new one
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode("ascii"))
        yield lock
    finally:
        with contextlib.suppress(FileNotFoundError):
            lock.unlink()  # while still locked: the next run creates a fresh one
        os.close(fd)


_DIGESTS: dict[tuple[str, int, int, int], str] = {}
_KEPT_DIGESTS = 256


def file_digest(path: PathLike) -> str:
    """SHA-256 of a file's content, computed once per file version (path, size, change time).

    A file that cannot be read gets the digest of its error message, so that a problem naming a
    missing file is still told apart from one naming another missing file.
    """
    real = os.path.realpath(path)
    try:
        info = os.stat(real)
    except OSError as exc:
        return hashlib.sha256(f"unreadable: {exc.strerror}".encode()).hexdigest()
    key = (real, info.st_size, info.st_mtime_ns, info.st_ino)
    if key not in _DIGESTS:
        digest = hashlib.sha256()
        try:
            with open(real, "rb") as f:
                while block := f.read(1 << 20):
                    digest.update(block)
        except OSError as exc:
            return hashlib.sha256(f"unreadable: {exc.strerror}".encode()).hexdigest()
        if len(_DIGESTS) >= _KEPT_DIGESTS:
            del _DIGESTS[next(iter(_DIGESTS))]
        _DIGESTS[key] = digest.hexdigest()
    return _DIGESTS[key]


def json_safe(data: Any) -> Any:
    """``data`` with every NaN or infinite number (undefined, e.g. an unsolved error) as None."""
    if isinstance(data, float):
        return data if math.isfinite(data) else None
    if isinstance(data, dict):
        return {key: json_safe(value) for key, value in data.items()}
    if isinstance(data, list | tuple):
        return [json_safe(value) for value in data]
    return data


def write_json_atomic(path: PathLike, data: Any) -> None:
    """Write ``data`` as indented JSON (no NaN/inf allowed) to ``path`` atomically."""
    text = json.dumps(data, indent=2, allow_nan=False) + "\n"
    write_bytes_atomic(path, text.encode("utf-8"))


def read_json(path: PathLike, what: str, error: type[SahGraspError]) -> Any:
    """Read a UTF-8 JSON file, raising ``error`` with one clear message for any failure.

    Args:
        path: The file.
        what: What the file is, for the message (e.g. ``"targets file"``).
        error: The error type to raise.

    Raises:
        SahGraspError: (``error``) the file is missing, a folder, unreadable, not UTF-8 text
            (binary, UTF-16), not JSON, or nested too deeply to parse.
    """
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise error(f"cannot read {what} {path}: {exc.strerror or exc}") from exc
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise error(
            f"{what} {path} is not UTF-8 text (byte {raw[exc.start]:#04x} at offset {exc.start}); "
            "JSON files must be saved as UTF-8"
        ) from None
    try:
        return json.loads(text)
    except RecursionError:
        raise error(f"{what} {path} is nested too deeply (arrays or objects) to be read") from None
    except ValueError as exc:  # JSONDecodeError, or an integer with too many digits
        raise error(f"{what} {path} is not valid JSON: {exc}") from None
