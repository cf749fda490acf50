"""Solve many IK problems on worker processes or a Dask cluster, with the same results anywhere.

Problems travel in chunks (:data:`CHUNK_SIZE` problems, a few hundred milliseconds of solving, on
a local pool; :data:`CLUSTER_CHUNK_SIZE` on a cluster, whose tasks cost more to schedule), pickled
into one bytes object each way; at most :data:`CHUNKS_IN_FLIGHT` chunks per worker are queued at
a time, so the memory does not grow with the number of problems (:func:`solve_stream`).

Workers receive the picklable :class:`HandDescription` and its digest and rebuild the hand once
per worker thread (Pinocchio's GeometryModel does not pickle); :func:`worker_hand` also serves the
offline sequence search. A problem's random initial configurations are seeded from the settings'
seed and the problem's content (:func:`sahgrasp.ik.starts.problem_seed`), and the collision
queries carry no state between problems, so a result depends neither on which worker solved it
nor on the problems solved before it. Each problem may carry its own obstacle: a
:class:`GraspObject`, or an :class:`ObjectSpec` of a targets file that the worker loads; a worker
keeps the first copy of each distinct object (by content) with its collision pieces. Loading an
object and building its collision pieces is the problem's set-up, timed apart from its solve: a
results entry's ``time_ms`` is the solve alone, its ``setup_ms`` the set-up it paid for (zero
when the worker had the object already).
"""

from __future__ import annotations

import hashlib
import math
import pickle
import threading
import time
from collections import deque
from collections.abc import Iterable, Iterator, Sequence
from concurrent.futures import Executor, Future
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from sahgrasp.core.errors import (
    InvalidSettingsError,
    InvalidTargetError,
    SahGraspError,
    SequenceFileError,
)
from sahgrasp.core.executors import open_executor
from sahgrasp.core.parallel import check_workers
from sahgrasp.ik.initial import Sequence as PoseSequence
from sahgrasp.ik.learned import GraspDatabase
from sahgrasp.ik.obstacle import check_obstacle, checker_of, pieces_of
from sahgrasp.ik.solver import IKResult, IKSettings, solve_ik
from sahgrasp.model.contacts import GraspTarget, ObjectSpec
from sahgrasp.model.hand import Hand, HandDescription, load_hand
from sahgrasp.model.hands import hand_entry
from sahgrasp.objects.targets import InvalidProblem, ObjectCache, build_object

if TYPE_CHECKING:
    from sahgrasp.objects import GraspObject

__all__ = [
    "CHUNKS_IN_FLIGHT",
    "CHUNK_SIZE",
    "CLUSTER_CHUNK_SIZE",
    "INVALID_ENTRY",
    "Job",
    "invalid_entry",
    "invalid_result",
    "object_key",
    "solve_chunks",
    "solve_many",
    "solve_stream",
    "worker_hand",
    "worker_obstacle",
]

CHUNK_SIZE = 32
"""Problems per task on a local pool: about 0.1 s of solving, against about 1 ms of scheduling."""

CLUSTER_CHUNK_SIZE = 128
"""Problems per task on a Dask cluster: about a second of solving, against 10 to 20 ms of CPU time
per task for the client, the scheduler and the worker together (measured on a LocalCluster)."""

CHUNKS_IN_FLIGHT = 4
"""Chunks queued per worker: enough to keep a worker busy while the parent collects results."""

INVALID_ENTRY: dict[str, Any] = {
    "success": False, "reason": "invalid_input", "inits_used": 0, "iterations": 0, "time_ms": 0.0,
    "setup_ms": 0.0, "max_position_error_mm": None, "max_centre_error_mm": None,
    "collision_free": None, "wrist": None, "joints": None, "contact_params": None,
}  # fmt: skip
"""The results entry of a problem refused as invalid input, besides its name and detail."""

Output = Literal["result", "entry"]


class _WorkerCache(threading.local):
    def __init__(self) -> None:
        self.hands: dict[str, Hand] = {}
        self.obstacles: dict[str, GraspObject | str] = {}
        self.objects = ObjectCache()  # one build per mesh file, whatever its placements


_CACHE = _WorkerCache()


