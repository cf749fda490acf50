"""Pieces shared by the subcommands: option types, help format, output paths, JSON output.

This module is imported to build the parser (``sahgrasp --help``), so it imports nothing heavy.
The option types and the IK options shared with the example scripts are those of
:mod:`sahgrasp.experiments.arguments`, re-exported here for the subcommands.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, NoReturn, TextIO

from sahgrasp.core.errors import HandModelError, SequenceFileError
from sahgrasp.core.fileio import (
    OutputPathError,
    atomic_path,
    check_output_path,
    json_safe,
    read_json,
    write_bytes_atomic,
)
from sahgrasp.experiments.arguments import (
    HAND_HELP,
    INITS_HELP,
    MAX_INITS,
    METHOD_HELP,
    add_ik_arguments,
    int_at_least,
    int_in_range,
    nonnegative_int,
    positive_float,
    positive_int,
)
from sahgrasp.model.hands import HANDS

__all__ = [
    "HAND_HELP",
    "HAND_OVERRIDE_HELP",
    "IMAGE_SUFFIXES",
    "INITS_HELP",
    "MAX_INITS",
    "METHOD_HELP",
    "HelpFormatter",
    "Parser",
    "add_command",
    "add_ik_arguments",
    "add_json_argument",
    "add_mesh_path_argument",
    "check_json_inputs",
    "check_outputs",
    "emit_json",
    "human_stream",
    "image_path",
    "int_at_least",
    "int_in_range",
    "json_text",
    "nonnegative_int",
    "output_file",
    "positive_float",
    "positive_int",
    "printable",
    "scheduler_address",
    "work_executor",
    "write_stdout",
]

HAND_OVERRIDE_HELP = f"use this hand instead of the targets file's: {HAND_HELP}"

IMAGE_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".tif", ".tiff", ".webp", ".eps")
"""Figure formats ``--plot`` accepts: matplotlib picks the format from the suffix."""


class Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line (and exit status 2)."""

    def error(self, message: str) -> NoReturn:
        """Print ``PROG: error: MESSAGE (see PROG --help)`` to stderr and exit with status 2."""
        self.exit(2, f"{self.prog}: error: {printable(message)} (see '{self.prog} --help')\n")


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows each option's default in ``--help``, except for flags and options without one."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if _plain_flag(action) or action.default is None or "%(default)" in (action.help or ""):
            return action.help
        return super()._get_help_string(action)


def _plain_flag(action: argparse.Action) -> bool:
    """A flag that only switches its default off or on (``store_true``/``store_false``)."""
    return action.nargs == 0 and not isinstance(action, argparse.BooleanOptionalAction)


def add_command(sub: Any, name: str, summary: str, description: str | None = None) -> Any:
    """Add a subcommand parser, summarised in its parent's help, that shows defaults in its help."""
    return sub.add_parser(
        name, help=summary, description=description or summary, formatter_class=HelpFormatter
    )


def add_json_argument(parser: argparse.ArgumentParser, what: str) -> None:
    """Add ``--json OUT``: write ``what`` as JSON to OUT, or to stdout with ``-``."""
    parser.add_argument(
        "--json",
        default=None,
        metavar="OUT",
        help=f"write {what} as JSON to OUT ('-': JSON alone on stdout, other lines on stderr)",
    )


def add_mesh_path_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--allow-any-mesh-path``: accept a targets file's meshes outside its folder."""
    parser.add_argument(
        "--allow-any-mesh-path",
        action="store_true",
        help="accept object meshes that a targets file names outside its own folder (absolute "
        "paths, '..', links leading out); without it such a problem is refused as invalid input",
    )


def scheduler_address(text: str) -> str:
    """Option type of ``--scheduler``: a Dask scheduler address, checked before any work.

    The check is :func:`sahgrasp.core.parallel.check_scheduler_address` (no connection is made
    here).
    """
    from sahgrasp.core.parallel import SchedulerError, check_scheduler_address

    try:
        return check_scheduler_address(text)
    except SchedulerError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def image_path(text: str) -> str:
    """Option type of ``--plot``: a file name whose suffix names an image format.

    Checked when the command line is parsed, so that a name matplotlib cannot write (no suffix,
    or an unknown one) fails before the work, not after it.
    """
    suffix = Path(text).suffix.lower()
    if suffix not in IMAGE_SUFFIXES:
        found = f"unknown suffix {suffix!r}" if suffix else "no suffix"
        raise argparse.ArgumentTypeError(
            f"{text!r} is not an image file name ({found}): end it in "
            f"{', '.join(IMAGE_SUFFIXES)}, e.g. fig9.png"
        )
    return text


def human_stream(json_out: str | None) -> TextIO:
    """Where the lines for a human go: stderr when stdout carries the JSON (``--json -``)."""
    return sys.stderr if json_out == "-" else sys.stdout


