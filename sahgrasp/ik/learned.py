"""A start chosen for each problem: the nearest grasps of a database (``init="learned"``).

The conclusions of Claret & Suárez's IK paper propose "the generation of a proper initial hand
configuration as a function of the constraints imposed by the contact points". A
:class:`GraspDatabase` holds hand configurations together with their fingertip contacts, keyed by
features that a rigid motion does not change: the contact points and normals expressed in a frame
built from the contacts themselves. For a target, the nearest keys (``scipy.spatial.cKDTree``)
give the finger joints of the first starts; each start's wrist is the neighbour's wrist moved by
the rigid transform that best aligns its contacts to the target's (least squares, Horn's closed
form).

The entries are of two kinds. *Random* entries are collision-free configurations of the hand
(every joint uniform in its range, virtual contact joints in the contact region): each is exactly
solved by its own contacts, so no IK runs to build them. *Grasp* entries are solved grasps of
contact sets that a grasp planner would draw (:mod:`sahgrasp.objects.grasp_sampler`) on random
primitive solids -- cylinders, boxes, ellipsoids and capsules of graspable sizes, none of them a
catalog object -- each solved by the IK from the searched sequence, the solid as the obstacle
(no link passes through it): a planner's contact sets lie
far from every random entry's key, and nearest random entries started no better there than the
sequence (docs/ik.md, "The learned start"). Grasp entries need the hand's reach, known for the
SAH only. The seeds (:data:`LEARN_SEED`) are used nowhere else.
"""

from __future__ import annotations

import io
import os
import zipfile
from collections.abc import Iterator
from concurrent.futures import Executor
from dataclasses import dataclass
from functools import cached_property
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from sahgrasp.core.errors import SequenceFileError
from sahgrasp.core.fileio import lock_output, write_bytes_atomic
from sahgrasp.ik._lm import rigid_key
from sahgrasp.ik.compiled import compiled_tree
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import Hand, HandDescription, check_made_for

if TYPE_CHECKING:
    from sahgrasp.objects.body import GraspObject

__all__ = [
    "CHUNK_SAMPLES",
    "FORMAT",
    "LEARN_SEED",
    "PRIMITIVES_PER_CHUNK",
    "SETS_PER_PRIMITIVE",
    "GraspDatabase",
    "GraspDatabaseError",
    "build_database",
    "contact_key",
    "default_database",
    "grasp_chunk",
    "primitive_chunks",
    "primitive_grasp_sets",
    "primitive_mesh",
    "primitive_object",
    "rigid_features",
    "target_key",
]

FORMAT = "sahgrasp-grasp-db-1"
"""Format tag stored in every database file."""
LEARN_SEED = 61_803_398
"""Seed of the shipped databases; no benchmark or test draws from it."""
CHUNK_SAMPLES = 2000
"""Random entries per chunk of :func:`build_database` (the unit of work, checkpoint, resume)."""
SETS_PER_PRIMITIVE = 5
"""Contact sets drawn on each random primitive solid of the grasp entries."""
PRIMITIVES_PER_CHUNK = 100
"""Primitive solids per chunk of grasp entries."""
NORMAL_WEIGHT_M = 0.02
"""Length [m] that a unit normal counts as in the features: 1 rad of normal ~ 2 cm of contact."""
QUERY_EPS = 1.0
"""Approximation of the neighbour search (``cKDTree.query``'s ``eps``): the k-th neighbour found
is within ``1 + eps`` times the true k-th nearest distance. In the 18-dimensional feature space an
exact search visits most leaves (about 0.4 ms a query); with eps = 1 it is 3x faster and finds
99% of the exact two nearest (docs/ik.md, "Cost")."""


class GraspDatabaseError(SequenceFileError):
    """A grasp database is missing, unreadable, malformed, or made for another hand."""


def rigid_features(points: NDArray[np.float64], normals: NDArray[np.float64]) -> NDArray[Any]:
    """Features of contact sets that a rigid motion of the set does not change.

    The frame: origin at the contacts' centroid, x towards the first contact (the thumb), y the
    part of "last minus second contact" orthogonal to x, z = x cross y. The features are the
    points in that frame [m] and the normals scaled by :data:`NORMAL_WEIGHT_M`.

    Args:
        points: Contact points, shape (..., F, 3) [m], F >= 3.
        normals: Their unit normals, shape (..., F, 3).

    Returns:
        Shape (..., 6 F).
    """
    if points.ndim > 2:  # a batch (building a database): one contact set at a time
        flat_points, flat_normals = (
            points.reshape(-1, *points.shape[-2:]),
            normals.reshape(-1, *normals.shape[-2:]),
        )
        each = [rigid_features(p, n) for p, n in zip(flat_points, flat_normals, strict=True)]
        return np.array(each).reshape(*points.shape[:-2], -1)
    out = np.empty(6 * points.shape[-2])
    # Compiled: on a few 3-vectors numpy's fixed cost per call is many times the arithmetic.
    rigid_key(np.ascontiguousarray(points), np.ascontiguousarray(normals), NORMAL_WEIGHT_M, out)
    return out