def worker_hand(description: HandDescription, digest: str) -> Hand:
    """The hand of ``description``, built once per worker thread and kept by its ``digest``.

    A built-in hand whose URDF path does not exist on this machine (a cluster node with another
    install prefix) is rebuilt from this machine's copy. Either way the hand must have ``digest``.

    Raises:
        SequenceFileError: This worker's hand is not the one the work was started with.
    """
    hand = _CACHE.hands.get(digest)
    if hand is None:
        local = description
        if not description.urdf_path.is_file() and hand_entry(description.name) is not None:
            local = load_hand(description.name).description
        hand = load_hand(local)
        found = hand.description.digest()
        if found != digest:
            raise SequenceFileError(
                f"worker's hand {description.name!r} has digest {found[:12]}, the caller's has "
                f"{digest[:12]}: install the same sahgrasp and URDF on every worker"
            )
        _CACHE.hands[digest] = hand
    return hand


_KEPT_OBSTACLES = 8
"""Objects a worker keeps (with their collision pieces) for the next problems."""


def worker_obstacle(obstacle: GraspObject | ObjectSpec, key: str) -> GraspObject | str:
    """The object of a problem: this worker's kept copy, or the reason it cannot be loaded.

    Every chunk carries its own unpickled copy; solving against one kept copy lets the solver
    reuse that object's collision pieces instead of building them for every problem. An
    :class:`ObjectSpec` is loaded here, once per worker and source (a new placement of the
    same mesh is the same solids moved); a load error is kept as its message.
    """
    kept = _CACHE.obstacles
    if key not in kept:
        if len(kept) >= _KEPT_OBSTACLES:
            del kept[next(iter(kept))]
        try:
            kept[key] = (
                build_object(obstacle, _CACHE.objects)
                if isinstance(obstacle, ObjectSpec)
                else obstacle
            )
        except SahGraspError as exc:
            kept[key] = f"object {obstacle}: {exc}"
    return kept[key]


def invalid_result(hand: Hand, name: str) -> IKResult:
    """The result of a problem refused as invalid input (nothing was solved)."""
    nan = np.full(len(hand.fingers), np.nan)
    return IKResult(
        name=name, success=False, reason="invalid_input", q=hand.configuration(),
        position_errors_m=nan, centre_errors_m=nan, inits_used=0, iterations=0, time_s=0.0,
        collision_free=False, fingers=hand.fingers,
    )  # fmt: skip


def invalid_entry(name: str, detail: str) -> dict[str, Any]:
    """The results entry (docs/how-to/file-formats.md) of a problem refused as invalid input."""
    return {"name": name, **INVALID_ENTRY, "detail": detail}


@dataclass(frozen=True)
class Job:
    """What every chunk of one run shares: hand, settings, pose sequence and grasp database.

    ``database`` is the grasp database of the learned start (None: the hand's shipped one).
    """

    description: HandDescription
    digest: str
    settings: IKSettings
    sequence: PoseSequence | None
    output: Output
    database: GraspDatabase | None = None


Item = tuple["GraspTarget | InvalidProblem", Any, str]
"""A problem, its obstacle (GraspObject, ObjectSpec or None) and the obstacle's content key."""


def _invalid(job: Job, hand: Hand, name: str, detail: str) -> IKResult | dict[str, Any]:
    if job.output == "entry":
        return invalid_entry(name, detail)
    return invalid_result(hand, name)


def _set_up(hand: Hand, obstacle: Any, key: str) -> GraspObject | str | None:
    """The problem's object, loaded and with its collision pieces built (kept for the next)."""
    obj = None if obstacle is None else worker_obstacle(obstacle, key)
    if obj is not None and not isinstance(obj, str):
        pieces_of(checker_of(hand, obj))  # the solver's own cached queries: built here, not timed
    return obj


def _solve_item(job: Job, hand: Hand, item: Item) -> IKResult | dict[str, Any]:
    problem, obstacle, key = item
    assert isinstance(problem, GraspTarget)
    start = time.perf_counter()
    obj = _set_up(hand, obstacle, key)
    setup_ms = (time.perf_counter() - start) * 1e3
    if isinstance(obj, str):
        invalid = _invalid(job, hand, problem.name, obj)
        if isinstance(invalid, dict):
            invalid["setup_ms"] = setup_ms
        return invalid
    try:
        problem.check_fingers(hand.fingers)
        result = solve_ik(
            hand, problem, job.settings, job.sequence, obstacle=obj, database=job.database
        )
    except InvalidTargetError as exc:
        return _invalid(job, hand, problem.name, str(exc))
    if job.output == "result":
        return result
    return {**result.to_dict(hand), "setup_ms": setup_ms}


