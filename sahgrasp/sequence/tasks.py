"""The unit of work of the sequence search and the worker side that runs it.

A :class:`Chunk` asks a worker to run Algorithm 1 on a few random problems with a given list of
initial poses, and a :class:`ChunkResult` says which problems were solved. Both are small and
picklable: the hand travels as its :class:`HandDescription` (file paths), never as a live Pinocchio
object, and the problems as their indices in the ``random_problem(hand, seed, index)`` stream.

The search uses one kind of chunk for both of its steps:

* evaluating a grid cell ``(lambda^1_j, lambda^2_k)``: ``lambdas`` holds that single pair, so
  every problem gets exactly one initial configuration (Section 3.2, step 3(b)ii);
* screening candidate problems: ``lambdas`` holds the sequence chosen so far, and a problem is kept
  for the round only if that sequence does not solve it (step 3(a)).

Each worker thread builds the hand once and keeps it, with the problems it has drawn, in a
thread-local cache keyed by the hand digest (``Hand`` holds Pinocchio data that threads must not
share, and its coal geometry does not pickle).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, replace

from sahgrasp.ik import IKSettings, PoseBasis, Sequence, random_problem, solve_ik, worker_hand
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import Hand, HandDescription

__all__ = ["Chunk", "ChunkResult", "solve_chunk"]

_PROBLEM_CACHE_SIZE = 20_000
"""Problems kept per worker thread: a round's problems are reused by every grid cell."""


@dataclass(frozen=True)
class Chunk:
    """Solve problems ``problems`` of stream ``seed`` with the initial poses ``lambdas``.

    Attributes:
        description: The hand.
        hand_digest: Its digest; a worker whose URDF differs refuses the chunk.
        basis: PCA basis the lambdas refer to (Eq. (11)).
        lambdas: Initial poses tried in order, each ``(lambda^1, lambda^2)``.
        problems: Indices in the ``random_problem(hand, seed, index)`` stream.
        seed: Problem stream.
        ik: Solver settings; ``max_inits`` is replaced by ``len(lambdas)``.
    """

    description: HandDescription
    hand_digest: str
    basis: PoseBasis
    lambdas: tuple[tuple[float, float], ...]
    problems: tuple[int, ...]
    seed: int
    ik: IKSettings


@dataclass(frozen=True)
class ChunkResult:
    """Outcome of a :class:`Chunk`.

    Attributes:
        solved: Per problem of the chunk, in order, whether Algorithm 1 solved it.
        ik_runs: Initial configurations tried in all (runs of Algorithm 1's inner loop).
        seconds: Worker wall time spent on the chunk [s].
    """

    solved: tuple[bool, ...]
    ik_runs: int
    seconds: float


class _WorkerState(threading.local):
    def __init__(self) -> None:
        self.problems: dict[tuple[str, int, int], GraspTarget] = {}


_STATE = _WorkerState()


def _problem(hand: Hand, digest: str, seed: int, index: int) -> GraspTarget:
    key = (digest, seed, index)
    problem = _STATE.problems.get(key)
    if problem is None:
        if len(_STATE.problems) >= _PROBLEM_CACHE_SIZE:
            _STATE.problems.clear()
        problem = _STATE.problems[key] = random_problem(hand, seed, index)
    return problem


def solve_chunk(chunk: Chunk) -> ChunkResult:
    """Run Algorithm 1 on every problem of ``chunk`` (the function workers execute)."""
    start = time.perf_counter()
    hand = worker_hand(chunk.description, chunk.hand_digest)
    sequence = Sequence(chunk.description.name, chunk.hand_digest, chunk.basis, chunk.lambdas)
    # The cells' lambdas alone: no learned start in front of the poses being evaluated.
    settings = replace(chunk.ik, init="sequence", max_inits=len(chunk.lambdas))
    results = [
        solve_ik(hand, _problem(hand, chunk.hand_digest, chunk.seed, i), settings, sequence)
        for i in chunk.problems
    ]
    return ChunkResult(
        solved=tuple(r.success for r in results),
        ik_runs=sum(r.inits_used for r in results),
        seconds=time.perf_counter() - start,
    )
