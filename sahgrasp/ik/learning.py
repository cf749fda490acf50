"""Building a grasp database for the learned start: random entries and grasp entries.

:func:`build_database` writes the :class:`~sahgrasp.ik.learned.GraspDatabase` that
``init="learned"`` reads (:mod:`sahgrasp.ik.learned`, whose module docstring describes the two
kinds of entries). Random entries are sampled collision-free configurations; grasp entries are
contact sets of the grasp sampler (:mod:`sahgrasp.objects.grasp_sampler`) on random primitive
solids, solved by the IK. This module sits above the solver and the batches it uses, so that the
solver's own module (which reads databases) does not import them back.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from concurrent.futures import Executor
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sahgrasp.core.fileio import lock_output, write_bytes_atomic
from sahgrasp.ik.batch import worker_hand
from sahgrasp.ik.learned import (
    CHUNK_SAMPLES,
    LEARN_SEED,
    PRIMITIVES_PER_CHUNK,
    SETS_PER_PRIMITIVE,
    GraspDatabase,
    GraspDatabaseError,
    rigid_features,
)
from sahgrasp.ik.solver import IKSettings, solve_ik
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import Hand, HandDescription
from sahgrasp.model.hands import hand_entry
from sahgrasp.objects.body import GraspObject
from sahgrasp.objects.grasp_sampler import (
    GraspSamplingError,
    registered_reach,
    sample_contact_sets,
)
from sahgrasp.objects.mesh_file import MeshSolid

__all__ = [
    "build_database",
    "grasp_chunk",
    "hand_reach",
    "primitive_chunks",
    "primitive_grasp_sets",
    "primitive_mesh",
    "primitive_object",
    "sample_chunk",
]


def sample_chunk(
    description: HandDescription, digest: str, seed: int, chunk: int, samples: int
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Random entries of chunk ``chunk``: ``samples`` collision-free configurations, features.

    A pure function of its arguments (seeded by ``[seed, chunk]``), so any executor may run it.
    """
    hand = worker_hand(description, digest)
    rng = np.random.default_rng([seed, chunk])
    q = np.array([hand.random_configuration(rng, collision_free=True) for _ in range(samples)])
    return _entries(hand, q)


def _entries(hand: Hand, q: NDArray[np.float64]) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Database rows of the configurations ``q`` (n, nq): themselves and their contacts' keys."""
    if not len(q):  # a grasp chunk whose solids all were out of reach
        return np.zeros((0, hand.nq), np.float32), np.zeros((0, 6 * len(hand.fingers)), np.float32)
    states = [hand.contact_state(x) for x in q]
    points, normals = np.array([s.points for s in states]), np.array([s.normals for s in states])
    return q.astype(np.float32), rigid_features(points, normals).astype(np.float32)


_GRASP_STREAM = 1
"""Second word of the grasp chunks' seeds (``[seed, 1, chunk]``), apart from the random ones'."""


def primitive_mesh(rng: np.random.Generator) -> Any:
    """A random primitive solid of graspable size, as a closed ``trimesh.Trimesh`` [m].

    One of four kinds, equally likely: a cylinder (radius 15-60 mm, height 40-200 mm), a box
    (edges 20-140 mm), an ellipsoid (semi-axes 20-70 mm) or a capsule (radius 15-50 mm, 20-150
    mm between the caps' centres). Their placement does not matter: the keys are rigid-invariant.
    """
    import trimesh.creation

    kind = int(rng.integers(4))
    if kind == 0:
        radius, height = rng.uniform(0.015, 0.06), rng.uniform(0.04, 0.2)
        return trimesh.creation.cylinder(radius=radius, height=height, sections=48)
    if kind == 1:
        return trimesh.creation.box(extents=rng.uniform(0.02, 0.14, 3))
    if kind == 2:
        sphere = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
        sphere.apply_scale(rng.uniform(0.02, 0.07, 3))
        return sphere
    radius, height = rng.uniform(0.015, 0.05), rng.uniform(0.02, 0.15)
    return trimesh.creation.capsule(radius=radius, height=height, count=[24, 24])


