"""Local worker processes that never outlive the process that started them.

:func:`process_pool` is the one way sahgrasp starts worker processes on this machine::

    from sahgrasp.core.parallel import process_pool

    with process_pool(workers=2) as pool:  # a concurrent.futures.ProcessPoolExecutor
        results = list(pool.map(function, items))

Its workers are started with ``spawn`` and one BLAS thread each, and each runs
:func:`die_with_parent` before its first task, so a ``kill -9`` or SIGTERM of the parent does not
leave them running (holding memory and the parent's pipes). Two mechanisms, because each misses a
case the other covers:

* Linux: ``prctl(PR_SET_PDEATHSIG, SIGTERM)``; the kernel sends the signal even while the worker
  is inside a long C call holding the GIL, where no Python thread can run;
* everywhere: a daemon thread blocked on :func:`multiprocessing.parent_process`'s sentinel, which
  becomes ready when the parent ends; it also catches a parent that died before the worker
  armed ``PR_SET_PDEATHSIG``.

All workers are started before the pool is handed out, from the thread that enters the ``with``
block (Linux sends the parent-death signal when the *thread* that started a worker ends, so enter
it from a thread that lives as long as the pool), with the stop signals (SIGINT, SIGTERM, SIGHUP)
held meanwhile: a stop that unwinds the parent while it writes a spawned worker's start-up data
makes that worker print a traceback (``EOFError``, ``FileNotFoundError``); held, it is acted on
once the workers are up, as a ``KeyboardInterrupt`` in the parent.

SIGINT ends a worker at once and silently (the default action, not Python's
``KeyboardInterrupt``): Ctrl-C in a terminal reaches the whole process group, so the workers stop
without printing a traceback each and without finishing their tasks, and the parent, which gets
the ``KeyboardInterrupt``, closes a pool that has nothing left to wait for.

SIGHUP (a closed terminal, ``kill -HUP`` of the process group) must not reach ``multiprocessing``'s
resource tracker: it ignores SIGINT and SIGTERM but dies of SIGHUP, and the tracker started again
for the pool's shutdown then prints a ``KeyError`` traceback for each semaphore it never saw.
:func:`process_pool` therefore starts the tracker with SIGHUP ignored (an ignored signal stays
ignored across ``exec``); the tracker still ends with this process, when its pipe closes.

A Dask cluster is the other place work runs. :func:`check_scheduler_address` is the one check of a
scheduler address (``--scheduler`` of every command, :func:`sahgrasp.sequence.open_executor`):
it refuses what Dask would fail on later with a traceback, and what sahgrasp does not support.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import re
import signal
import sys
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor, wait
from contextlib import contextmanager

from sahgrasp.core.errors import InvalidSettingsError, SahGraspError

__all__ = [
    "SCHEDULER_ADDRESS_FORMS",
    "SCHEDULER_TIMEOUT_S",
    "SINGLE_THREADED_BLAS",
    "WORKERS_PER_CORE_LIMIT",
    "SchedulerError",
    "SchedulerLostError",
    "check_scheduler_address",
    "check_workers",
    "die_with_parent",
    "process_pool",
    "watch_parent",
]

SINGLE_THREADED_BLAS = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
"""Environment of local workers, as Dask's nanny gives its workers: with one BLAS thread per
process, workers do not compete with each other's (spinning) BLAS threads for the cores."""

_PR_SET_PDEATHSIG = 1
"""``PR_SET_PDEATHSIG`` of ``<linux/prctl.h>``."""

_ORPHAN_EXIT_CODE = 128 + signal.SIGTERM
"""Exit status of a worker that ends because its parent did (as if killed by SIGTERM)."""


WORKERS_PER_CORE_LIMIT = 4
"""At most this many workers per core: the IK is CPU-bound, so more only add memory (some
100 MB per worker)."""


def check_workers(workers: int | None) -> int:
    """The number of worker processes for ``workers`` (None: one per core).

    Raises:
        InvalidSettingsError: ``workers`` is not an integer in 1 .. 4 per core.
    """
    cores = os.cpu_count() or 1
    if workers is None:
        return cores
    limit = WORKERS_PER_CORE_LIMIT * cores
    if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= limit:
        raise InvalidSettingsError(
            f"workers must be an integer >= 1 and <= {limit} ({WORKERS_PER_CORE_LIMIT} per "
            f"core; None: one per core), got {workers!r}"
        )
    return workers


SCHEDULER_ADDRESS_FORMS = "tcp://HOST:PORT or HOST:PORT (e.g. tcp://127.0.0.1:8786)"
"""The scheduler addresses sahgrasp accepts, as said in its messages."""

SCHEDULER_TIMEOUT_S = 10.0
"""How long connecting (or reconnecting) to a Dask scheduler may take [s] before the run gives up.

Dask's own default, 30 s, made a mistyped local address wait half a minute; a scheduler answers
within a second on a local network, and a port where nothing listens is refused at once."""

_HOST_PORT = re.compile(r"(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9](?:[A-Za-z0-9.-]*[A-Za-z0-9])?)"
                        r":(?P<port>[0-9]{1,5})")  # fmt: skip
_UNSUPPORTED_SCHEMES = {
    "tls": "TLS needs certificates, which sahgrasp does not pass on (reach a remote scheduler "
    "over an SSH tunnel with tcp://)",
    "inproc": "an in-process scheduler lives in another process's memory; pass the "
    "dask.distributed.Client to the Python API instead",
    "ws": "sahgrasp connects over TCP only",
    "wss": "sahgrasp connects over TCP only",
    "ucx": "sahgrasp connects over TCP only",
}


class SchedulerError(SahGraspError):
    """A Dask scheduler address is malformed or unsupported, unreachable, or lost mid-run."""


