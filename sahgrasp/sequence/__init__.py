"""The offline search for the sequence of initial hand poses (Claret & Suárez Section 3.2).

:func:`search_sequence` runs the greedy search on any ``concurrent.futures.Executor`` (local worker
processes by default, Dask, MPI), checkpoints as it goes, and writes a
:class:`~sahgrasp.ik.Sequence` file that ``solve_ik`` can use.
"""

from sahgrasp.core.executors import open_executor
from sahgrasp.sequence.checkpoint import CellOutcome, Checkpoint, RoundState
from sahgrasp.sequence.search import (
    Progress,
    RoundResult,
    SearchResult,
    SearchSettings,
    search_sequence,
)
from sahgrasp.sequence.tasks import Chunk, ChunkResult, solve_chunk

__all__ = [
    "CellOutcome",
    "Checkpoint",
    "Chunk",
    "ChunkResult",
    "Progress",
    "RoundResult",
    "RoundState",
    "SearchResult",
    "SearchSettings",
    "open_executor",
    "search_sequence",
    "solve_chunk",
]
