"""Plans for many objects: a folder of meshes, one JSON Lines document per object, resumable.

Each object is planned by one worker (:func:`plan_file`), from the hand's description and the
mesh file's path: nothing unpicklable crosses to the workers, and the object's draws depend only
on the plan's seed and the object's name, so the documents are the same on any number of workers
(or a Dask cluster) and in any order of completion; they are written in the folder's order as
they complete. Each document carries ``object_digest``, the SHA-256 of the mesh file's bytes and
of the settings: ``--resume`` keeps the documents of a stopped run whose digest still matches and
plans only the other objects.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Executor, Future, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sahgrasp.ik import worker_hand
from sahgrasp.model.hand import Hand, HandDescription
from sahgrasp.objects import GraspObject, load_mesh
from sahgrasp.objects.mesh_file import MESH_SUFFIXES, MeshFileError
from sahgrasp.planner.plan import plan_grasps
from sahgrasp.planner.settings import PlanningError, PlanSettings

__all__ = ["ObjectJob", "folder_jobs", "object_digest", "plan_file", "plan_jobs"]


@dataclass(frozen=True)
class ObjectJob:
    """One object of a folder run.

    Attributes:
        path: The mesh file.
        scale: Factor from the file's unit to metres.
        digest: :func:`object_digest` of the file and the settings.
    """

    path: str
    scale: float
    digest: str


def object_digest(
    path: str | os.PathLike[str], settings: PlanSettings, scale: float, hand: str
) -> str:
    """SHA-256 of a mesh file's bytes, the scale, the hand and the plan settings."""
    h = hashlib.sha256(Path(path).read_bytes())
    h.update(json.dumps([settings.to_dict(), scale, hand], sort_keys=True).encode("utf-8"))
    return h.hexdigest()


def folder_jobs(
    folder: str | os.PathLike[str], settings: PlanSettings, scale: float, hand: str
) -> list[ObjectJob]:
    """The mesh files of ``folder`` (STL, OBJ, PLY; sorted by name), as jobs.

    Raises:
        PlanningError: The folder holds no mesh file.
    """
    paths = sorted(
        p for p in Path(folder).iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES
    )
    if not paths:
        raise PlanningError(f"{folder} holds no mesh file ({', '.join(MESH_SUFFIXES)})")
    return [ObjectJob(str(p), scale, object_digest(p, settings, scale, hand)) for p in paths]


def plan_file(
    description: HandDescription,
    job: ObjectJob,
    settings: PlanSettings,
    make_check: Callable[[Hand, GraspObject], Any] | None = None,
    max_candidates: int | None = None,
) -> dict[str, Any]:
    """Plan one mesh file; its document (an ``error`` entry instead when the mesh is refused).

    ``make_check``: builds the extra check of every verified grasp for the file's hand and object
    (``plan_grasps(check=)``; e.g. :class:`sahgrasp.sim.verify.PhysicsCheckFactory` for ``plan
    --verify physics``), picklable so that workers build their own; a check with an ``annotate``
    method adds its verdicts to the document. None: no extra check. ``max_candidates``: with a
    check, the candidates the planner may draw in batches until enough grasps pass it
    (``plan_grasps(max_candidates=)``).
    """
    start = time.perf_counter()
    hand = worker_hand(description, description.digest())
    try:
        obj = load_mesh(job.path, scale=job.scale)
    except MeshFileError as exc:
        return {"object": {"mesh": job.path}, "object_digest": job.digest, "error": str(exc)}
    spec: dict[str, Any] = {"mesh": job.path, "xyz": [0.0, 0.0, 0.0], "quat": [0.0, 0.0, 0.0, 1.0]}
    if job.scale != 1.0:
        spec["scale"] = job.scale
    check = None if make_check is None else make_check(hand, obj)
    plan = plan_grasps(
        hand,
        obj,
        settings,
        object_spec=spec,
        check=check,
        started=start,
        max_candidates=max_candidates,
    )
    document = plan.to_dict()
    annotate = getattr(check, "annotate", None)
    if annotate is not None:
        document = annotate(document)
    return {**document, "object_digest": job.digest}


def plan_jobs(
    description: HandDescription,
    jobs: Iterable[ObjectJob],
    settings: PlanSettings,
    executor: Executor | None,
    in_flight: int = 4,
    make_check: Callable[[Hand, GraspObject], Any] | None = None,
    max_candidates: int | None = None,
) -> Iterator[dict[str, Any]]:
    """The documents of ``jobs``, in their order, planned here or on ``executor``'s workers.

    Up to ``in_flight`` objects are planned at once, largest file first (a mesh's planning time
    grows with its size: the long ones start early and the short ones fill the gaps at the
    end), and a worker gets the next object as soon as it finishes one; the documents are held
    back until those before them are done, so that they come out in ``jobs``' order.
    """
    if executor is None:
        for job in jobs:
            yield plan_file(description, job, settings, make_check, max_candidates)
        return
    ordered = list(jobs)
    queue = sorted(range(len(ordered)), key=lambda i: (-_size(ordered[i].path), i))
    running: dict[Future[dict[str, Any]], int] = {}
    finished: dict[int, dict[str, Any]] = {}
    following = 0
    try:
        while following < len(ordered):
            while queue and len(running) < max(in_flight, 1):
                index = queue.pop(0)
                job = ordered[index]
                running[
                    executor.submit(
                        plan_file, description, job, settings, make_check, max_candidates
                    )
                ] = index
            done, _ = wait(list(running), return_when=FIRST_COMPLETED)
            for future in done:
                finished[running.pop(future)] = future.result()
            while following in finished:
                yield finished.pop(following)
                following += 1
    finally:
        for future in running:
            future.cancel()


def _size(path: str) -> int:
    try:
        return os.stat(path).st_size
    except OSError:  # planned anyway: plan_file reports the error
        return 0
