"""``sahgrasp solve TARGETS``: IK for every problem of a targets file (JSON or JSON Lines)."""

from __future__ import annotations

import argparse
import math
import shlex
import sys
import time
from collections import Counter
from pathlib import Path
from statistics import mean, median
from typing import TYPE_CHECKING, Any

from sahgrasp.cli.common import (
    HAND_OVERRIDE_HELP,
    INITS_HELP,
    MAX_INITS,
    METHOD_HELP,
    add_command,
    add_mesh_path_argument,
    check_json_inputs,
    emit_json,
    human_stream,
    int_in_range,
    nonnegative_int,
    positive_int,
    printable,
    scheduler_address,
    work_executor,
)

if TYPE_CHECKING:
    from collections.abc import Iterable, Iterator

    from sahgrasp.ik.learned import GraspDatabase
    from sahgrasp.ik.stream import ResultsWriter
    from sahgrasp.model.contacts import GraspTarget
    from sahgrasp.model.hand import Hand
    from sahgrasp.objects.targets import InvalidProblem

__all__ = [
    "Summary",
    "add_parser",
    "check_run_outputs",
    "hand_inputs",
    "load_database",
    "results_document",
    "run",
    "solve_items",
]

TARGETS_HELP = "targets file: a JSON document, or JSON Lines (.jsonl) read line by line"
JSON_HELP = (
    "write the results to OUT: a JSON document, or JSON Lines if OUT ends in .jsonl (written "
    "as solved, resumable); '-': JSON alone on stdout, other lines on stderr"
)
DISPATCH_CHUNKS_IN_FLIGHT = 64
"""Chunks queued on a Dask cluster (its size is not known here): 8,192 problems."""


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    p = add_command(sub, "solve", "inverse kinematics for every problem of a targets file")
    p.add_argument("targets", type=Path, help=TARGETS_HELP)
    p.add_argument("--hand", default=None, help=HAND_OVERRIDE_HELP)
    p.add_argument("--method", choices=("auto", "paper"), default="auto", help=METHOD_HELP)
    p.add_argument(
        "--init",
        choices=("learned", "sequence", "random"),
        default="learned",
        help="initial configurations: the nearest solved grasps of the shipped database followed "
        "by the searched sequence of poses (the sequence alone for a hand without a database), "
        "the sequence alone, or random ones",
    )
    p.add_argument("--inits", type=int_in_range(1, MAX_INITS), default=12, help=INITS_HELP)
    p.add_argument(
        "--sequence",
        type=Path,
        default=None,
        help="sequence file of initial poses (default: the one shipped for the hand)",
    )
    p.add_argument("--seed", type=nonnegative_int, default=0, help="random seed (>= 0)")
    p.add_argument(
        "--database",
        type=Path,
        default=None,
        metavar="FILE",
        help="grasp database of --init learned, made by `sahgrasp learn` (default: the one "
        "shipped for the hand)",
    )
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=positive_int, default=1, help="worker processes (>= 1)")
    where.add_argument(
        "--scheduler",
        type=scheduler_address,
        default=None,
        metavar="ADDR",
        help="Dask scheduler, e.g. tcp://host:8786",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the JSON Lines results of a stopped run (--json OUT.jsonl)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_mesh_path_argument(p)
    p.add_argument("--json", default=None, metavar="OUT", help=JSON_HELP)
    p.set_defaults(run=run, on_interrupt=resume_hint)


def resume_hint(args: argparse.Namespace) -> str:
    """What to say when a run is interrupted: how to continue a JSON Lines output."""
    from sahgrasp.ik.stream import is_jsonl

    if not is_jsonl(args.json):
        return "interrupted"
    words = ["sahgrasp", *sys.argv[1:]]
    command = shlex.join(words if "--resume" in words else [*words, "--resume"])
    return f"interrupted; results so far in {args.json}.part; continue with: {command}"


def _line(entry: dict[str, Any]) -> str:
    """One problem's line for the terminal."""
    name = printable(entry["name"])
    if entry["reason"] == "invalid_input":
        return f"{name}: invalid input: {printable(entry.get('detail', 'refused by the solver'))}"
    status = "solved" if entry["success"] else f"FAILED ({entry['reason']})"
    error_mm = max(entry["max_position_error_mm"], entry["max_centre_error_mm"])
    setup = f" (set-up {entry['setup_ms']:.0f} ms)" if entry.get("setup_ms", 0.0) >= 1.0 else ""
    return (f"{name}: {status}, inits {entry['inits_used']}, iterations {entry['iterations']}, "
            f"{entry['time_ms']:.2f} ms{setup}, max error {error_mm:.3f} mm")  # fmt: skip


def results_document(hand_name: str, entries: list[dict[str, Any]]) -> dict[str, Any]:
    """The results file (docs/how-to/file-formats.md) from the results entries, in problem order.

    The summary's times are of the solves alone; the set-up (loading objects, building their
    collision pieces) is summed apart in ``setup_ms``.
    """
    times = [e["time_ms"] for e in entries if e["reason"] != "invalid_input"] or [0.0]
    solved = sum(e["success"] for e in entries)
    return {
        "hand": hand_name,
        "results": entries,
        "summary": {
            "problems": len(entries),
            "solved": solved,
            "invalid": sum(e["reason"] == "invalid_input" for e in entries),
            "success_rate": solved / len(entries) if entries else 0.0,
            "median_time_ms": median(times),
            "mean_time_ms": mean(times),
            "setup_ms": sum(float(e.get("setup_ms") or 0.0) for e in entries),
        },
    }


class Summary:
    """Counts of a run, in constant memory: solved, unsolved by reason, invalid, resumed."""

    def __init__(self) -> None:
        self.reasons: Counter[str] = Counter()
        self.solved = 0
        self.resumed = 0
        self.solve_ms = 0.0
        self.started = time.perf_counter()

    def add(self, entry: dict[str, Any], resumed: bool = False) -> None:
        """Count one result entry (``resumed``: read from the output, not solved now)."""
        self.solved += bool(entry.get("success"))
        self.reasons[str(entry.get("reason"))] += not entry.get("success")
        self.resumed += resumed
        if not resumed:
            self.solve_ms += float(entry.get("time_ms") or 0.0)

    @property
    def problems(self) -> int:
        """Problems counted."""
        return self.solved + sum(self.reasons.values())

    def line(self) -> str:
        """The final summary line."""
        invalid = self.reasons["invalid_input"]
        unsolved = ", ".join(f"{r} {n}" for r, n in sorted(self.reasons.items())
                             if n and r != "invalid_input")  # fmt: skip
        seconds = time.perf_counter() - self.started
        done = self.problems - self.resumed
        return (f"solved {self.solved}/{self.problems} ({invalid} invalid input); unsolved: "
                f"{unsolved or 'none'}; {self.resumed} resumed; {done} problems in {seconds:.1f} "
                f"s, {done / max(seconds, 1e-9):.1f} problems/s")  # fmt: skip


def _skip_finished(
    writer: ResultsWriter,
    problems: Iterator[GraspTarget | InvalidProblem],
    summary: Summary,
    out: Any,
) -> Iterator[GraspTarget | InvalidProblem]:
    """Count the results a resumed output holds for unchanged problems; the problems left.

    A result is kept while its ``problem_digest`` is the digest of the problem at its place in
    the targets file; from the first changed problem on (or the first result without a
    digest), the problems are solved again and the file is cut there.
    """
    import itertools

    from sahgrasp.ik.stream import problem_digest

    changed: GraspTarget | InvalidProblem | None = None
    finished = writer.finished()  # a generator: closing it keeps the entry it stopped at out
    try:
        for entry in finished:
            problem = next(problems, None)
            if problem is None:
                break  # the targets file is shorter now: the extra results are cut
            if entry.get("problem_digest") != problem_digest(problem):
                changed = problem
                break
            summary.add(entry, resumed=True)
    finally:
        finished.close()  # the entry it stopped at is not kept
    if changed is None:
        return problems
    print(
        f"{printable(changed.name)} (problem {summary.resumed}) differs from the one "
        f"{writer.shown} was solved for: kept {summary.resumed} results, solving again from there",
        file=out,
    )
    return itertools.chain([changed], problems)


def _chunking(args: argparse.Namespace, total: int | None) -> tuple[int, int]:
    """Problems per chunk and chunks in flight: all workers busy, scheduling cost under 1%."""
    from sahgrasp.ik.batch import CHUNK_SIZE, CHUNKS_IN_FLIGHT, CLUSTER_CHUNK_SIZE

    if args.scheduler is not None:
        return CLUSTER_CHUNK_SIZE, DISPATCH_CHUNKS_IN_FLIGHT
    if args.workers <= 1:  # solved here: each chunk written as soon as it is solved
        return CHUNK_SIZE, 1
    if total is None:  # a pipe: its length is not known
        return CHUNK_SIZE, CHUNKS_IN_FLIGHT * args.workers
    per_worker = math.ceil(total / (CHUNKS_IN_FLIGHT * args.workers))
    return max(1, min(CHUNK_SIZE, per_worker)), CHUNKS_IN_FLIGHT * args.workers


def hand_inputs(hand_name: str, hand: Hand | None = None) -> list[Path]:
    """The files a hand is read from: its description file (if a path) and its URDF."""
    files = [Path(hand_name)] if Path(hand_name).suffix and Path(hand_name).is_file() else []
    if hand is not None:
        files.append(hand.description.urdf_path)
    return files


def check_run_outputs(out: str | None, inputs: Iterable[str | Path | None]) -> None:
    """Check an output and, for JSON Lines, its side files against every input of the run.

    Raises:
        OutputPathError: The output, ``OUT.part`` or ``OUT.lock`` is an input, or the output
            cannot be written.
    """
    from sahgrasp.core.fileio import check_output_path, side_files
    from sahgrasp.ik.stream import is_jsonl

    if out is None or out == "-":
        return
    check_output_path(out, inputs, side=side_files(out) if is_jsonl(out) else ())


def load_database(path: Path | None, hand: Hand, init: str) -> GraspDatabase | None:
    """The grasp database of ``--database`` (None: the hand's shipped one), made for ``hand``.

    Raises:
        InvalidSettingsError: A database with an ``init`` other than ``learned``.
        GraspDatabaseError: Not a database file, or one made for another hand.
    """
    from sahgrasp.core.errors import InvalidSettingsError
    from sahgrasp.ik.learned import GraspDatabase

    if path is None:
        return None
    if init != "learned":
        raise InvalidSettingsError(
            f"--database is the database of --init learned, not of --init {init}; drop one"
        )
    database = GraspDatabase.load(path)
    database.check_hand(hand)
    return database


def solve_items(
    problems: Iterable[GraspTarget | InvalidProblem],
    outputs: Iterable[Path],
    named: list[str],
    digests: Any = None,
) -> Iterator[tuple[GraspTarget | InvalidProblem, Any, str]]:
    """The ``(problem, object, key)`` items of :func:`sahgrasp.ik.batch.solve_chunks`.

    A problem whose mesh is one of ``outputs`` is not read: it becomes an invalid problem and
    its name is appended to ``named`` (the run must then not publish that output).

    Args:
        problems: The problems, in file order.
        outputs: The files the run writes (side files included).
        named: Receives the names of the problems that name an output.
        digests: A deque that receives each problem's :func:`~sahgrasp.ik.stream.problem_digest`
            (None: not computed).
    """
    import os

    from sahgrasp.ik.stream import problem_digest
    from sahgrasp.objects.targets import InvalidProblem

    written = {os.path.realpath(p) for p in outputs}
    for problem in problems:
        spec = getattr(problem, "object_spec", None)
        if spec is not None and spec.mesh is not None and os.path.realpath(spec.mesh) in written:
            named.append(problem.name)
            problem = InvalidProblem(
                problem.name, f"its mesh {spec.mesh} is a file this run writes; not read"
            )
            spec = None
        if digests is not None:
            digests.append(problem_digest(problem))
        yield problem, spec, "" if spec is None else spec.key()


def _check_run(args: argparse.Namespace, hand_name: str, inputs: list[Any]) -> None:
    from sahgrasp.core.errors import InvalidSettingsError
    from sahgrasp.ik.stream import is_jsonl

    check_run_outputs(args.json, inputs)
    check_json_inputs(hand_name, args.sequence)
    if args.resume and not is_jsonl(args.json):
        raise InvalidSettingsError("--resume continues a JSON Lines output: give --json OUT.jsonl")


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp solve``; 0 if every problem was solved, 1 otherwise."""
    from sahgrasp.ik.stream import open_targets

    targets = open_targets(args.targets, allow_outside_paths=args.allow_any_mesh_path)
    hand_name = args.hand or targets.hand
    inputs = [args.targets, args.sequence, args.database, *targets.files, *hand_inputs(hand_name)]
    _check_run(args, hand_name, inputs)

    from collections import deque

    from sahgrasp.core.fileio import OutputPathError, file_digest, side_files
    from sahgrasp.ik import IKSettings, Sequence, default_sequence
    from sahgrasp.ik.batch import solve_chunks
    from sahgrasp.ik.stream import ResultsWriter, is_jsonl, settings_header
    from sahgrasp.model.hand import load_hand

    hand = load_hand(hand_name)
    check_run_outputs(args.json, hand_inputs(hand_name, hand))  # the URDF the description names
    database = load_database(args.database, hand, args.init)
    settings = IKSettings(method=args.method, init=args.init, max_inits=args.inits, seed=args.seed)
    sequence = Sequence.load(args.sequence) if args.sequence else None
    summary = Summary()
    out = human_stream(args.json)
    writer = None
    outputs = [] if args.json in (None, "-") else [Path(args.json), *side_files(args.json)]
    named: list[str] = []
    entries: list[dict[str, Any]] = []
    complete = False
    try:
        problems = targets.problems
        if is_jsonl(args.json):
            used = sequence or default_sequence(hand)
            header = settings_header(
                hand, settings, used.to_dict(), args.targets, targets.digest,
                None if args.database is None else file_digest(args.database),
            )  # fmt: skip
            writer = ResultsWriter(args.json, header, args.resume)
            problems = _skip_finished(writer, problems, summary, out)
        digests: deque[str] = deque()
        items = solve_items(problems, outputs, named, digests)
        total = None if targets.total is None else targets.total - summary.resumed
        size, in_flight = _chunking(args, total)
        with work_executor(args) as pool, _bar(args, targets.total, summary.resumed) as bar:
            for chunk in solve_chunks(
                hand, items, settings, sequence, pool, "entry", size, in_flight, database
            ):
                done: list[dict[str, Any]] = chunk  # type: ignore[assignment]
                for entry in done:
                    entry["problem_digest"] = digests.popleft()
                    summary.add(entry)
                bar.update(len(done))
                if writer is not None:
                    writer.write(done)
                else:  # a document: written at the end, each problem shown as it is solved
                    entries += done
                    bar.write("\n".join(map(_line, done)), file=out)
        complete = True
    finally:
        if writer is not None:
            writer.close(complete, publish=not named)
    if named:
        kept = f"; the results are in {args.json}.part" if writer is not None else ""
        raise OutputPathError(
            f"problem(s) {', '.join(map(repr, named[:3]))} name the output {args.json} (or its "
            f"side files) as their mesh: an input is never replaced{kept}"
        )
    print(summary.line(), file=out)
    if writer is None and args.json:
        emit_json(results_document(hand.description.name, entries), args.json)
    elif writer is not None:
        print(f"wrote {args.json}", file=out)
    return 0 if summary.solved == summary.problems else 1


def _bar(args: argparse.Namespace, total: int | None, done: int) -> Any:
    """A tqdm bar on stderr (problems/s and ETA), shown on a terminal unless ``--quiet``."""
    from tqdm import tqdm

    return tqdm(
        total=total, initial=done, unit="problem", smoothing=0.05, file=sys.stderr,
        disable=True if args.quiet else None, dynamic_ncols=True,
    )  # fmt: skip