class SchedulerLostError(SchedulerError):
    """The Dask scheduler went away mid-run: its chunks were cancelled; what was done is kept."""


def check_scheduler_address(address: object) -> str:
    """The Dask scheduler address ``address`` in its full form ``tcp://HOST:PORT``.

    Only the address is checked here (no connection is made): its form, and a port in 1 .. 65535.

    Args:
        address: ``tcp://HOST:PORT`` or ``HOST:PORT``; HOST a name, an IPv4 address or a
            bracketed IPv6 address.

    Raises:
        SchedulerError: Not a string, an empty or malformed address, a port out of range, or a
            scheme sahgrasp does not support (``tls://``, ``ws://``, ``inproc://``...); the
            message names the valid forms.
    """
    if not isinstance(address, str):
        raise SchedulerError(
            f"a Dask scheduler address must be a string, {SCHEDULER_ADDRESS_FORMS}; got {address!r}"
        )
    scheme, sep, rest = address.partition("://")
    if not sep:
        scheme, rest = "tcp", address
    if scheme in _UNSUPPORTED_SCHEMES:
        raise SchedulerError(
            f"scheduler address {address!r} is not supported: {_UNSUPPORTED_SCHEMES[scheme]}; "
            f"give {SCHEDULER_ADDRESS_FORMS}"
        )
    match = _HOST_PORT.fullmatch(rest) if scheme == "tcp" else None
    if match is None or not 1 <= int(match["port"]) <= 65535:
        raise SchedulerError(
            f"{address!r} is not a Dask scheduler address: give {SCHEDULER_ADDRESS_FORMS}, "
            "the port in 1..65535"
        )
    return f"tcp://{match['host']}:{int(match['port'])}"


@contextmanager
def process_pool(workers: int | None = None) -> Iterator[ProcessPoolExecutor]:
    """Yield a ``ProcessPoolExecutor`` whose workers end when this process ends.

    Workers are started with ``spawn`` while :data:`SINGLE_THREADED_BLAS` is in the environment
    (values the user has set are kept); the environment is restored when the pool closes. On
    exit the queued work is cancelled and the running tasks are waited for.

    Args:
        workers: Worker processes (default: one per core).

    Raises:
        InvalidSettingsError: ``workers`` is not an integer >= 1.
    """
    count = check_workers(workers)
    _start_resource_tracker()
    saved = {k: os.environ.get(k) for k in SINGLE_THREADED_BLAS}
    os.environ.update({k: v for k, v in SINGLE_THREADED_BLAS.items() if saved[k] is None})
    pool = ProcessPoolExecutor(
        count,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=die_with_parent,
        initargs=(os.getpid(),),
    )
    try:
        with _stop_signals_held():
            wait([pool.submit(time.monotonic) for _ in range(count)])  # one spawn per submit
        yield pool
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)


_STOP_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")


def _start_resource_tracker() -> None:
    """Start multiprocessing's resource tracker, if not running, immune to SIGHUP (module doc)."""
    hup = getattr(signal, "SIGHUP", None)
    if hup is None or threading.current_thread() is not threading.main_thread():
        return  # no SIGHUP (Windows), or signal dispositions cannot be changed from this thread
    from multiprocessing import resource_tracker

    previous = signal.signal(hup, signal.SIG_IGN)
    try:
        resource_tracker.ensure_running()
    finally:
        signal.signal(hup, previous)


@contextmanager
def _stop_signals_held() -> Iterator[None]:
    """Record the stop signals instead of acting on them; raise KeyboardInterrupt after, if any."""
    if threading.current_thread() is not threading.main_thread():
        yield  # signal handlers can only be set in the main thread
        return
    caught: list[int] = []
    numbers = [getattr(signal, name) for name in _STOP_SIGNALS if hasattr(signal, name)]
    previous = {n: signal.signal(n, lambda number, _: caught.append(number)) for n in numbers}
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
    if caught:
        raise KeyboardInterrupt


def die_with_parent(parent_pid: int) -> None:
    """Worker initializer: end this process when its parent ``parent_pid`` ends (module doc).

    Args:
        parent_pid: Process id of the parent, read in the parent (``os.getpid()``).
    """
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # an ignored SIGTERM survives the exec of spawn
    _arm_parent_death_signal(signal.SIGTERM)
    watch_parent()
    if os.getppid() != parent_pid:  # the parent ended before the watch started
        os._exit(_ORPHAN_EXIT_CODE)


def watch_parent() -> threading.Thread | None:
    """Start a daemon thread that ends this process as soon as its parent process ends.

    Portable (it waits on the parent sentinel that ``multiprocessing`` gives every child it
    starts); does nothing in a process that ``multiprocessing`` did not start.

    Returns:
        The watching thread, or None when there is no ``multiprocessing`` parent.
    """
    parent = multiprocessing.parent_process()
    if parent is None:
        return None

    def wait_for_parent() -> None:
        parent.join()  # returns when the parent's end of the sentinel pipe closes
        os._exit(_ORPHAN_EXIT_CODE)

    thread = threading.Thread(target=wait_for_parent, name="sahgrasp-watch-parent", daemon=True)
    thread.start()
    return thread


def _arm_parent_death_signal(signum: int) -> bool:
    """Ask Linux to send ``signum`` to this process when its parent ends; False if unsupported."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        status = libc.prctl(
            ctypes.c_int(_PR_SET_PDEATHSIG), ctypes.c_ulong(signum), ctypes.c_ulong(0),
            ctypes.c_ulong(0), ctypes.c_ulong(0),
        )  # fmt: skip
    except (OSError, AttributeError):  # no C library symbols, or no prctl in it
        return False
    return int(status) == 0
