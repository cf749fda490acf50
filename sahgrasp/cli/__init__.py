"""The ``sahgrasp`` command: parses arguments, calls the API, prints.

Each subcommand lives in its own module with ``add_parser(subparsers)`` and ``run(args) -> int``.
Building the parser imports only these modules, which import nothing heavy at module level (numpy,
Pinocchio, matplotlib, meshcat, dask... are imported inside ``run``), so ``sahgrasp --help`` is
quick.

Exit status: 0 everything succeeded; 1 the command ran but some problems were unsolved or invalid;
2 usage or input error (one ``sahgrasp: error: ...`` line); 130 interrupted by Ctrl-C, SIGTERM or
SIGHUP (one line, for ``sequence`` the command that resumes the search); 141 stdout closed early
(e.g. piped into ``head``), silently.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import signal
import sys
from collections.abc import Iterator, Sequence
from types import FrameType

from sahgrasp.cli.common import Parser, printable
from sahgrasp.core.errors import SahGraspError

__all__ = ["EXIT_BROKEN_PIPE", "EXIT_INPUT", "EXIT_INTERRUPTED", "main"]

COMMANDS = (
    "info",
    "solve",
    "plan",
    "check",
    "bench",
    "atlas",
    "sequence",
    "learn",
    "demo",
    "screenshot",
)

EXIT_INPUT = 2
"""Usage or input error."""
EXIT_INTERRUPTED = 130
"""Ctrl-C, SIGTERM or SIGHUP (128 + SIGINT, as a shell reports Ctrl-C)."""
EXIT_BROKEN_PIPE = 141
"""The reader of stdout went away (128 + SIGPIPE, as a shell reports it)."""

_STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGTERM", "SIGHUP") if hasattr(signal, n))


class _Version(argparse.Action):
    """``--version``: looked up only when asked, importlib.metadata is not free."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: object) -> None:
        super().__init__(
            option_strings, argparse.SUPPRESS, nargs=0, default=argparse.SUPPRESS,
            help="print the version and exit",
        )  # fmt: skip

    def __call__(self, parser: argparse.ArgumentParser, *args: object, **kwargs: object) -> None:
        from importlib.metadata import PackageNotFoundError, version

        try:
            text = version("sahgrasp")
        except PackageNotFoundError:
            text = "unknown (not installed)"
        print(f"sahgrasp {text}")
        parser.exit(0)


def _parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="sahgrasp", description="Precision grasps for anthropomorphic robot hands."
    )
    parser.add_argument("--version", action=_Version)
    sub = parser.add_subparsers(
        dest="command", required=True, metavar="COMMAND", help="see 'sahgrasp COMMAND --help'"
    )
    for name in COMMANDS:
        module = importlib.import_module(f"sahgrasp.cli.{name}")
        module.add_parser(sub)
    return parser


@contextlib.contextmanager
def _stop_signals_interrupt() -> Iterator[None]:
    """While the command runs, SIGTERM and SIGHUP raise KeyboardInterrupt, as Ctrl-C does.

    Worker processes forked meanwhile inherit the handler; in them it restores the default action
    and re-raises the signal, so that they still die of it.
    """
    owner = os.getpid()

    def interrupt(signum: int, frame: FrameType | None) -> None:
        if os.getpid() != owner:
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
        raise KeyboardInterrupt

    try:
        previous = {s: signal.signal(s, interrupt) for s in _STOP_SIGNALS}
    except ValueError:  # not the main thread (main() called from a thread): leave signals alone
        yield
        return
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def _error(message: str) -> int:
    print(f"sahgrasp: error: {printable(message)}", file=sys.stderr)
    return EXIT_INPUT


def _os_error(exc: OSError) -> str:
    if exc.strerror and exc.filename is not None:
        return f"{exc.strerror}: {exc.filename}"
    return str(exc)


def _run(argv: Sequence[str] | None) -> int:
    args = _parser().parse_args(argv)
    hint = getattr(args, "on_interrupt", None)
    try:
        code = int(args.run(args))
    except KeyboardInterrupt:
        print(f"sahgrasp: {hint(args) if hint else 'interrupted'}", file=sys.stderr)
        return EXIT_INTERRUPTED
    except SahGraspError as exc:
        from sahgrasp.core.parallel import SchedulerLostError

        if not isinstance(exc, SchedulerLostError) or hint is None:
            raise
        # A lost scheduler stops the run as an interruption does: say how to continue it.
        resume = hint(args).removeprefix("interrupted")
        raise SchedulerLostError(f"{exc}{resume}") from None
    sys.stdout.flush()  # a closed pipe shows here, while BrokenPipeError can still be handled
    return code


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the process exit status (see the module docstring)."""
    with contextlib.suppress(AttributeError, ValueError):  # a stream replaced by a test harness
        sys.stdout.reconfigure(errors="backslashreplace")  # type: ignore[union-attr]
    try:
        with _stop_signals_interrupt():
            return _run(argv)
    except SystemExit as exc:  # --help, --version, or a usage error already printed
        return exc.code if isinstance(exc.code, int) else 0 if exc.code is None else EXIT_INPUT
    except KeyboardInterrupt:  # before the command started
        print("sahgrasp: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # Point stdout at /dev/null so that the interpreter's last flush does not fail again.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except SahGraspError as exc:
        return _error(str(exc))
    except OSError as exc:  # a user's path: missing, unreadable, a full disk...
        return _error(_os_error(exc))
