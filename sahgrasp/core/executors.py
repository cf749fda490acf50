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
from collections.abc import Iterator
from concurrent.futures import CancelledError, Executor
from contextlib import contextmanager
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

__all__ = ["open_executor"]


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
        with _dask_client(check_scheduler_address(spec)) as client:
            yield client.get_executor(pure=False)
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
    host, port = address.removeprefix("tcp://").rsplit(":", 1)
    try:
        socket.create_connection((host.strip("[]"), int(port)), SCHEDULER_TIMEOUT_S).close()
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise SchedulerError(f"cannot reach the Dask scheduler at {address}: {reason}") from None
    from dask.distributed import Client

    log = logging.getLogger("distributed.client")
    level = log.level
    log.setLevel(logging.CRITICAL)
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
            except (CancelledError, OSError, RuntimeError):
                # A lost scheduler cancels the chunks in flight (CancelledError); a submit after
                # it fails on the closed connection. Either way the client is no longer running.
                if client.status == "running":
                    raise  # cancelled on purpose, or another failure: not a lost scheduler
                raise SchedulerLostError(f"lost the Dask scheduler at {address} mid-run") from None
    finally:
        log.setLevel(level)
