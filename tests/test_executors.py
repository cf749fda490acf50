"""Executors of the chunked work: local processes, Dask, any Executor."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import pytest

from sahgrasp.errors import InvalidSettingsError
from sahgrasp.sequence.executors import open_executor


def test_an_executor_is_used_as_is_and_left_open() -> None:
    with ThreadPoolExecutor(1) as pool:
        with open_executor(pool) as executor:
            assert executor is pool
        assert pool.submit(sum, [2, 2]).result() == 4


def test_anything_else_is_refused_naming_what_is_valid() -> None:
    with pytest.raises(InvalidSettingsError, match="Dask scheduler address"), open_executor(42):
        pass
