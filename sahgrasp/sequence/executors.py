"""Where the chunks of the search run: any :class:`concurrent.futures.Executor`.

* local worker processes (default): a ``ProcessPoolExecutor`` started with ``spawn``, one worker
  per core unless told otherwise, each with a single BLAS thread;
* Dask distributed: a scheduler address (``tcp://HOST:PORT``) or a ``dask.distributed.Client``;
  chunks go through ``Client.get_executor()``. Dask reruns the chunks of a worker that dies;
* anything else with the ``Executor`` interface, e.g. ``mpi4py.futures.MPIPoolExecutor``.

Chunks are pure functions of their arguments, so the result does not depend on which of these ran
them, nor on how many workers they had.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Iterator
from concurrent.futures import Executor, ProcessPoolExecutor
from contextlib import contextmanager
from typing import Any

from sahgrasp.errors import InvalidSettingsError

__all__ = ["open_executor"]

SINGLE_THREADED_BLAS = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
"""Environment of local workers, as Dask's nanny gives its workers: with one BLAS thread per
process, workers do not compete with each other's (spinning) BLAS threads for the cores."""


@contextmanager
def _local_pool(workers: int | None) -> Iterator[ProcessPoolExecutor]:
    """Worker processes on this machine, started with ``spawn`` (one per core by default).

    The processes are started while :data:`SINGLE_THREADED_BLAS` is in the environment (values
    the user has set are kept); the environment is restored when the pool closes.
    """
    count = (os.cpu_count() or 1) if workers is None else workers
    if count < 1:
        raise InvalidSettingsError(f"workers must be >= 1, got {count}")
    saved = {k: os.environ.get(k) for k in SINGLE_THREADED_BLAS}
    os.environ.update({k: v for k, v in SINGLE_THREADED_BLAS.items() if saved[k] is None})
    pool = ProcessPoolExecutor(count, mp_context=multiprocessing.get_context("spawn"))
    try:
        yield pool
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)


@contextmanager
def open_executor(spec: Any = None, workers: int | None = None) -> Iterator[Executor]:
    """Yield an executor for ``spec``; close what this function opened, and only that.

    Args:
        spec: None for local processes; a Dask scheduler address such as ``tcp://host:8786``;
            a ``dask.distributed.Client``; or any ``Executor`` (used as is, left open).
        workers: Number of local processes (only when ``spec`` is None).
    """
    if spec is None:
        with _local_pool(workers) as pool:
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