def primitive_object(mesh: Any) -> GraspObject:
    """The convex ``trimesh.Trimesh`` of :func:`primitive_mesh` as a GraspObject (its own hull)."""
    solid = MeshSolid(
        "primitive",
        np.asarray(mesh.vertices, dtype=np.float64),
        np.asarray(mesh.faces, dtype=np.int64),
        collision="hull",
    )
    return GraspObject("primitive", (solid,), (0.6, 0.6, 0.6, 1.0))


def primitive_chunks(grasp_sets: int) -> list[int]:
    """Primitive solids per grasp chunk for ``grasp_sets`` contact sets (rounded up to solids)."""
    return _split(-(-grasp_sets // SETS_PER_PRIMITIVE), PRIMITIVES_PER_CHUNK)


def primitive_grasp_sets(
    hand: Hand, seed: int, chunk: int, primitives: int
) -> Iterator[tuple[Any, list[GraspTarget]]]:
    """The solids of grasp chunk ``chunk`` and the contact sets drawn on each (seeded).

    Each of the ``primitives`` solids (:func:`primitive_mesh`) gets :data:`SETS_PER_PRIMITIVE`
    contact sets from the grasp sampler with the hand's reach; a solid too large or too small for
    it gives none and is skipped. Seeded by ``[seed, 1, chunk]``.
    """
    reach = hand_reach(hand)
    rng = np.random.default_rng([seed, _GRASP_STREAM, chunk])
    for _ in range(primitives):
        mesh, set_seed = primitive_mesh(rng), int(rng.integers(2**63))
        try:
            sets = sample_contact_sets(mesh, SETS_PER_PRIMITIVE, set_seed, reach)
        except GraspSamplingError:
            continue
        yield mesh, sets


def grasp_chunk(
    description: HandDescription, digest: str, seed: int, chunk: int, primitives: int
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Grasp entries of chunk ``chunk``: contact sets on ``primitives`` random solids, solved.

    Each set of :func:`primitive_grasp_sets` is solved by :func:`~sahgrasp.ik.solver.solve_ik`
    from the searched sequence with its solid as the obstacle (:func:`primitive_object`), and
    the solved ones are the entries: grasps that do not pass through their solid. A pure
    function of its arguments.
    """
    hand = worker_hand(description, digest)
    settings = IKSettings(init="sequence", seed=seed)  # validated once, not per solve
    solved = []
    for mesh, targets in primitive_grasp_sets(hand, seed, chunk, primitives):
        # With the solid as obstacle: a start that passes through its own solid leads the IK
        # into the user's object as well (docs/methods/ik.md, "The learned start").
        solid = primitive_object(mesh)
        results = (solve_ik(hand, t, settings, obstacle=solid) for t in targets)
        solved += [r.q for r in results if r.success]
    return _entries(hand, np.array(solved).reshape(-1, hand.nq))


def hand_reach(hand: Hand) -> Any:
    """The grasp sampler's :class:`~sahgrasp.objects.grasp_sampler.HandReach` of ``hand``.

    The reach measured with the IK that the hand's registry entry gives
    (:class:`sahgrasp.model.hands.SamplerReach`): grasp entries are solved contact sets, and a
    reach only bounded from the model draws many sets the hand cannot reach.

    Raises:
        GraspDatabaseError: The hand's entry gives no reach (or the hand is not registered).
    """
    entry = hand_entry(hand.description.name)
    if entry is None or entry.reach is None:
        raise GraspDatabaseError(
            f"grasp entries need the hand's measured reach, which the hand registry does not give "
            f"for {hand.description.name!r}; build with grasps=0 (`--grasps 0`) or register the "
            "hand with its reach (docs/methods/hand-model.md)"
        )
    return registered_reach(entry.name)


def build_database(
    hand: Hand,
    samples: int,
    out: str | os.PathLike[str],
    seed: int = LEARN_SEED,
    executor: Executor | None = None,
    progress: Any = None,
    grasp_sets: int = 0,
) -> GraspDatabase:
    """Build a database of ``samples`` random entries and grasp entries; write it to ``out``.

    Work is split into chunks (:data:`CHUNK_SAMPLES` random entries, or
    :data:`PRIMITIVES_PER_CHUNK` primitive solids); each finished chunk is saved in
    ``<out>.parts/`` and a rerun with the same arguments skips it, so an interrupted build
    resumes where it stopped. The result does not depend on the executor or on interruptions.
    ``out`` is locked while it is built (:func:`sahgrasp.core.fileio.lock_output`): a second build
    of the same file is refused, so that one build never removes the parts of another.

    Args:
        hand: The hand.
        samples: Random entries (>= 1).
        out: The ``.npz`` file to write (atomically).
        seed: Seed of the entries (default :data:`LEARN_SEED`).
        executor: Where the chunks run (None: in this process).
        progress: Called with (chunks done, chunks) after each chunk.
        grasp_sets: Contact sets to draw on primitive solids, :data:`SETS_PER_PRIMITIVE` per
            solid (rounded up); the solved ones become grasp entries (0: none).

    Raises:
        GraspDatabaseError: Grasp entries asked for a hand whose reach is unknown.
        OutputLockedError: Another build is writing ``out``.
    """
    if grasp_sets > 0:
        hand_reach(hand)
    with lock_output(out):
        return _build_locked(hand, samples, out, seed, executor, progress, grasp_sets)


def _build_locked(
    hand: Hand,
    samples: int,
    out: str | os.PathLike[str],
    seed: int,
    executor: Executor | None,
    progress: Any,
    grasp_sets: int,
) -> GraspDatabase:
    """:func:`build_database` with ``out`` locked."""
    digest = hand.description.digest()
    jobs = [(sample_chunk, "r", _split(samples, CHUNK_SAMPLES)),
            (grasp_chunk, "g", primitive_chunks(grasp_sets))]  # fmt: skip
    tasks = [(fn, i, n, f"{seed}-{tag}{i}-{n}-{digest[:16]}.npz")
             for fn, tag, sizes in jobs for i, n in enumerate(sizes)]  # fmt: skip
    parts = Path(f"{out}.parts")
    parts.mkdir(parents=True, exist_ok=True)
    todo = [t for t in tasks if not (parts / t[3]).is_file()]
    results: Any = iter(())
    if todo:
        args = [(fn, hand.description, digest, seed, i, n) for fn, i, n, _ in todo]
        results = (
            (_run(*a) for a in args)
            if executor is None
            else executor.map(_run, *zip(*args, strict=True))
        )
    done = len(tasks) - len(todo)
    for (_, _, _, name), (q, features) in zip(todo, results, strict=True):
        part = GraspDatabase(hand.description.name, digest, q, features, seed)
        write_bytes_atomic(parts / name, part.to_bytes())
        done += 1
        if progress is not None:
            progress(done, len(tasks))
    chunks = [_load_part(parts / name) for _, _, _, name in tasks]
    grasps = sum(
        len(c.configurations) for c, t in zip(chunks, tasks, strict=True) if t[0] is grasp_chunk
    )
    db = GraspDatabase(
        hand.description.name, digest,
        np.concatenate([c.configurations for c in chunks]).reshape(-1, hand.nq),
        np.concatenate([c.features for c in chunks]).reshape(-1, 6 * len(hand.fingers)),
        seed, grasps,
    )  # fmt: skip
    db.save(out)
    for _, _, _, name in tasks:
        (parts / name).unlink()
    parts.rmdir()
    return db


def _load_part(path: Path) -> GraspDatabase:
    """A finished chunk of :func:`build_database` (it may hold no entry)."""
    part = GraspDatabase._read(path)
    part.validate(str(path), empty_ok=True)
    return part


def _split(total: int, size: int) -> list[int]:
    """``total`` in chunks of ``size``, the last one smaller."""
    return [min(size, total - start) for start in range(0, total, size)]


def _run(fn: Any, *args: Any) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """``fn(*args)``: one picklable entry point for the executors' map."""
    return fn(*args)
