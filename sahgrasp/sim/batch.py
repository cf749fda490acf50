"""Hold tests of many grasps: the grasps of a results file, checked on local worker processes.

:func:`read_grasps` pairs the results of ``sahgrasp solve`` (a JSON document or JSON Lines) with
the problems of their targets file, which name each grasp's object, or reads a planner's
document (``{"object": ..., "grasps": [...]}``, or JSON Lines of such documents), which carries
its object. :func:`check_grasps` hold-tests them in order; each worker builds the MuJoCo model of
an object once and reuses it for every grasp of that object. A result depends only on the grasp,
the object and the settings, so any worker count gives the same results.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from sahgrasp.core.errors import SahGraspError
from sahgrasp.core.fileio import read_json
from sahgrasp.core.parallel import process_pool
from sahgrasp.ik.batch import worker_hand
from sahgrasp.model.contacts import ObjectSpec
from sahgrasp.model.hand import Hand, HandDescription, load_hand
from sahgrasp.objects.targets import InvalidProblem, build_object, object_spec, read_problems
from sahgrasp.sim.hold import HoldResult, HoldTester
from sahgrasp.sim.settings import HoldSettings

__all__ = [
    "CHUNK_GRASPS",
    "GraspToCheck",
    "ResultsFileError",
    "check_grasps",
    "grasp_configuration",
    "read_documents",
    "read_grasps",
    "summarize",
]

CHUNK_GRASPS = 8
"""Grasps of one object per task sent to a worker."""


class ResultsFileError(SahGraspError):
    """A results file cannot be read, or does not match its targets file."""


@dataclass(frozen=True)
class GraspToCheck:
    """One grasp of a results file.

    Attributes:
        name: The grasp's name (its problem's, or ``<object> #<rank>`` for a planner's grasp).
        object_spec: The object it grasps, or None.
        q: The hand's configuration (wrist pose, joints), or None when there is nothing to
            check.
        skipped: Why it is not checked (empty when it is).
        fingers: The contact fingers a planner's grasp names (its other fingers are free and
            do not squeeze); None: every fingertip near the object squeezes.
    """

    name: str
    object_spec: ObjectSpec | None
    q: NDArray[np.float64] | None
    skipped: str = ""
    fingers: tuple[str, ...] | None = None


def grasp_configuration(hand: Hand, entry: dict[str, Any], where: str) -> NDArray[np.float64]:
    """The configuration ``q`` of a results entry's ``wrist`` (``xyz``, ``quat``) and ``joints``.

    Raises:
        ResultsFileError: The wrist or a joint of the hand is missing or not a finite number.
    """
    wrist = entry.get("wrist")
    joints = entry.get("joints")
    if not isinstance(wrist, dict) or not isinstance(joints, dict):
        raise ResultsFileError(f"{where}: needs 'wrist' {{xyz, quat}} and 'joints'")
    try:
        xyz = np.array(wrist["xyz"], dtype=np.float64)
        quat = np.array(wrist["quat"], dtype=np.float64)
        values = {n: float(joints[n]) for n in hand.joint_names}
    except (KeyError, TypeError, ValueError) as exc:
        raise ResultsFileError(
            f"{where}: 'wrist' needs 'xyz' (3 numbers) and 'quat' (4), 'joints' a number for "
            f"each of {list(hand.joint_names)} ({type(exc).__name__}: {exc})"
        ) from None
    finite = np.all(np.isfinite(xyz)) and np.all(np.isfinite(quat))
    if (
        xyz.shape != (3,)
        or quat.shape != (4,)
        or not finite
        or not np.all(np.isfinite(list(values.values())))
    ):
        raise ResultsFileError(f"{where}: the wrist and joints must be finite numbers")
    norm = float(np.linalg.norm(quat))
    if abs(norm - 1.0) > 1e-3:
        raise ResultsFileError(f"{where}: the wrist quaternion must have unit length, got {norm}")
    pose = pin.XYZQUATToSE3(np.concatenate([xyz, quat / norm]))
    return hand.configuration(pose, values)


def _lines(path: Path) -> Iterator[tuple[int, Any]]:
    """The JSON value of each non-blank line of a JSON Lines file, with its line number."""
    try:
        handle = path.open("rb")
    except OSError as exc:
        raise ResultsFileError(f"cannot read results file {path}: {exc.strerror}") from None
    with handle:
        for number, raw in enumerate(handle, 1):
            if not raw.strip():
                continue
            if not raw.endswith(b"\n"):
                break  # a line cut by a stopped run (docs/how-to/file-formats.md)
            try:
                yield number, json.loads(raw.decode("utf-8"))
            except (UnicodeDecodeError, ValueError, RecursionError):
                raise ResultsFileError(f"results file {path}, line {number}: not JSON") from None


def _plan_grasps(
    hand: Hand, document: dict[str, Any], folder: Path, where: str, allow_outside_paths: bool
) -> list[GraspToCheck]:
    described = document.get("object")
    if isinstance(described, dict):  # what loading the mesh repaired is a note, not a key
        described = {k: v for k, v in described.items() if k != "repairs"}
    try:
        spec = object_spec(described, folder, allow_outside_paths=allow_outside_paths)
    except SahGraspError as exc:
        raise ResultsFileError(f"{where}: invalid 'object': {exc}") from None
    grasps = document.get("grasps")
    if not isinstance(grasps, list):
        raise ResultsFileError(f"{where}: 'grasps' must be a list")
    label = "object" if spec is None else (spec.name or Path(spec.mesh or "mesh").name)
    out = []
    for k, entry in enumerate(grasps):
        if not isinstance(entry, dict):
            raise ResultsFileError(f"{where}, grasp {k}: must be an object")
        name = f"{label} #{entry.get('rank', k + 1)}"
        q = grasp_configuration(hand, entry, f"{where}, grasp {name}")
        fingers = entry.get("fingers")
        if fingers is not None and (
            not isinstance(fingers, list) or any(f not in hand.fingers for f in fingers)
        ):
            raise ResultsFileError(
                f"{where}, grasp {name}: 'fingers' must list fingers of {list(hand.fingers)}"
            )
        named = None if fingers is None else tuple(fingers)
        out.append(GraspToCheck(name, spec, q, "" if spec else "no object", named))
    return out


def read_documents(path: str | Path) -> list[Any]:
    """The JSON values of a results file: one document, or one per line of a ``.jsonl`` file.

    Raises:
        ResultsFileError: The file cannot be read or is not JSON.
    """
    path = Path(path)
    if path.suffix.lower() == ".jsonl":
        return [value for _, value in _lines(path)]
    return [read_json(path, "results file", ResultsFileError)]


def read_grasps(
    hand: Hand,
    results: str | Path,
    targets: str | Path | None = None,
    *,
    allow_outside_paths: bool = False,
) -> list[GraspToCheck]:
    """The grasps of a results file, in order.

    Args:
        hand: The hand the results are for.
        results: ``sahgrasp solve`` results (JSON document or ``.jsonl``), or a planner's
            document(s) carrying their object (then ``targets`` may be None).
        targets: The targets file the results were solved from (names each grasp's object).
        allow_outside_paths: Accept object meshes named outside the folder of the file that
            names them (see :func:`sahgrasp.objects.targets.object_spec`).

    Raises:
        ResultsFileError: A file cannot be read, the results are not of the targets' problems
            (count or names differ), or an entry is malformed.
    """
    path = Path(results)
    values = read_documents(path)
    if values and all(isinstance(v, dict) and "grasps" in v for v in values):
        return [
            grasp
            for i, value in enumerate(values)
            for grasp in _plan_grasps(
                hand, value, path.parent, f"{path}, document {i + 1}", allow_outside_paths
            )
        ]
    if len(values) == 1 and isinstance(values[0], dict) and "results" in values[0]:
        entries = values[0]["results"]
    else:  # JSON Lines results: a header line (with "format"), then one entry per line
        entries = [v for v in values if not (isinstance(v, dict) and "format" in v)]
    if not isinstance(entries, list):
        raise ResultsFileError(f"results file {path}: 'results' must be a list")
    if targets is None:
        raise ResultsFileError(
            f"results file {path} holds no objects: give the targets file it was solved from"
        )
    _, problems = read_problems(targets, allow_outside_paths=allow_outside_paths)
    if len(problems) != len(entries):
        raise ResultsFileError(
            f"results file {path} has {len(entries)} results but targets file {targets} has "
            f"{len(problems)} problems: give the targets file the results were solved from"
        )
    out = []
    for k, (problem, entry) in enumerate(zip(problems, entries, strict=True)):
        if not isinstance(entry, dict):
            raise ResultsFileError(f"results file {path}, result {k}: must be an object")
        if entry.get("name") != problem.name:
            raise ResultsFileError(
                f"results file {path}, result {k} is {entry.get('name')!r} but problem {k} of "
                f"{targets} is {problem.name!r}: give the targets file the results were solved from"
            )
        if isinstance(problem, InvalidProblem):
            out.append(GraspToCheck(problem.name, None, None, "invalid problem"))
            continue
        if not entry.get("success"):
            out.append(GraspToCheck(problem.name, problem.object_spec, None,
                                    f"not solved ({entry.get('reason')})"))  # fmt: skip
            continue
        q = grasp_configuration(hand, entry, f"results file {path}, result {problem.name!r}")
        spec = problem.object_spec
        out.append(GraspToCheck(problem.name, spec, q, "" if spec else "no object"))
    return out


_KEPT_TESTERS = 8
"""Hold testers (compiled MuJoCo models) a hand's cache keeps: a long run covers many objects."""


def _tester(hand: Hand, spec: ObjectSpec, settings: HoldSettings) -> HoldTester | str:
    """The hand's tester of ``spec`` under ``settings``, kept in ``hand.cache``.

    A string says why the object cannot be simulated.
    """

    def build() -> HoldTester | str:
        try:
            return HoldTester(hand, build_object(spec), settings)
        except SahGraspError as exc:
            return f"object {spec} cannot be simulated: {exc}"

    return hand.cache.kept("hold_testers", (spec.key(), settings), build, _KEPT_TESTERS)


def _check_chunk(
    task: tuple[
        HandDescription,
        str,
        ObjectSpec,
        HoldSettings,
        list[tuple[str, NDArray[np.float64], tuple[str, ...] | None]],
    ],
) -> list[HoldResult | str]:
    """Hold-test grasps of one object (a worker's task); a string says why one was not.

    The worker's hand is the one :func:`sahgrasp.ik.worker_hand` keeps per worker (rebuilt from
    its description: Pinocchio's geometry does not pickle), its testers in the hand's cache.
    """
    description, digest, spec, settings, grasps = task
    tester = _tester(worker_hand(description, digest), spec, settings)
    if isinstance(tester, str):
        return [tester] * len(grasps)
    return [tester.test(q, name=name, fingers=fingers) for name, q, fingers in grasps]


def check_grasps(
    hand_name: str,
    grasps: Sequence[GraspToCheck],
    settings: HoldSettings | None = None,
    workers: int = 1,
    progress: Callable[[int], None] | None = None,
) -> list[HoldResult | str]:
    """Hold-test every checkable grasp; per grasp its result, or why it was not tested.

    Args:
        hand_name: The hand (a built-in name or a description path: workers load it).
        grasps: The grasps (:func:`read_grasps`).
        settings: The test's parameters.
        workers: Local worker processes (1: in this process).
        progress: Called with the number of grasps done after each chunk.
    """
    settings = settings or HoldSettings()
    description = load_hand(hand_name).description  # what the workers rebuild the hand from
    digest = description.digest()
    out: list[HoldResult | str] = [g.skipped or "" for g in grasps]
    tasks, where = [], []
    by_object: dict[str, list[int]] = {}
    for i, g in enumerate(grasps):
        if g.q is not None and g.object_spec is not None and not g.skipped:
            by_object.setdefault(g.object_spec.key(), []).append(i)
    for indices in by_object.values():
        for start in range(0, len(indices), CHUNK_GRASPS):
            chunk = indices[start : start + CHUNK_GRASPS]
            spec = grasps[chunk[0]].object_spec
            assert spec is not None
            items = [(grasps[i].name, grasps[i].q, grasps[i].fingers) for i in chunk]
            tasks.append((description, digest, spec, settings, items))
            where.append(chunk)
    done = 0

    def record(chunk: list[int], results: list[HoldResult | str]) -> None:
        nonlocal done
        for i, result in zip(chunk, results, strict=True):
            out[i] = result
        done += len(chunk)
        if progress is not None:
            progress(done)

    if workers <= 1 or len(tasks) <= 1:
        for task, chunk in zip(tasks, where, strict=True):
            record(chunk, _check_chunk(task))  # type: ignore[arg-type]
        return out
    with process_pool(min(workers, len(tasks))) as pool:
        for chunk, results in zip(where, pool.map(_check_chunk, tasks), strict=True):
            record(chunk, results)
    return out


def summarize(
    grasps: Sequence[GraspToCheck], results: Sequence[HoldResult | str]
) -> dict[str, Any]:
    """Counts and hold rates, over all grasps and per object (JSON-able)."""
    tested = [(g, r) for g, r in zip(grasps, results, strict=True) if isinstance(r, HoldResult)]
    per_object: dict[str, dict[str, Any]] = {}
    for g, r in tested:
        assert g.object_spec is not None
        label = str(g.object_spec.name or g.object_spec.mesh)
        row = per_object.setdefault(label, {"checked": 0, "holds": 0, "holds_bodex": 0})
        row["checked"] += 1
        row["holds"] += r.holds
        row["holds_bodex"] += r.holds_bodex
    for row in per_object.values():
        row["hold_rate"] = row["holds"] / row["checked"]
        row["hold_rate_bodex"] = row["holds_bodex"] / row["checked"]
    times = sorted(r.time_s for _, r in tested)
    holds = sum(r.holds for _, r in tested)
    holds_bodex = sum(r.holds_bodex for _, r in tested)
    return {
        "grasps": len(grasps),
        "checked": len(tested),
        "not_checked": len(grasps) - len(tested),
        "holds": holds,
        "holds_bodex": holds_bodex,
        "hold_rate": holds / len(tested) if tested else math.nan,
        "hold_rate_bodex": holds_bodex / len(tested) if tested else math.nan,
        "median_time_ms": 1e3 * times[len(times) // 2] if times else math.nan,
        "objects": per_object,
    }
