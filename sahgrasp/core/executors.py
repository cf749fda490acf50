"""Where the chunks of the search run: any :class:`concurrent.futures.Executor`.

* local worker processes (default): :func:`sahgrasp.core.parallel.process_pool`, started with
  ``spawn``, one worker per core unless told otherwise, each with a single BLAS thread, each
  ending when the process that started it ends (even by ``kill -9``);
* Dask distributed: a scheduler address (``tcp://HOST:PORT``) or a ``dask.distributed.Client``;
  chunks go through ``Client.get_executor()``. Dask reruns the chunks of a worker that dies. An
  address is checked before anything starts, a scheduler that does not answer is given up after
  :data:`~sahgrasp.core.parallel.SCHEDULER_TIMEOUT_S`, and one lost mid-run ends the run with a
  :class:`~sahgrasp.core.parallel.SchedulerError` (the work done so far stays, to be resumed);
* anything else with the ``Executor`` interface, e.g. ``mpi4py.futures.MPIPoolExecutor``.

Chunks are pure functions of their arguments, so the result does not depend on which of these ran
them, nor on how many workers they had.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
import weakref
from collections.abc import Callable, Iterator
from concurrent.futures import CancelledError, Executor, Future, InvalidStateError
from contextlib import contextmanager, suppress
from typing import Any

from sahgrasp.core.errors import InvalidSettingsError
from sahgrasp.core.extras import require_extra
from sahgrasp.core.parallel import (
    SCHEDULER_TIMEOUT_S,
    SchedulerError,
    SchedulerLostError,
    check_scheduler_address,
    process_pool,
)

__all__ = ["WatchedExecutor", "open_executor"]

_MUTED_LOGS = ("distributed.client", "tornado.application")
"""Loggers muted while a scheduler's client is open: a lost scheduler is one
:class:`SchedulerError` line, not their tracebacks."""


@contextmanager
def open_executor(spec: Any = None, workers: int | None = None) -> Iterator[Executor]:
    """Yield an executor for ``spec``; close what this function opened, and only that.

    Args:
        spec: None for local processes; a Dask scheduler address such as ``tcp://host:8786``;
            a ``dask.distributed.Client``; or any ``Executor`` (used as is, left open).
        workers: Number of local processes (only when ``spec`` is None).

    Raises:
        SchedulerError: A malformed or unsupported scheduler address, a scheduler that cannot be
            reached, or one lost while the block runs (its chunks cancelled).
        InvalidSettingsError: ``spec`` is none of the above.
    """
    if spec is None:
        with process_pool(workers) as pool:
            yield pool
    elif isinstance(spec, Executor):
        yield spec
    elif isinstance(spec, str):
        address = check_scheduler_address(spec)
        with _dask_client(address) as client:
            watched = WatchedExecutor(client.get_executor(pure=False), client, address)
            try:
                yield watched
            finally:
                watched.stop()
    elif hasattr(spec, "get_executor"):
        yield spec.get_executor(pure=False)
    else:
        raise InvalidSettingsError(
            f"cannot run the search on {spec!r}: give None (local processes), a Dask scheduler "
            "address, a dask.distributed.Client or a concurrent.futures.Executor"
        )


@contextmanager
def _dask_client(address: str) -> Iterator[Any]:
    """A ``dask.distributed.Client`` of the scheduler at ``address`` (``tcp://HOST:PORT``).

    A plain TCP connection is tried first: a port where nothing listens is then one clear line
    at once, where Dask retries for its whole connect timeout. While the client is open, Dask's
    own log of a lost connection is muted: the :class:`SchedulerError` raised instead says it.
    """
    require_extra("cluster", f"the Dask scheduler {address}")  # before connecting: one line
    try:
        _connect(address, SCHEDULER_TIMEOUT_S)
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise SchedulerError(f"cannot reach the Dask scheduler at {address}: {reason}") from None
    from dask.distributed import Client

    # Dask's client and its event loop (tornado's callbacks) log the lost connection and the
    # futures it breaks, tracebacks included, also after the client is closed: once the
    # scheduler is lost they stay muted.
    logs = [logging.getLogger(name) for name in _MUTED_LOGS]
    levels = [log.level for log in logs]
    for log in logs:
        log.setLevel(logging.CRITICAL)
    lost = False
    try:
        try:
            client = Client(address, timeout=SCHEDULER_TIMEOUT_S)
        except OSError as exc:  # something listens there, but it is no Dask scheduler
            raise SchedulerError(
                f"no Dask scheduler answers at {address} within {SCHEDULER_TIMEOUT_S:g} s ({exc})"
            ) from None
        with client:
            try:
                yield client
            except SchedulerLostError:
                lost = True
                raise
            except (CancelledError, OSError, RuntimeError):
                # A lost scheduler cancels the chunks in flight (CancelledError); a submit after
                # it fails on the closed connection. Either way the client is no longer running.
                if client.status == "running":
                    raise  # cancelled on purpose, or another failure: not a lost scheduler
                lost = True
                raise SchedulerLostError(f"lost the Dask scheduler at {address} mid-run") from None
    finally:
        if not lost:
            for log, level in zip(logs, levels, strict=True):
                log.setLevel(level)


class WatchedExecutor(Executor):
    """A Dask client's executor whose futures fail once its scheduler is gone for good.

    Dask cancels the futures of a client whose scheduler connection is lost after its reconnect
    timeout, but an error inside its event loop can leave them pending for ever, and a run
    waiting on them would hang. A thread looks every ``period_s``: while the client is not
    running or its connection to the scheduler is closed, the scheduler's port is probed (only
    then, so that a healthy scheduler is not sent connections it logs), and once it has refused
    connections for ``patience_s``, every future not done fails with
    :class:`~sahgrasp.core.parallel.SchedulerLostError`.

    Args:
        inner: The client's executor (``Client.get_executor()``).
        client: The client (its ``status`` and ``scheduler_comm`` are looked at).
        address: The scheduler's ``tcp://HOST:PORT``.
        patience_s: How long the scheduler may be unreachable [s]; twice Dask's reconnect
            timeout by default, so that Dask's own cancellation comes first.
        period_s: How often the thread looks [s].
        probe: Whether the scheduler accepts connections (tests replace it).
    """

    def __init__(
        self,
        inner: Executor,
        client: Any,
        address: str,
        patience_s: float = 2.0 * SCHEDULER_TIMEOUT_S,
        period_s: float = 1.0,
        probe: Callable[[str], bool] | None = None,
    ) -> None:
        self._inner = inner
        self._client = client
        self._address = address
        self._probe = probe if probe is not None else _accepts_connections
        self._pending: weakref.WeakSet[Future[Any]] = weakref.WeakSet()
        self._lock = threading.Lock()
        self._stopped = threading.Event()
        self.lost = False
        self._thread = threading.Thread(
            target=self._watch, args=(patience_s, period_s), name="sahgrasp-scheduler-watch",
            daemon=True,
        )  # fmt: skip
        self._thread.start()

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future[Any]:
        """Submit to the client's executor, the future watched until it is done."""
        if self.lost:
            raise SchedulerLostError(f"lost the Dask scheduler at {self._address} mid-run")
        future = self._inner.submit(fn, *args, **kwargs)
        with self._lock:
            self._pending.add(future)
        return future

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Stop watching and shut the client's executor down."""
        self.stop()
        self._inner.shutdown(wait=wait)

    def stop(self) -> None:
        """Stop watching (the futures are left as they are)."""
        self._stopped.set()

    def _suspect(self) -> bool:
        if getattr(self._client, "status", "running") != "running":
            return True
        comm = getattr(getattr(self._client, "scheduler_comm", None), "comm", None)
        return comm is None or bool(getattr(comm, "closed", lambda: False)())

    def _watch(self, patience_s: float, period_s: float) -> None:
        unreachable_since: float | None = None
        while not self._stopped.wait(period_s):
            if not self._suspect() or self._probe(self._address):
                unreachable_since = None
                continue
            now = time.monotonic()
            unreachable_since = now if unreachable_since is None else unreachable_since
            if now - unreachable_since < patience_s:
                continue
            self.lost = True
            with self._lock:
                pending = [f for f in self._pending if not f.done()]
            for future in pending:
                with suppress(InvalidStateError):  # Dask settled it meanwhile
                    future.set_exception(
                        SchedulerLostError(f"lost the Dask scheduler at {self._address} mid-run")
                    )
            return


def _connect(address: str, timeout_s: float) -> None:
    """Open and close a TCP connection to ``tcp://HOST:PORT``; OSError if none is accepted."""
    host, port = address.removeprefix("tcp://").rsplit(":", 1)
    socket.create_connection((host.strip("[]"), int(port)), timeout_s).close()


def _accepts_connections(address: str) -> bool:
    """Whether something accepts a TCP connection at ``tcp://HOST:PORT`` within a second."""
    try:
        _connect(address, 1.0)
    except OSError:
        return False
    return True