def _solve_chunk(job: Job, items: list[Item]) -> list[IKResult | dict[str, Any]]:
    """Solve one chunk in a worker; results in the chunk's order."""
    hand = worker_hand(job.description, job.digest)
    return [_solve_item(job, hand, item) for item in items]


def _solve_packed(job: Job, items: bytes) -> bytes:
    """:func:`_solve_chunk` on a pickled chunk, its results pickled.

    One bytes object each way instead of a tree of small arrays: Dask serialises every array of
    a task's arguments and results as a frame of its own (eight per problem); for a task of 32
    problems that cost 60-65 ms of CPU time (worker, client and scheduler) against about 20 ms
    pickled.
    """
    return pickle.dumps(_solve_chunk(job, pickle.loads(items)), pickle.HIGHEST_PROTOCOL)


_MAX_CHUNK_ITEMS = 64 * CHUNK_SIZE
"""Items of a chunk at most, invalid problems included (they are answered by the caller)."""


def _chunks(items: Iterable[Item], size: int) -> Iterator[list[Item]]:
    """Chunks of ``size`` problems to solve, with the invalid problems among them."""
    chunk: list[Item] = []
    valid = 0
    for item in items:
        chunk.append(item)
        valid += isinstance(item[0], GraspTarget)
        if valid == size or len(chunk) >= _MAX_CHUNK_ITEMS:
            yield chunk
            chunk, valid = [], 0
    if chunk:
        yield chunk


class _Batch:
    """A chunk under way: its valid problems sent to be solved, its invalid ones answered here."""

    def __init__(self, chunk: list[Item], job: Job, executor: Executor | None) -> None:
        self.chunk = chunk
        todo = [item for item in chunk if isinstance(item[0], GraspTarget)]
        self.future: Future[bytes | list[Any]] = Future()
        if not todo:
            self.future.set_result([])
        elif executor is None:
            self.future.set_result(_solve_chunk(job, todo))
        else:
            packed = pickle.dumps(todo, pickle.HIGHEST_PROTOCOL)
            self.future = executor.submit(_solve_packed, job, packed)

    def results(self, job: Job, hand: Hand) -> list[IKResult | dict[str, Any]]:
        done = self.future.result()
        solved = iter(pickle.loads(done) if isinstance(done, bytes) else done)
        return [
            next(solved) if isinstance(p, GraspTarget) else _invalid(job, hand, p.name, p.detail)
            for p, _, _ in self.chunk
        ]


def solve_chunks(
    hand: Hand,
    items: Iterable[Item],
    settings: IKSettings,
    sequence: PoseSequence | None = None,
    executor: Executor | None = None,
    output: Output = "entry",
    chunk_size: int = CHUNK_SIZE,
    in_flight: int = 2 * CHUNKS_IN_FLIGHT,
    database: GraspDatabase | None = None,
) -> Iterator[list[IKResult | dict[str, Any]]]:
    """Solve ``items`` lazily, yielding the results in input order, a chunk at a time.

    At most ``in_flight`` chunks of ``chunk_size`` problems are submitted and not yet collected,
    so ``items`` may be an unbounded stream: memory does not grow with its length. Invalid
    problems are answered here, without a trip to a worker.

    Args:
        hand: The hand.
        items: ``(problem, obstacle, key)`` triples: a :class:`GraspTarget` or an
            :class:`InvalidProblem`, its obstacle (a GraspObject, an ObjectSpec or None) and a
            string that is equal for equal obstacles.
        settings: IK settings.
        sequence: The pose sequence (None: the hand's default).
        executor: Where the chunks run (None: in this process).
        output: ``"entry"`` yields results-file entries (dicts), ``"result"`` IKResults.
        chunk_size: Problems per task.
        in_flight: Chunks submitted ahead of the oldest uncollected one.
        database: Grasp database of ``init="learned"`` (None: the hand's shipped one).
    """
    job = Job(hand.description, hand.description.digest(), settings, sequence, output, database)
    _CACHE.hands.setdefault(job.digest, hand)
    pending: deque[_Batch] = deque()
    try:
        for chunk in _chunks(items, chunk_size):
            pending.append(_Batch(chunk, job, executor))
            if len(pending) >= in_flight:
                yield pending.popleft().results(job, hand)
        while pending:
            yield pending.popleft().results(job, hand)
    finally:
        for batch in pending:
            batch.future.cancel()


