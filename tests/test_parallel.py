"""Local worker processes: they end with their parent, however the parent ends."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import pytest

from sahgrasp.core.errors import InvalidSettingsError
from sahgrasp.core.parallel import (
    SINGLE_THREADED_BLAS,
    SchedulerError,
    check_scheduler_address,
    check_workers,
    process_pool,
)

psutil = pytest.importorskip("psutil")

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
CLI = "import sys; from sahgrasp.cli import main; sys.exit(main())"

WATCH_ONLY = """
import multiprocessing, os, time
from concurrent.futures import ProcessPoolExecutor
from sahgrasp.core.parallel import watch_parent

if __name__ == "__main__":
    spawn = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(1, mp_context=spawn, initializer=watch_parent) as pool:
        print(pool.submit(os.getpid).result(), flush=True)
        time.sleep(600)
"""
"""A parent whose worker has only the portable watch (no PR_SET_PDEATHSIG), as off Linux."""


def _wait_until(condition: object, seconds: float, what: str) -> None:
    deadline = time.monotonic() + seconds
    while not condition():  # type: ignore[operator]
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {seconds} s waiting for {what}")
        time.sleep(0.1)


def _alive(processes: list[psutil.Process]) -> list[psutil.Process]:
    """The processes still running (a zombie holds no memory: an unreaped orphan is dead)."""
    alive = []
    for p in processes:
        try:
            if p.is_running() and p.status() != psutil.STATUS_ZOMBIE:
                alive.append(p)
        except psutil.NoSuchProcess:
            pass
    return alive


def _workers(parent: subprocess.Popen[bytes]) -> list[psutil.Process]:
    children = psutil.Process(parent.pid).children(recursive=True)
    return [p for p in children if "spawn_main" in " ".join(p.cmdline())]


def _first_cell_done(out: Path) -> bool:
    try:
        return bool(json.loads((out / "checkpoint" / "round-001.json").read_text())["cells"])
    except (OSError, ValueError, KeyError):
        return False


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGKILL, signal.SIGTERM], ids=["kill-9", "term"])
def test_sequence_workers_end_with_a_killed_parent(tmp_path: Path, signum: int) -> None:
    args = ["sequence", "--grid", "4", "--problems", "100", "--rounds", "3", "--workers", "2",
            "--out", str(tmp_path)]  # fmt: skip
    parent = subprocess.Popen(
        [sys.executable, "-c", CLI, *args], env=ENV,
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    descendants: list[psutil.Process] = []
    try:
        _wait_until(lambda: _first_cell_done(tmp_path), 120, "the first grid cell")
        assert len(_workers(parent)) == 2
        descendants = psutil.Process(parent.pid).children(recursive=True)
        parent.send_signal(signum)
        parent.wait(10)
        _wait_until(lambda: not _alive(descendants), 5, f"{_alive(descendants)} to end")
    finally:
        _kill_all(parent, descendants)


def _kill_all(parent: subprocess.Popen[bytes], descendants: list[psutil.Process]) -> None:
    """Leave nothing running, even when the test fails."""
    if parent.poll() is None:
        descendants += psutil.Process(parent.pid).children(recursive=True)
        parent.kill()
    parent.wait()
    for p in _alive(descendants):
        p.kill()


def test_the_portable_watch_ends_a_worker_without_prctl() -> None:
    parent = subprocess.Popen(
        [sys.executable, "-c", WATCH_ONLY], env=ENV, stdout=subprocess.PIPE, text=True
    )
    try:
        assert parent.stdout is not None
        worker = psutil.Process(int(parent.stdout.readline()))
        assert worker.ppid() == parent.pid
        parent.kill()
        parent.wait()
        _wait_until(lambda: not _alive([worker]), 5, f"worker {worker.pid} to end")
    finally:
        parent.kill()
        parent.wait()


def test_pool_workers_have_one_blas_thread() -> None:
    before = {k: os.environ.get(k) for k in SINGLE_THREADED_BLAS}
    with process_pool(1) as pool:
        blas = {k: pool.submit(os.getenv, k).result() for k in SINGLE_THREADED_BLAS}
        parent = pool.submit(os.getppid).result()
    assert blas == {k: before[k] or "1" for k in SINGLE_THREADED_BLAS}
    assert parent == os.getpid()
    assert {k: os.environ.get(k) for k in SINGLE_THREADED_BLAS} == before


def test_sigint_ends_a_busy_worker_at_once() -> None:
    with process_pool(1) as pool:
        worker = psutil.Process(pool.submit(os.getpid).result())
        busy = pool.submit(time.sleep, 30)  # short: a worker that ignores SIGINT is waited for
        worker.send_signal(signal.SIGINT)
        with pytest.raises(BrokenProcessPool):
            busy.result(timeout=20)
    assert not _alive([worker])


@pytest.mark.parametrize("workers", [0, -1, True, 1.5, "2", 10**6])
def test_bad_worker_counts_are_refused(workers: object) -> None:
    with pytest.raises(InvalidSettingsError, match=r"workers must be an integer >= 1"):
        check_workers(workers)  # type: ignore[arg-type]
    with (
        pytest.raises(InvalidSettingsError, match=r"workers must be an integer >= 1"),
        process_pool(workers),  # type: ignore[arg-type]
    ):
        pass


def test_default_is_one_worker_per_core() -> None:
    assert check_workers(None) == (os.cpu_count() or 1)
    assert check_workers(3) == 3


@pytest.mark.parametrize(
    ("address", "pattern"),
    [
        ("bogus", r"'bogus' is not a Dask scheduler address: give tcp://HOST:PORT or HOST:PORT"),
        ("", r"'' is not a Dask scheduler address"),
        ("tcp://", r"'tcp://' is not a Dask scheduler address"),
        ("tcp://host:0", r"the port in 1\.\.65535"),
        ("tcp://host:65536", r"the port in 1\.\.65535"),
        ("tcp://host:8786/path", r"is not a Dask scheduler address"),
        (" host:8786", r"is not a Dask scheduler address"),
        ("http://host:80", r"'http://host:80' is not a Dask scheduler address"),
        ("inproc://x", r"'inproc://x' is not supported: .*give tcp://HOST:PORT"),
        ("tls://host:8786", r"'tls://host:8786' is not supported: TLS needs certificates"),
        ("ws://host:8786", r"is not supported: sahgrasp connects over TCP only"),
        (None, r"must be a string"),
        (8786, r"must be a string"),
    ],
)
def test_bad_scheduler_addresses_are_refused_naming_the_valid_forms(
    address: object, pattern: str
) -> None:
    with pytest.raises(SchedulerError, match=pattern):
        check_scheduler_address(address)


@pytest.mark.parametrize(
    ("address", "full"),
    [
        ("tcp://127.0.0.1:8786", "tcp://127.0.0.1:8786"),
        ("127.0.0.1:8786", "tcp://127.0.0.1:8786"),
        ("cluster-head.example.org:1", "tcp://cluster-head.example.org:1"),
        ("[::1]:8786", "tcp://[::1]:8786"),
        ("tcp://host:08786", "tcp://host:8786"),
    ],
)
def test_scheduler_addresses_in_their_full_form(address: str, full: str) -> None:
    assert check_scheduler_address(address) == full
