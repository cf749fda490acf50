"""Executors of the chunked work: local processes, Dask, any Executor."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from concurrent.futures import Executor, Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest

from sahgrasp.core.errors import InvalidSettingsError
from sahgrasp.core.executors import WatchedExecutor, open_executor
from sahgrasp.core.parallel import SchedulerError, SchedulerLostError
from sahgrasp.ik import random_problems
from sahgrasp.model.hand import load_hand
from sahgrasp.objects.targets import save_targets

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def test_an_executor_is_used_as_is_and_left_open() -> None:
    with ThreadPoolExecutor(1) as pool:
        with open_executor(pool) as executor:
            assert executor is pool
        assert pool.submit(sum, [2, 2]).result() == 4


def test_anything_else_is_refused_naming_what_is_valid() -> None:
    with pytest.raises(InvalidSettingsError, match="Dask scheduler address"), open_executor(42):
        pass


class _Stuck(Executor):
    """An executor whose futures never finish, as Dask's when its event loop has failed."""

    def submit(self, fn: Any, /, *args: Any, **kwargs: Any) -> Future[Any]:
        return Future()


class _Comm:
    def closed(self) -> bool:
        return False


class _Send:
    comm = _Comm()


class _Client:
    """What the watch reads of a ``dask.distributed.Client``: its status, its scheduler comm."""

    scheduler_comm = _Send()

    def __init__(self, status: str) -> None:
        self.status = status


def _watched(status: str, reachable: bool, probes: list[str]) -> WatchedExecutor:
    def probe(address: str) -> bool:
        probes.append(address)
        return reachable

    return WatchedExecutor(
        _Stuck(), _Client(status), "tcp://127.0.0.1:1", patience_s=0.2, period_s=0.02, probe=probe
    )


def test_futures_fail_once_a_lost_scheduler_stays_unreachable() -> None:
    probes: list[str] = []
    watched = _watched("connecting", reachable=False, probes=probes)
    future = watched.submit(print)
    with pytest.raises(SchedulerLostError, match=r"lost the Dask scheduler at tcp://127.0.0.1:1"):
        future.result(timeout=10)
    assert watched.lost and probes
    with pytest.raises(SchedulerLostError):
        watched.submit(print)
    watched.shutdown()


def test_a_running_client_or_a_reachable_scheduler_is_left_alone() -> None:
    for status, reachable in (("running", False), ("connecting", True)):
        probes: list[str] = []
        watched = _watched(status, reachable, probes)
        future = watched.submit(print)
        time.sleep(0.5)
        assert not future.done() and not watched.lost
        # A running client with an open connection is never probed: the scheduler would log it.
        assert bool(probes) == (status != "running")
        watched.shutdown()


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def test_a_malformed_scheduler_address_is_refused_before_connecting() -> None:
    with pytest.raises(SchedulerError, match="give tcp://HOST:PORT"), open_executor("bogus"):
        pass


def test_a_refused_connection_fails_at_once_with_one_line() -> None:
    port = _free_port()  # nothing listens there now
    with (
        pytest.raises(SchedulerError, match=rf"tcp://127\.0\.0\.1:{port}: Connection refused"),
        open_executor(f"127.0.0.1:{port}"),
    ):
        pass


def _sahgrasp(*args: object, cwd: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "sahgrasp", *map(str, args)], cwd=cwd, env=ENV,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, encoding="utf-8",
    )  # fmt: skip


def _lines(path: Path) -> int:
    try:
        return path.read_bytes().count(b"\n")
    except FileNotFoundError:
        return 0


def _results(path: Path) -> list[dict[str, object]]:
    """The results of a JSON Lines output without their times (which differ run to run)."""
    lines = path.read_text(encoding="utf-8").splitlines()[1:]
    return [
        {k: v for k, v in json.loads(line).items() if k not in {"time_ms", "setup_ms"}}
        for line in lines
    ]


@pytest.mark.slow
def test_a_scheduler_lost_mid_run_ends_in_one_line_and_the_part_resumes(tmp_path: Path) -> None:
    hand = load_hand("sah")
    save_targets(tmp_path / "t.json", "sah", random_problems(hand, 300, 3) * 10)
    port = _free_port()
    scheduler = subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_scheduler", "--port", str(port),
         "--no-dashboard"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=ENV,
    )  # fmt: skip
    worker = subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_worker", f"tcp://127.0.0.1:{port}",
         "--nthreads", "1", "--no-dashboard"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=ENV,
    )  # fmt: skip
    try:
        args = ("solve", "t.json", "--init", "random", "--inits", "50", "--quiet")
        run = _sahgrasp(*args, "--scheduler", f"127.0.0.1:{port}", "--json", "r.jsonl",
                        cwd=tmp_path)  # fmt: skip
        part = tmp_path / "r.jsonl.part"
        deadline = time.monotonic() + 240
        while _lines(part) < 2 and run.poll() is None:  # the header and one chunk's results
            assert time.monotonic() < deadline, "no result reached the .part"
            time.sleep(0.1)
        scheduler.kill()
        _, err = run.communicate(timeout=120)
    finally:
        for process in (scheduler, worker):
            process.kill()
            process.wait()
    assert run.returncode == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith(
        f"sahgrasp: error: lost the Dask scheduler at tcp://127.0.0.1:{port}"
    )
    assert "results so far in r.jsonl.part; continue with: sahgrasp solve" in lines[0]
    assert part.exists() and not (tmp_path / "r.jsonl").exists()
    resumed = _sahgrasp(*args, "--json", "r.jsonl", "--resume", cwd=tmp_path)
    assert resumed.wait(timeout=300) in (0, 1), resumed.communicate()
    whole = _sahgrasp(*args, "--json", "whole.jsonl", cwd=tmp_path)
    assert whole.wait(timeout=300) in (0, 1), whole.communicate()
    assert _results(tmp_path / "r.jsonl") == _results(tmp_path / "whole.jsonl")
