"""Where the chunks of the search run: any :class:`concurrent.futures.Executor`.

* local worker processes (default): :func:`sahgrasp.parallel.process_pool`, started with
  ``spawn``, one worker per core unless told otherwise, each with a single BLAS thread, each
  ending when the process that started it ends (even by ``kill -9``);
* Dask distributed: a scheduler address (``tcp://HOST:PORT``) or a ``dask.distributed.Client``;
  chunks go through ``Client.get_executor()``. Dask reruns the chunks of a worker that dies;
* anything else with the ``Executor`` interface, e.g. ``mpi4py.futures.MPIPoolExecutor``.

Chunks are pure functions of their arguments, so the result does not depend on which of these ran
them, nor on how many workers they had.
"""

from __future__ import annotations

from collections.abc import Iterator
from concurrent.futures import Executor
from contextlib import contextmanager
from typing import Any

from sahgrasp.errors import InvalidSettingsError
from sahgrasp.parallel import process_pool

__all__ = ["open_executor"]


@contextmanager
def open_executor(spec: Any = None, workers: int | None = None) -> Iterator[Executor]:
    """Yield an executor for ``spec``; close what this function opened, and only that.

    Args:
        spec: None for local processes; a Dask scheduler address such as ``tcp://host:8786``;
            a ``dask.distributed.Client``; or any ``Executor`` (used as is, left open).
        workers: Number of local processes (only when ``spec`` is None).
    """
    if spec is None:
        with process_pool(workers) as pool:
            yield pool
    elif isinstance(spec, Executor):
        yield spec
    elif isinstance(spec, str):
        from dask.distributed import Client

        with Client(spec) as client:
            yield client.get_executor(pure=False)
    elif hasattr(spec, "get_executor"):
        yield spec.get_executor(pure=False)
    else:
        raise InvalidSettingsError(
            f"cannot run the search on {spec!r}: give None (local processes), a Dask scheduler "
            "address, a dask.distributed.Client or a concurrent.futures.Executor"
        )
