"""Benchmark of ``sahgrasp solve`` at scale: problems per second and peak memory of the run.

Each case runs the command line as a user would (``sahgrasp solve T.jsonl --json R.jsonl``) in a
subprocess, on random SAH problems written as JSON Lines, with 1 and 2 local workers and on a
Dask LocalCluster of 2 single-threaded workers. The memory is the resident set size summed over
the command's process tree (and over the cluster's processes for Dask), sampled every
:data:`SAMPLE_S` seconds with psutil; the peak is reported, and the CPU seconds of those
processes (as last sampled: the work of the final 0.2 s is missed). A last case solves a file
of mostly invalid lines (a few valid problems among them) to show that the memory does not grow
with the file. Wall times include starting Python and the workers: other processes on the
machine share the cores, so the load average is recorded with the numbers, and the problems per
CPU second show the parallel overhead even on a busy machine (equal per-CPU-second rates for 1
and 2 workers mean a 2x speed-up on two idle cores).
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from sahgrasp.bench.report import progress_reporter
from sahgrasp.core.errors import InvalidSettingsError
from sahgrasp.core.extras import install_command
from sahgrasp.core.progress import ProgressCallback
from sahgrasp.ik import random_problems
from sahgrasp.model.hand import load_hand
from sahgrasp.model.hands import DEFAULT_HAND

__all__ = ["run"]

SAMPLE_S = 0.2
"""Interval of the memory samples [s]."""

VALID_EVERY = 1000
"""In the file of mostly invalid lines, one line in this many is a valid problem."""

_INVALID_LINE = '{"name": "bad", "contacts": [{"finger": "thumb", "point": [0, 0], "normal": 1}]}\n'


def _write_problems(path: Path, count: int, seed: int, every: int = 1) -> None:
    """``count`` lines: random SAH problems, or one in ``every`` of them and invalid lines."""
    hand = load_hand(DEFAULT_HAND)
    valid = random_problems(hand, max(1, count // every), seed)
    with path.open("w", encoding="utf-8") as out:
        out.write(json.dumps({"hand": DEFAULT_HAND}) + "\n")
        for i in range(count):
            if i % every == 0 and i // every < len(valid):
                out.write(json.dumps(valid[i // every].to_dict()) + "\n")
            else:
                out.write(_INVALID_LINE)


def _sample(roots: list[Any], cpu: dict[int, float]) -> int:
    """Resident bytes of ``roots`` and their descendants; their CPU seconds recorded in ``cpu``."""
    import psutil

    total = 0
    for root in roots:
        try:
            tree = [root, *root.children(recursive=True)]
        except psutil.Error:  # the root ended
            continue
        for p in tree:
            try:
                total += p.memory_info().rss
                times = p.cpu_times()
                cpu[p.pid] = times.user + times.system
            except psutil.Error:  # a process ended between listing and reading
                continue
    return total


class _Lines:
    """Counts the result lines a running ``solve`` has written to its ``.part`` so far."""

    def __init__(self, part: Path) -> None:
        self.part = part
        self.count = -1  # the header line is no result
        self.handle: Any = None

    def __call__(self) -> int:
        if self.handle is None:
            try:
                self.handle = self.part.open("rb")
            except FileNotFoundError:
                return 0
        self.count += self.handle.read().count(b"\n")
        return max(self.count, 0)

    def close(self) -> None:
        if self.handle is not None:
            self.handle.close()


def _case(
    targets: Path,
    where: list[str],
    extra: list[Any],
    total: int,
    progress: ProgressCallback | None,
    label: str = "",
) -> dict[str, Any]:
    """Run one ``sahgrasp solve`` and sample its memory (and that of ``extra`` processes).

    ``progress`` hears of the results written so far, out of ``total`` lines.
    """
    import psutil

    out = targets.with_name(f"results-{time.monotonic_ns()}.jsonl")
    command = [sys.executable, "-m", "sahgrasp", "solve", str(targets), "--json", str(out),
               "--quiet", *where]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    started = time.perf_counter()
    process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    root = psutil.Process(process.pid)
    peak = 0
    cpu: dict[int, float] = {}
    written = _Lines(out.with_name(out.name + ".part"))
    stage = f"bench solve: {label or ' '.join(where)}"
    try:
        while process.poll() is None:
            peak = max(peak, _sample([root, *extra], cpu))
            if progress is not None:
                progress(stage, min(written(), total), total)
            time.sleep(SAMPLE_S)
    finally:
        written.close()
    wall = time.perf_counter() - started
    if progress is not None:
        progress(stage, total, total)
    stdout, stderr = process.communicate()
    if process.returncode not in (0, 1):
        raise InvalidSettingsError(f"{' '.join(command)} failed: {stderr.decode()[-500:]}")
    lines = out.read_bytes().count(b"\n") - 1
    out.unlink()
    return {
        "where": " ".join(where),
        "lines": lines,
        "wall_s": wall,
        "problems_per_s": lines / wall,
        "peak_rss_mb": peak / 1e6,
        "cpu_s": sum(cpu.values()),
        "problems_per_cpu_s": lines / max(sum(cpu.values()), 1e-9),
        "summary": stdout.decode().splitlines()[0],
    }


def _dask_case(targets: Path, total: int, progress: ProgressCallback | None) -> dict[str, Any]:
    import psutil

    from sahgrasp.core.extras import require_extra

    require_extra("cluster", "the Dask case of the solve benchmark")
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True) as cluster:
        pids = [w.pid for w in cluster.workers.values() if getattr(w, "pid", None)]
        extra = [psutil.Process(pid) for pid in pids]
        where = ["--scheduler", cluster.scheduler_address]
        result = _case(targets, where, extra, total, progress, "dask LocalCluster")
    return {**result, "where": "dask LocalCluster, 2 workers"}


def run(
    problems: int = 10_000,
    lines: int = 1_000_000,
    seed: int = 9090,
    dask: bool = True,
    workers: Sequence[int] = (1, 2),
    quiet: bool = False,
    progress: ProgressCallback | None = None,
) -> dict[str, Any]:
    """Time ``sahgrasp solve`` on ``problems`` random SAH problems and on ``lines`` mostly invalid.

    Args:
        problems: Random SAH problems of the 1-worker, 2-worker and Dask cases.
        lines: Lines of the mostly invalid file (one valid problem in :data:`VALID_EVERY`); 0
            skips that case.
        seed: Seed of the random problems.
        dask: Also run on a Dask LocalCluster of 2 workers.
        workers: The local worker counts to run; the speed-up is reported when 1 and 2 are
            among them.
        quiet: No progress bars on stderr.
        progress: Reports the results written, per case (instead of the bars).

    Returns:
        The cases (wall time, lines per second, peak memory), the speed-up from 1 to 2 workers
        and the machine's load average.

    Raises:
        InvalidSettingsError: psutil (the ``[bench]`` extra) is not installed.
    """
    if importlib.util.find_spec("psutil") is None:
        raise InvalidSettingsError(
            "bench solve measures memory with psutil, which is not installed: "
            + install_command("bench")
        )
    with (
        tempfile.TemporaryDirectory(prefix="sahgrasp-bench-solve-") as folder,
        progress_reporter(progress, quiet) as report,
    ):
        targets = Path(folder) / "random.jsonl"
        _write_problems(targets, problems, seed)
        cases = [_case(targets, ["--workers", str(n)], [], problems, report) for n in workers]
        if dask:
            cases.append(_dask_case(targets, problems, report))
        if lines:
            mostly_invalid = Path(folder) / "mostly-invalid.jsonl"
            _write_problems(mostly_invalid, lines, seed + 1, VALID_EVERY)
            label = "mostly invalid, 2 workers"
            case = _case(mostly_invalid, ["--workers", "2"], [], lines, report, label)
            cases.append({**case, "where": label})
    rate = {case["where"]: case["problems_per_s"] for case in cases}
    return {
        "benchmark": "solve",
        "problems": problems,
        "seed": seed,
        "cases": cases,
        "speedup_1_to_2_workers": (
            rate["--workers 2"] / rate["--workers 1"]
            if {"--workers 1", "--workers 2"} <= rate.keys()
            else None
        ),
        "load_average_1_5_15": list(os.getloadavg()),
        "cpu_count": os.cpu_count(),
    }