def printable(text: str) -> str:
    """``text`` safe for a terminal: control characters (ANSI escapes...) shown as escapes."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def check_json_inputs(hand: str | None = None, sequence: str | Path | None = None) -> None:
    """Read a user's hand-description and sequence files as JSON first, for a one-line error.

    The hand and sequence loaders let some malformed files (binary, UTF-16, nested thousands of
    levels deep) escape as RecursionError or UnicodeDecodeError; :func:`read_json` turns each into
    the loader's own error type. A hand name (``sah``) or a missing file is left to the loader.

    Raises:
        HandModelError: The hand description is a URDF, or not UTF-8 JSON.
        SequenceFileError: The sequence file is not UTF-8 JSON.
    """
    if hand is not None and Path(hand).suffix and _is_file(hand):
        _refuse_urdf(hand)
        read_json(hand, "hand description", HandModelError)
    if sequence is not None and _is_file(sequence):
        read_json(sequence, "sequence file", SequenceFileError)


def _is_file(path: str | Path) -> bool:
    """Whether ``path`` is a file; a path no file can have (too long, a loop) is the loader's."""
    try:
        return Path(path).is_file()
    except OSError:
        return False


def check_outputs(outputs: Iterable[str | None], inputs: Iterable[str | Path | None] = ()) -> None:
    """Check every output file before the work starts (``-`` is stdout, None is no output).

    Raises:
        OutputPathError: An output is an input, a folder, unwritable, or given twice.
    """
    inputs = list(inputs)
    seen: set[str] = set()
    for out in outputs:
        if out is None or out == "-":
            continue
        check_output_path(out, inputs=inputs)
        real = os.path.realpath(out)
        if real in seen:
            raise OutputPathError(f"output {out} is given twice; give each output its own file")
        seen.add(real)


def _refuse_urdf(hand: str) -> None:
    """A URDF given where a hand description goes: say what is expected and how to make one."""
    try:
        with open(hand, "rb") as f:
            start = f.read(512).lstrip(b"\xef\xbb\xbf \t\r\n")
    except OSError:
        return  # left to the loader, which names the file and the reason
    if Path(hand).suffix.lower() == ".urdf" or start.startswith(b"<"):
        raise HandModelError(
            f'{hand} is a URDF, but a hand (--hand, a targets file\'s "hand") is '
            f"{', '.join(HANDS)} or a hand-description JSON, which "
            "names the URDF and says which links are the fingertips and palm; write one as "
            "docs/how-to/add-a-hand.md shows"
        )


@contextlib.contextmanager
def output_file(path: str | None) -> Iterator[str | None]:
    """For writers that need a file name: a temporary name that becomes ``path`` on success.

    Yields None when there is no such output (``path`` None).
    """
    if path is None:
        yield None
        return
    with atomic_path(path) as tmp:
        yield str(tmp)


def _layout(data: Any, depth: int = 0) -> str:
    """Indented JSON down to the items of top-level entries, each item on one line.

    ``json.dumps`` with ``indent`` runs in pure Python (a 200 000-problem results file took half
    a minute); without it the C encoder writes each item.
    """
    pad = "  " * depth
    if depth < 2 and isinstance(data, dict) and data:
        body = ",\n".join(
            f"{pad}  {json.dumps(k)}: {_layout(v, depth + 1)}" for k, v in data.items()
        )
        return f"{{\n{body}\n{pad}}}"
    if depth < 2 and isinstance(data, list) and data:
        body = ",\n".join(f"{pad}  {_layout(v, depth + 1)}" for v in data)
        return f"[\n{body}\n{pad}]"
    return json.dumps(data, allow_nan=False)


def json_text(data: Any) -> str:
    """``data`` as strict JSON text (undefined numbers as ``null``), indented two levels deep."""
    try:
        return _layout(data) + "\n"
    except ValueError:  # NaN or inf somewhere: rare, so only then pay for a cleaned copy
        return _layout(json_safe(data)) + "\n"


def write_stdout(text: str) -> None:
    """Write ``text`` to stdout whole, or raise ``BrokenPipeError`` when its reader went away.

    With ``PYTHONUNBUFFERED`` set (as in many containers), ``sys.stdout.write`` makes one
    ``write`` call and ignores how much of it went through: a reader that closes mid-document
    left a truncated document and exit status 0. Here every byte is written or the error
    raised, so that the command exits with 141 (see :mod:`sahgrasp.cli`).
    """
    sys.stdout.flush()
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # a stream without a file (a test harness)
        sys.stdout.write(text)
        return
    data = memoryview(text.encode("utf-8", errors="backslashreplace"))
    while data:
        data = data[os.write(fd, data) :]


def emit_json(data: Any, out: str | None) -> None:
    """Write ``data`` as strict JSON (undefined numbers as ``null``) to ``out``.

    ``out`` ``-`` or None prints it on stdout; a path is written atomically and reported.
    """
    text = json_text(data)
    if out is None or out == "-":
        write_stdout(text)
        return
    write_bytes_atomic(out, text.encode("utf-8"))
    print(f"wrote {out}")


def work_executor(args: argparse.Namespace) -> Any:
    """Where a command's work runs, from ``--scheduler`` and ``--workers``.

    A context manager giving None (this process: one worker), a local process pool, or a Dask
    cluster's executor.
    """
    if args.scheduler is not None:
        from sahgrasp.core.executors import open_executor

        return open_executor(args.scheduler)
    if args.workers <= 1:
        return contextlib.nullcontext(None)
    from sahgrasp.core.parallel import process_pool

    return process_pool(args.workers)
