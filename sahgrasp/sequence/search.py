"""The greedy search for the sequence of initial hand poses (Claret & Suárez Section 3.2).

The domain of ``(lambda^1, lambda^2)`` is discretised into ``N`` values each, uniform in [0, 1]
with both ends included, giving ``N^2`` candidate cells (flat index ``j * N + k`` for
``(lambda^1_j, lambda^2_k)``). ``SEQ`` starts empty; in round ``i = 1 .. i_max``:

1. *Screening* -- the round's ``M`` problems are the first indices of the stream
   ``random_problem(hand, seed, index)``, from just after the previous round's last problem, that
   Algorithm 1 with ``SEQ`` (one initial configuration per element, the same solver settings)
   does not solve. Every problem is feasible: it is read off a random collision-free hand.
2. *Evaluation* -- for every cell, Algorithm 1 runs on each of the ``M`` problems with that
   cell's single initial configuration; ``E_i[j, k]`` is the fraction solved.
3. *Choice* -- the cell with the highest ``E_i`` joins ``SEQ`` (ties: the lowest flat index).

Each problem's outcome is a deterministic function of its index and the initial poses, so the
result depends only on the hand and the :class:`SearchSettings` -- not on the executor, the number
of workers, the chunk size, or on interruptions (see :mod:`sahgrasp.sequence.checkpoint`).
Rounds are not part of a search's identity: a finished search can be resumed with more rounds,
and its first ``i`` rounds are those of a search run with ``i`` rounds.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future, as_completed
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sahgrasp.core.errors import InvalidSettingsError
from sahgrasp.core.executors import open_executor
from sahgrasp.core.extras import has_extra
from sahgrasp.core.fileio import write_bytes_atomic, write_json_atomic
from sahgrasp.ik import IKSettings, PoseBasis, Sequence, pose_basis
from sahgrasp.ik.initial import PCA_SAMPLES, PCA_SEED, expansion_matrix
from sahgrasp.model.hand import Hand, HandDescription, load_hand
from sahgrasp.sequence.checkpoint import CellOutcome, Checkpoint, RoundState, refuse_leftovers
from sahgrasp.sequence.figure import success_maps_png
from sahgrasp.sequence.folder import (
    CHECKPOINT,
    FIGURE,
    HEADER,
    REPORT,
    SEQUENCE,
    locked_folder,
    remove_stale_temporaries,
)
from sahgrasp.sequence.tasks import Chunk, ChunkResult, solve_chunk

__all__ = ["Progress", "RoundResult", "SearchResult", "SearchSettings", "search_sequence"]

CHUNK_SIZE = 100
"""Problems per chunk (affects load balancing only, never the result)."""


@dataclass(frozen=True)
class SearchSettings:
    """Parameters of the search; together with the hand they determine its result.

    Attributes:
        grid: ``N``, values of each lambda (``N^2`` candidate initial poses).
        problems: ``M``, random problems per round.
        rounds: ``i_max``, length of the sequence.
        seed: Seed of the random-problem stream.
        ik: Solver settings of Algorithm 1 (``method`` included); ``max_inits`` is set by the
            search and so is ``init``, to ``"sequence"``: the search evaluates the sequence
            itself, so the learned start (the solver's default) must not stand in front of it.
            ``init="random"`` is refused.
    """

    grid: int = 10
    problems: int = 300
    rounds: int = 12
    seed: int = 0
    ik: IKSettings = field(default_factory=lambda: IKSettings(init="sequence"))

    def __post_init__(self) -> None:
        for name, lower in (("grid", 2), ("problems", 1), ("rounds", 1)):
            if int(getattr(self, name)) < lower:
                raise InvalidSettingsError(f"{name} must be >= {lower}, got {getattr(self, name)}")
        if self.ik.init == "random":
            raise InvalidSettingsError("the search evaluates initial poses: ik.init = 'sequence'")
        object.__setattr__(self, "ik", replace(self.ik, init="sequence"))

    @property
    def method(self) -> str:
        """The IK method searched for (``auto`` or ``paper``)."""
        return self.ik.method

    @property
    def cells(self) -> int:
        """``N^2``."""
        return self.grid * self.grid

    def lambda_values(self) -> NDArray[np.float64]:
        """The ``N`` values of each lambda: uniform in [0, 1], both ends included."""
        return np.linspace(0.0, 1.0, self.grid)

    def cell_lambdas(self, cell: int) -> tuple[float, float]:
        """``(lambda^1_j, lambda^2_k)`` of flat cell index ``j * N + k``."""
        j, k = divmod(cell, self.grid)
        values = self.lambda_values()
        return (float(values[j]), float(values[k]))

    def identity(self) -> dict[str, Any]:
        """The settings that determine the result (JSON-able; rounds excluded, see module)."""
        ik = {k: v for k, v in asdict(self.ik).items() if k not in ("max_inits", "record_history")}
        return {"grid": self.grid, "problems": self.problems, "seed": self.seed, "ik": ik}


@dataclass(frozen=True)
class RoundResult:
    """One round of the search.

    Attributes:
        index: Round ``i``, from 1.
        cell: ``(j, k)`` of the chosen cell.
        lambdas: The chosen ``(lambda^1, lambda^2)``.
        solved: Problems solved per cell, shape (N, N), ``[j, k]`` for ``(lambda^1_j, lambda^2_k)``.
        problem_indices: The round's ``M`` problems (indices in the random-problem stream).
        scanned: Problems screened to find them.
        ik_runs: Initial configurations tried in the round (grid and screening).
        worker_seconds: Worker time spent on the round [s] (summed over workers).
    """

    index: int
    cell: tuple[int, int]
    lambdas: tuple[float, float]
    solved: NDArray[np.int64]
    problem_indices: tuple[int, ...]
    scanned: int
    ik_runs: int
    worker_seconds: float

    @property
    def success_rates(self) -> NDArray[np.float64]:
        """``E_i``: fraction of the round's problems solved, per cell, shape (N, N)."""
        return self.solved / len(self.problem_indices)

    @property
    def prior_success_rate(self) -> float:
        """Fraction of the screened problems that the sequence before this round solved."""
        return 1.0 - len(self.problem_indices) / self.scanned

    def to_dict(self) -> dict[str, Any]:
        """JSON form (the per-round statistics of ``search.json``)."""
        rates = self.success_rates
        return {
            "round": self.index,
            "cell": list(self.cell),
            "lambdas": list(self.lambdas),
            "best_success_rate": float(rates.max()),
            "mean_success_rate": float(rates.mean()),
            "prior_success_rate": self.prior_success_rate,
            "problems": len(self.problem_indices),
            "first_problem": self.problem_indices[0],
            "last_problem": self.problem_indices[-1],
            "scanned": self.scanned,
            "ik_runs": self.ik_runs,
            "worker_seconds": self.worker_seconds,
            "solved": self.solved.tolist(),
        }


@dataclass(frozen=True)
class SearchResult:
    """Outcome of :func:`search_sequence`.

    Attributes:
        sequence: The sequence found (``source="search"``, settings in ``meta``).
        settings: The search settings.
        rounds: Per-round results, in order.
        cells_computed: Grid cells evaluated by this call (not read back from a checkpoint).
        ik_runs_computed: Initial configurations tried by this call (grid and screening).
        wall_seconds: Wall time of this call [s].
    """

    sequence: Sequence
    settings: SearchSettings
    rounds: tuple[RoundResult, ...]
    cells_computed: int
    ik_runs_computed: int
    wall_seconds: float

    def to_dict(self) -> dict[str, Any]:
        """The content of ``search.json``."""
        return {
            "format": "sahgrasp-search-1",
            "hand": self.sequence.hand,
            "hand_digest": self.sequence.hand_digest,
            "settings": {**self.settings.identity(), "rounds": self.settings.rounds},
            "lambda_values": self.settings.lambda_values().tolist(),
            "lambdas": [list(pair) for pair in self.sequence.lambdas],
            "rounds": [r.to_dict() for r in self.rounds],
            "run": {
                "wall_seconds": self.wall_seconds,
                "cells_computed": self.cells_computed,
                "ik_runs_computed": self.ik_runs_computed,
                "ik_runs_per_second": self.ik_runs_computed / max(self.wall_seconds, 1e-9),
            },
        }


@dataclass(frozen=True)
class Progress:
    """Where the search is, reported after every finished chunk.

    Attributes:
        round: Current round, from 1.
        rounds: ``i_max``.
        stage: ``"screening"`` or ``"cells"``.
        found: Problems of this round found so far by screening.
        problems: ``M``.
        scanned: Problems screened so far in this round.
        cells_done: Cells finished in this round.
        cells: ``N^2``.
        runs_done: Grid IK runs finished in the whole search (checkpointed ones included).
        runs_total: ``i_max * N^2 * M``.
    """

    round: int
    rounds: int
    stage: str
    found: int
    problems: int
    scanned: int
    cells_done: int
    cells: int
    runs_done: int
    runs_total: int


ProgressCallback = Callable[[Progress], None]


def search_sequence(
    hand: Hand | HandDescription | str,
    settings: SearchSettings,
    out_dir: str | Path,
    *,
    executor: Any = None,
    workers: int | None = None,
    resume: bool = False,
    chunk_size: int = CHUNK_SIZE,
    progress: ProgressCallback | None = None,
) -> SearchResult:
    """Search the sequence of initial poses and write it, with its statistics, to ``out_dir``.

    Writes ``sequence.json`` (:meth:`Sequence.save`), ``search.json`` (settings, the ``E_i``
    maps and per-round statistics), ``fig4.png`` (the ``E_i`` maps as in the paper's Fig. 4;
    with matplotlib only, the extra ``plot``) and keeps ``checkpoint/`` up to date as cells
    finish. It holds an exclusive lock on ``out_dir`` from start to end
    (:func:`sahgrasp.sequence.folder.locked_folder`) and deletes the temporary files of writes
    that a kill interrupted. Call it under ``if __name__ == "__main__":`` in
    scripts: local workers are started with ``spawn``.

    Args:
        hand: The hand, a built-in name, or a description.
        settings: The search settings.
        out_dir: Output folder (created if needed).
        executor: None for local worker processes, a Dask scheduler address or
            ``dask.distributed.Client``, or any ``concurrent.futures.Executor``.
        workers: Local worker processes (default: one per core); only when ``executor`` is None.
        resume: Continue the search checkpointed in ``out_dir``, if any.
        chunk_size: Problems per chunk of work.
        progress: Called after every finished chunk.

    Raises:
        SequenceFileError: ``out_dir`` holds a search and ``resume`` is False; or what is left
            of a search without its header; or its checkpoint is corrupted or belongs to another
            hand or settings; or another process is running a search in ``out_dir``.
        InvalidSettingsError: ``chunk_size`` or ``workers`` below 1.
    """
    if chunk_size < 1:
        raise InvalidSettingsError(f"chunk_size must be >= 1, got {chunk_size}")
    start = time.perf_counter()
    hand = hand if isinstance(hand, Hand) else load_hand(hand)
    out = Path(out_dir)
    # The executor first (a bad one is refused before the folder is touched), then the lock,
    # held until the outputs are written.
    with open_executor(executor, workers) as pool, locked_folder(out):
        checkpoint = _open_checkpoint(hand, settings, out, resume)
        search = _Search(hand, settings, checkpoint, pool, chunk_size, progress)
        rounds = search.run()
        result = SearchResult(
            sequence=_sequence(hand, settings, checkpoint.basis, rounds),
            settings=settings,
            rounds=rounds,
            cells_computed=search.cells_computed,
            ik_runs_computed=search.ik_runs,
            wall_seconds=time.perf_counter() - start,
        )
        _write_outputs(result, out)
    return result


def _open_checkpoint(hand: Hand, settings: SearchSettings, out: Path, resume: bool) -> Checkpoint:
    """Resume the checkpoint in ``out`` or start one; ``out`` must be locked by this process."""
    for folder in (out, out / CHECKPOINT):
        if folder.is_dir():
            remove_stale_temporaries(folder)
    identity = {
        "hand": hand.description.name,
        "hand_digest": hand.description.digest(),
        "settings": settings.identity(),
    }
    shape = (settings.cells, settings.problems)
    if resume and (out / CHECKPOINT / HEADER).exists():
        return Checkpoint.open(out, identity, shape, expansion_matrix(hand).shape[0])
    refuse_leftovers(out)  # before the PCA, which takes seconds
    return Checkpoint.create(out, identity, pose_basis(hand), shape)


class _Search:
    """The rounds of one call of :func:`search_sequence` (module docstring)."""

    def __init__(
        self,
        hand: Hand,
        settings: SearchSettings,
        checkpoint: Checkpoint,
        executor: Executor,
        chunk_size: int,
        progress: ProgressCallback | None,
    ) -> None:
        self.settings = settings
        self.checkpoint = checkpoint
        self.executor = executor
        self.chunk_size = chunk_size
        self.progress = progress
        self.cells_computed = 0
        self.ik_runs = 0
        self._description = hand.description
        self._digest = hand.description.digest()
        self._pending: set[Future[ChunkResult]] = set()
        done = sum(len(r.cells) for r in checkpoint.rounds[: settings.rounds])
        self._runs_done = done * settings.problems

    def run(self) -> tuple[RoundResult, ...]:
        """Play (or read back) every round; cancel the chunks in flight if interrupted."""
        results: list[RoundResult] = []
        try:
            for index in range(1, self.settings.rounds + 1):
                state = self._state(index, results)
                state = self._screen(state, results)
                state = self._evaluate(state)
                results.append(self._result(state))
        except BaseException:
            for future in self._pending:
                future.cancel()
            raise
        return tuple(results)

    def _state(self, index: int, results: list[RoundResult]) -> RoundState:
        if index <= len(self.checkpoint.rounds):
            return self.checkpoint.rounds[index - 1]
        start = results[-1].problem_indices[-1] + 1 if results else 0
        return RoundState(index, start, start)

    # ----- step 3(a): the round's problems ----------------------------------------------------
    def _screen(self, state: RoundState, results: list[RoundResult]) -> RoundState:
        M = self.settings.problems
        if not results and len(state.problems) < M:  # nothing chosen yet: nothing is solved
            problems = tuple(range(state.start, state.start + M))
            state = RoundState(state.index, state.start, problems[-1] + 1, problems)
            self.checkpoint.save(state)
        while len(state.problems) < M:
            self._report(state, "screening")
            need = M - len(state.problems)
            count = math.ceil(need / max(_unsolved_rate(state, results), 0.02) * 1.25)
            stop = state.scanned + max(count, self.chunk_size)
            sequence = tuple(r.lambdas for r in results)
            candidates = tuple(range(state.scanned, stop))
            futures = [self._submit(sequence, p) for p in _split(candidates, self.chunk_size)]
            outcomes = [self._collect(f) for f in futures]
            solved = [s for o in outcomes for s in o.solved]
            found = [p for p, ok in zip(candidates, solved, strict=True) if not ok]
            problems = (*state.problems, *found)[:M]
            scanned = problems[-1] + 1 if len(problems) == M else stop
            state = RoundState(
                state.index, state.start, scanned, problems, {},
                state.screen_runs + sum(o.ik_runs for o in outcomes),
                state.screen_seconds + sum(o.seconds for o in outcomes),
            )  # fmt: skip
            self.checkpoint.save(state)
            self._report(state, "screening")
        return state

    # ----- step 3(b): E_i over the grid -------------------------------------------------------
    def _evaluate(self, state: RoundState) -> RoundState:
        todo = [c for c in range(self.settings.cells) if c not in state.cells]
        owner: dict[Future[ChunkResult], int] = {}
        left: dict[int, int] = {}
        partial: dict[int, list[ChunkResult]] = {c: [] for c in todo}
        parts = list(_split(state.problems, self.chunk_size))
        for cell in todo:
            for part in parts:
                owner[self._submit((self.settings.cell_lambdas(cell),), part)] = cell
            left[cell] = len(parts)
        self._report(state, "cells")
        for future in as_completed(owner):
            cell = owner[future]
            outcome = self._collect(future)
            partial[cell].append(outcome)
            self._runs_done += len(outcome.solved)
            left[cell] -= 1
            if left[cell] == 0:
                done = partial.pop(cell)
                solved = sum(sum(o.solved) for o in done)
                state = state.with_cell(cell, CellOutcome(solved, sum(o.seconds for o in done)))
                self.checkpoint.save(state)
                self.cells_computed += 1
            self._report(state, "cells")
        return state

    # ----- step 3(c) --------------------------------------------------------------------------
    def _result(self, state: RoundState) -> RoundResult:
        N = self.settings.grid
        solved = np.array([state.cells[c].solved for c in range(N * N)], dtype=np.int64)
        best = int(np.argmax(solved))  # the first maximum: ties go to the lowest index
        return RoundResult(
            index=state.index,
            cell=divmod(best, N),
            lambdas=self.settings.cell_lambdas(best),
            solved=solved.reshape(N, N),
            problem_indices=state.problems,
            scanned=state.scanned - state.start,
            ik_runs=state.screen_runs + self.settings.problems * N * N,
            worker_seconds=state.screen_seconds + sum(o.seconds for o in state.cells.values()),
        )

    # ----- plumbing ---------------------------------------------------------------------------
    def _submit(
        self, lambdas: tuple[tuple[float, float], ...], problems: tuple[int, ...]
    ) -> Future[ChunkResult]:
        chunk = Chunk(
            self._description, self._digest, self.checkpoint.basis, lambdas, problems,
            self.settings.seed, self.settings.ik,
        )  # fmt: skip
        future = self.executor.submit(solve_chunk, chunk)
        self._pending.add(future)
        return future

    def _collect(self, future: Future[ChunkResult]) -> ChunkResult:
        outcome = future.result()
        self._pending.discard(future)
        self.ik_runs += outcome.ik_runs
        return outcome

    def _report(self, state: RoundState, stage: str) -> None:
        if self.progress is not None:
            s = self.settings
            report = Progress(
                state.index, s.rounds, stage, len(state.problems), s.problems,
                state.scanned - state.start,
                len(state.cells), s.cells, self._runs_done, s.rounds * s.cells * s.problems,
            )  # fmt: skip
            self.progress(report)


def _split(items: tuple[int, ...], size: int) -> Iterator[tuple[int, ...]]:
    for a in range(0, len(items), size):
        yield items[a : a + size]


def _unsolved_rate(state: RoundState, results: list[RoundResult]) -> float:
    """Estimate of the fraction of fresh problems that the sequence so far does not solve."""
    if state.scanned > state.start:
        return (len(state.problems) + 1) / (state.scanned - state.start + 2)
    last = results[-1]
    return (1.0 - last.prior_success_rate) * (1.0 - float(last.success_rates.max()))


def _sequence(
    hand: Hand, settings: SearchSettings, basis: PoseBasis, rounds: tuple[RoundResult, ...]
) -> Sequence:
    meta = {
        **settings.identity(),
        "rounds": settings.rounds,
        "method": settings.method,
        "pca": {"samples": PCA_SAMPLES, "seed": PCA_SEED},
        "success_rates": [float(r.success_rates.max()) for r in rounds],
    }
    lambdas = tuple(r.lambdas for r in rounds)
    digest = hand.description.digest()
    return Sequence(hand.description.name, digest, basis, lambdas, "search", meta)


def _write_outputs(result: SearchResult, out: Path) -> None:
    write_json_atomic(out / SEQUENCE, result.sequence.to_dict())  # as Sequence.save writes it
    write_json_atomic(out / REPORT, result.to_dict())
    if not has_extra("plot"):  # the figure is a view of search.json: without matplotlib, none
        return
    rounds = result.rounds
    title = f"Success rates E_i of the initial-pose search, hand {result.sequence.hand}"
    png = success_maps_png([r.success_rates for r in rounds], [r.lambdas for r in rounds], title)
    write_bytes_atomic(out / FIGURE, png)