def target_key(hand: Hand, target: GraspTarget) -> NDArray[np.float64] | None:
    """The database key of ``target``; None without a contact for every finger."""
    if set(target.fingers) != set(hand.fingers):
        return None
    contacts = [target.contact(f) for f in hand.fingers]
    points = np.array([c.point for c in contacts])
    return contact_key(points, np.array([c.normal for c in contacts]))


def contact_key(
    points: NDArray[np.float64], target_normals: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The database key (:func:`rigid_features`) of contacts in the hand's finger order.

    Args:
        points: Contact points, shape (F, 3) [m].
        target_normals: The targets' unit normals, which point into the fingertips (the features
            use the fingertips' outward ones), shape (F, 3).
    """
    out = np.empty(6 * len(points))
    points, target_normals = np.ascontiguousarray(points), np.ascontiguousarray(target_normals)
    rigid_key(points, target_normals, -NORMAL_WEIGHT_M, out)
    return out


@dataclass(frozen=True)
class GraspDatabase:
    """Solved grasps of one hand, looked up by :func:`rigid_features` of their contacts.

    Attributes:
        hand: Hand name.
        hand_digest: :meth:`HandDescription.digest` of the hand it was made for.
        configurations: Configurations ``q``, shape (n, nq) (float32: they are starts only).
        features: :func:`rigid_features` of their contacts, shape (n, 6 F) (float32).
        seed: Seed the entries were drawn from.
        grasp_entries: How many of the entries, the last ones, are solved grasps of contact sets
            drawn on primitive solids (the others are random configurations).
    """

    hand: str
    hand_digest: str
    configurations: NDArray[np.float32]
    features: NDArray[np.float32]
    seed: int
    grasp_entries: int = 0

    @cached_property
    def tree(self) -> cKDTree:
        """The k-d tree of the features, built on first use."""
        return cKDTree(self.features.astype(np.float64))  # float64 queries are faster

    def __getstate__(self) -> dict[str, Any]:
        """The fields without the k-d tree: a worker rebuilds it rather than unpickle it."""
        state = dict(self.__dict__)
        state.pop("tree", None)
        return state

    def check_hand(self, hand: Hand) -> None:
        """Raise :class:`GraspDatabaseError` unless this database was made for ``hand``."""
        check_made_for(
            hand, "grasp database", self.hand, self.hand_digest, GraspDatabaseError,
            "build one with `sahgrasp learn --hand ...`",
        )  # fmt: skip

    def starts(
        self, hand: Hand, key: NDArray[np.float64], goal: NDArray[np.float64], count: int
    ) -> Iterator[NDArray[np.float64]]:
        """The ``count`` nearest entries' configurations, each wrist moved onto the target.

        Lazy: a start is aligned only when the solver asks for it.

        Args:
            hand: The hand.
            key: The target's key (:func:`contact_key`, :func:`target_key`).
            goal: The target's contact stack (p_i*, r_i*) per finger in the hand's order, shape
                (6 F,) [m]: each start's wrist moves by the rigid motion that best maps its own
                stack onto it (least squares, Horn's closed form, compiled).
            count: Starts to yield at most.
        """
        if count <= 0:
            return
        _, index = self.tree.query(key, k=min(count, len(self.features)), eps=QUERY_EPS)
        tree, fingers = compiled_tree(hand), np.arange(len(hand.fingers))
        for i in np.atleast_1d(index).tolist():
            q = self.configurations[i].astype(np.float64)
            tree.align(q, goal, fingers)
            yield q

    def to_bytes(self) -> bytes:
        """The ``.npz`` file content."""
        buffer = io.BytesIO()
        np.savez(
            buffer,
            format=np.array(FORMAT),
            hand=np.array(self.hand),
            hand_digest=np.array(self.hand_digest),
            seed=np.array(self.seed),
            grasp_entries=np.array(self.grasp_entries),
            configurations=self.configurations,
            features=self.features,
        )
        return buffer.getvalue()

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write atomically (``.npz``)."""
        write_bytes_atomic(path, self.to_bytes())

    @classmethod
    def load(cls, path: str | os.PathLike[str] | Any) -> GraspDatabase:
        """Read a database file, raising :class:`GraspDatabaseError` if it is not one."""
        db = cls._read(path)
        db.validate(str(path))
        return db

    @classmethod
    def _read(cls, path: str | os.PathLike[str] | Any) -> GraspDatabase:
        """The file's database, not yet validated."""
        try:
            with np.load(path, allow_pickle=False) as data:
                if str(data["format"]) != FORMAT:
                    raise ValueError(f"format is {str(data['format'])!r}, not {FORMAT}")
                # Files written before grasp entries existed hold random entries only.
                grasps = int(data["grasp_entries"]) if "grasp_entries" in data.files else 0
                db = cls(
                    str(data["hand"]), str(data["hand_digest"]),
                    np.asarray(data["configurations"], dtype=np.float32),
                    np.asarray(data["features"], dtype=np.float32), int(data["seed"]), grasps,
                )  # fmt: skip
        except FileNotFoundError as exc:
            raise GraspDatabaseError(f"grasp database {path} not found") from exc
        except (OSError, KeyError, ValueError, TypeError, EOFError, zipfile.BadZipFile) as exc:
            raise GraspDatabaseError(
                f"{path} is not a valid sahgrasp grasp database ({exc}); build one with "
                "`sahgrasp learn --hand ... --out FILE`"
            ) from exc
        return db

    def validate(self, origin: str, empty_ok: bool = False) -> None:
        """Raise :class:`GraspDatabaseError` on inconsistent shapes or non-finite values.

        Args:
            origin: Where the database comes from (for the message).
            empty_ok: Accept a database without entries (a chunk of :func:`build_database`).
        """
        n = len(self.configurations)
        ok = (
            (n > 0 or empty_ok)
            and self.configurations.ndim == 2
            and self.features.shape[0] == n
            and self.features.ndim == 2
            and 0 <= self.grasp_entries <= n
            and bool(np.isfinite(self.configurations).all() and np.isfinite(self.features).all())
        )
        if not ok:
            raise GraspDatabaseError(
                f"{origin}: a grasp database needs n > 0 finite configurations (n, nq), features "
                f"(n, 6F) and 0 <= grasp_entries <= n; got {self.configurations.shape}, "
                f"{self.features.shape} and {self.grasp_entries}"
            )


def sample_chunk(
    description: HandDescription, digest: str, seed: int, chunk: int, samples: int
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Random entries of chunk ``chunk``: ``samples`` collision-free configurations, features.

    A pure function of its arguments (seeded by ``[seed, chunk]``), so any executor may run it.
    """
    from sahgrasp.ik.batch import worker_hand  # the workers' hand cache

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
    from sahgrasp.objects.body import GraspObject
    from sahgrasp.objects.mesh_file import MeshSolid

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
    from sahgrasp.objects.grasp_sampler import GraspSamplingError, sample_contact_sets

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
    from sahgrasp.ik.batch import worker_hand
    from sahgrasp.ik.solver import IKSettings, solve_ik

    hand = worker_hand(description, digest)
    settings = IKSettings(init="sequence", seed=seed)  # validated once, not per solve
    solved = []
    for mesh, targets in primitive_grasp_sets(hand, seed, chunk, primitives):
        # With the solid as obstacle: a start that passes through its own solid leads the IK
        # into the user's object as well (docs/ik.md, "The learned start").
        solid = primitive_object(mesh)
        results = (solve_ik(hand, t, settings, obstacle=solid) for t in targets)
        solved += [r.q for r in results if r.success]
    return _entries(hand, np.array(solved).reshape(-1, hand.nq))


def hand_reach(hand: Hand) -> Any:
    """The grasp sampler's :class:`~sahgrasp.objects.grasp_sampler.HandReach` of ``hand``.

    Raises:
        GraspDatabaseError: Not known for this hand (the SAH's only).
    """
    from sahgrasp.objects.grasp_sampler import SAH_REACH

    if hand.description.name != "sah":
        raise GraspDatabaseError(
            f"grasp entries need the hand's reach, known for the SAH only, not for "
            f"{hand.description.name!r}; build with grasps=0 (`--grasps 0`)"
        )
    return SAH_REACH


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


_DEFAULTS: dict[str, GraspDatabase | None] = {}


def default_database(hand: Hand) -> GraspDatabase | None:
    """The shipped database of ``hand`` (``sahgrasp/data/grasps/<name>.npz``), None if none.

    A shipped file made for another version of the hand is not used (None): the learned start
    then falls back to the sequence.

    Raises:
        GraspDatabaseError: The shipped file is corrupt.
    """
    digest = hand.description.digest()
    if digest not in _DEFAULTS:
        shipped = resources.files("sahgrasp") / "data" / "grasps" / f"{hand.description.name}.npz"
        db = None
        if shipped.is_file():
            with shipped.open("rb") as stream:
                db = GraspDatabase.load(io.BytesIO(stream.read()))
            db = db if db.hand_digest == digest else None
        _DEFAULTS[digest] = db
    return _DEFAULTS[digest]
