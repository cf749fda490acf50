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
  its output paths before it starts working, so that a bad path fails at once.

Input: :func:`read_json` reads a UTF-8 JSON file and turns every way of failing (missing file, a
folder, binary or UTF-16 bytes, invalid or too deeply nested JSON) into one typed error.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import secrets
import stat
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from sahgrasp.errors import SahGraspError

__all__ = [
    "OutputPathError",
    "atomic_path",
    "check_output_path",
    "is_temporary",
    "read_json",
    "write_bytes_atomic",
    "write_json_atomic",
]

_TEMPORARY = re.compile(r"\..+\.[0-9]+-[0-9a-f]{8}\.sahgrasp\.tmp(?:\.[^.]+)?")
_TEMPORARY_ATTEMPTS = 1000

PathLike = str | os.PathLike[str]


class OutputPathError(SahGraspError):
    """An output path cannot be written: a folder, the command's own input, an unwritable place."""


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
    path: PathLike, inputs: Iterable[PathLike | None] = (), *, folder: bool = False
) -> Path:
    """Check that ``path`` can be written, before any work is done.

    Args:
        path: An output file (or, with ``folder``, an output folder, created if missing).
        inputs: The command's input files (None entries are ignored): the output may not be one.
        folder: ``path`` is a folder rather than a file.

    Returns:
        ``path`` as a Path.

    Raises:
        OutputPathError: ``path`` is empty, one of ``inputs``, a folder (a file for ``folder``),
            or in a place that cannot be written.
    """
    if not str(path):
        raise OutputPathError("the output path is empty; give a file name")
    out = Path(path)
    for given in inputs:
        if given is not None and _same_file(out, Path(given)):
            raise OutputPathError(
                f"output {out} is the input file {given}; choose another output path"
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
        OSError: The folder cannot be written, the disk is full, ...
    """
    target, info = _target(path)
    if _is_special(info):
        with open(target, "wb") as f:
            f.write(payload)
        return
    tmp, fd = _create_temporary(target, info, "")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(payload)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
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
