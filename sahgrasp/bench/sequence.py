"""Benchmark of the initial-pose search: wall time, IK runs per second, speed-up with workers.

The same small search runs once per worker count, on local worker processes that are started
(and have built the hand) before the clock starts, so the numbers are those of the search itself:
PCA basis, screening, grid evaluation, checkpoints and output files. The workers' CPU time per
run (their start included) tells a slow search from a busy machine: if it stays the same with
more workers while the wall time grows, other processes had the cores. The per-run worker time
then extrapolates to the paper's scale (N = 30, M = 5000, 12 rounds) on a cluster.
"""

from __future__ import annotations

import os
import resource
import tempfile
import time
from collections.abc import Sequence
from concurrent.futures import Executor, wait
from typing import Any

from sahgrasp.ik import IKSettings, worker_hand
from sahgrasp.ik.solver import Method
from sahgrasp.model.hand import HandDescription, load_hand
from sahgrasp.model.hands import DEFAULT_HAND
from sahgrasp.sequence import SearchSettings, open_executor, search_sequence

__all__ = ["extrapolate", "run"]

PAPER_SCALE = SearchSettings(grid=30, problems=5000, rounds=12)
"""The search of Claret & Suárez Fig. 4 and Table 1."""


def _warm(description: HandDescription, digest: str) -> None:
    worker_hand(description, digest)
    time.sleep(0.5)  # keep this worker busy so that the others take the other warm-up tasks


def _start(pool: Executor, workers: int, description: HandDescription) -> None:
    digest = description.digest()
    wait([pool.submit(_warm, description, digest) for _ in range(workers)])


def _children_cpu_seconds() -> float:
    """CPU time of the finished child processes (the pool's workers, once it is shut down)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def extrapolate(
    seconds_per_run: float, screening_runs_per_problem: float, workers: int, efficiency: float
) -> float:
    """Wall time [s] of the paper-scale search on ``workers`` workers.

    Each round evaluates ``N^2`` initial poses on each of its ``M`` problems, and screening costs
    a number of runs per problem found that depends on how often the sequence so far fails (not
    on ``N``), so the work is ``rounds * M * (N^2 + screening_runs_per_problem)`` runs.

    Args:
        seconds_per_run: Worker time per initial configuration tried [s].
        screening_runs_per_problem: Screening runs per round problem, averaged over the rounds.
        workers: Workers of the cluster.
        efficiency: Parallel efficiency (speed-up / workers, measured locally).
    """
    s = PAPER_SCALE
    runs = s.rounds * s.problems * (s.cells + screening_runs_per_problem)
    return runs * seconds_per_run / (workers * efficiency)


def run(
    hand: str = DEFAULT_HAND,
    grid: int = 5,
    problems: int = 60,
    rounds: int = 2,
    seed: int = 0,
    method: Method = "auto",
    workers: Sequence[int] = (1, 2),
    cluster_workers: int = 16,
) -> dict[str, Any]:
    """Time the same search with each worker count; extrapolate to the paper's scale."""
    model = load_hand(hand)
    settings = SearchSettings(
        grid, problems, rounds, seed, IKSettings(method=method, init="sequence")
    )
    rows: dict[str, dict[str, float]] = {}
    for count in workers:
        cpu = _children_cpu_seconds()
        with tempfile.TemporaryDirectory() as out, open_executor(None, count) as pool:
            _start(pool, count, model.description)
            start = time.perf_counter()
            result = search_sequence(model, settings, out, executor=pool)
            wall = time.perf_counter() - start
        runs = result.ik_runs_computed
        rows[str(count)] = {
            "wall_seconds": wall,
            "ik_runs": runs,
            "ik_runs_per_second": runs / wall,
            "worker_seconds_per_run": sum(r.worker_seconds for r in result.rounds) / runs,
            "worker_cpu_seconds_per_run": (_children_cpu_seconds() - cpu) / runs,
        }
    base, top = rows[str(workers[0])], rows[str(workers[-1])]
    speedup = base["wall_seconds"] / top["wall_seconds"]
    efficiency = speedup * workers[0] / workers[-1]
    screening = sum(r.ik_runs - settings.cells * problems for r in result.rounds) / (
        rounds * problems
    )
    per_run = base["worker_seconds_per_run"]
    return {
        "benchmark": "sequence",
        "hand": hand,
        "settings": {**settings.identity(), "rounds": rounds},
        "load_average": list(os.getloadavg()),
        "workers": rows,
        "speedup": speedup,
        "paper_scale": {
            "grid": PAPER_SCALE.grid,
            "problems": PAPER_SCALE.problems,
            "rounds": PAPER_SCALE.rounds,
            "cluster_workers": cluster_workers,
            "screening_runs_per_problem": screening,
            "hours": extrapolate(per_run, screening, cluster_workers, efficiency) / 3600.0,
        },
    }