def solve_stream(
    hand: Hand,
    items: Iterable[Item],
    settings: IKSettings,
    sequence: PoseSequence | None = None,
    executor: Executor | None = None,
    output: Output = "entry",
    chunk_size: int = CHUNK_SIZE,
    in_flight: int = 2 * CHUNKS_IN_FLIGHT,
) -> Iterator[IKResult | dict[str, Any]]:
    """:func:`solve_chunks`, one result at a time."""
    for results in solve_chunks(
        hand, items, settings, sequence, executor, output, chunk_size, in_flight
    ):
        yield from results


def object_key(obj: object) -> str:
    """The content key of an object: equal objects share a worker's kept copy."""
    return hashlib.sha256(pickle.dumps(obj)).hexdigest()


def _keyed(
    targets: Sequence[GraspTarget], obstacle: GraspObject | Sequence[GraspObject | None] | None
) -> Iterator[Item]:
    """The targets with their obstacles, each distinct obstacle object hashed once.

    A target without an ``obstacle`` given here grasps the object its targets file names.
    """
    per_target = isinstance(obstacle, list | tuple)
    if per_target and len(obstacle) != len(targets):  # type: ignore[arg-type]
        raise InvalidTargetError(
            f"obstacle holds {len(obstacle)} objects for {len(targets)} targets; "  # type: ignore[arg-type]
            "give one object (or None) per target, or one object for all"
        )
    keys: dict[int, str] = {}
    for i, target in enumerate(targets):
        obj = obstacle[i] if per_target else obstacle  # type: ignore[index]
        if obj is None and target.object_spec is not None:
            yield target, target.object_spec, target.object_spec.key()
            continue
        if obj is not None and id(obj) not in keys:
            check_obstacle(obj)
            keys[id(obj)] = object_key(obj)
        yield target, obj, keys.get(id(obj), "")


def solve_many(
    hand: Hand,
    targets: Sequence[GraspTarget],
    settings: IKSettings | None = None,
    sequence: PoseSequence | None = None,
    workers: int = 1,
    executor: Any = None,
    obstacle: GraspObject | Sequence[GraspObject | None] | None = None,
) -> list[IKResult]:
    """Solve every target; ``workers > 1`` or an ``executor`` spreads them over processes.

    Targets whose fingers do not match the hand get a ``reason="invalid_input"`` result.

    Args:
        hand: The hand.
        targets: The problems.
        settings: IK settings (default ``IKSettings()``).
        sequence: The pose sequence (None: the hand's default).
        workers: Local worker processes, when no ``executor`` is given.
        executor: A ``concurrent.futures.Executor``, a Dask scheduler address
            (``tcp://host:8786``) or a ``dask.distributed.Client``; the results are those of
            local workers.
        obstacle: The object every target grasps, or one object (or None) per target (see
            :func:`solve_ik`); each distinct object is built once per worker.

    Raises:
        InvalidTargetError: ``targets`` is not a list of GraspTarget; an ``obstacle`` is not a
            GraspObject, or the list has another length.
        InvalidSettingsError: ``settings`` is not an IKSettings, or ``workers`` is not an
            integer in 1 .. 4 per core.
    """
    if not isinstance(targets, list | tuple) or not all(
        isinstance(t, GraspTarget) for t in targets
    ):
        raise InvalidTargetError(f"targets must be a list of GraspTarget, got {targets!r:.80}")
    if executor is None:
        workers = check_workers(workers)  # None: one per core, as process_pool
    if settings is not None and not isinstance(settings, IKSettings):
        raise InvalidSettingsError(
            f"settings must be an IKSettings (or None: the defaults), got {type(settings).__name__}"
        )
    settings = settings or IKSettings()
    items = list(_keyed(targets, obstacle))
    if not items or (executor is None and workers <= 1):
        return list(solve_stream(hand, items, settings, sequence, output="result"))  # type: ignore[arg-type]
    count = 1 if executor is not None else workers
    largest = CHUNK_SIZE if executor is None else CLUSTER_CHUNK_SIZE
    size = max(1, min(largest, math.ceil(len(items) / (CHUNKS_IN_FLIGHT * count))))
    with open_executor(executor, None if executor is not None else workers) as pool:
        stream = solve_stream(hand, items, settings, sequence, pool, "result", size)
        return list(stream)  # type: ignore[arg-type]
