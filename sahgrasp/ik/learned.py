"""A start chosen for each problem: the nearest grasps of a database (``init="learned"``).

The conclusions of Claret & Suárez's IK paper propose "the generation of a proper initial hand
configuration as a function of the constraints imposed by the contact points". A
:class:`GraspDatabase` holds hand configurations together with their fingertip contacts, keyed by
features that a rigid motion does not change: the contact points and normals expressed in a frame
built from the contacts themselves. For a target, the nearest keys (``scipy.spatial.cKDTree``)
give the finger joints of the first starts; each start's wrist is the neighbour's wrist moved by
the rigid transform that best aligns its contacts to the target's (Kabsch's least squares).

The entries are random collision-free configurations of the hand (every joint uniform in its
range, virtual contact joints in the contact region): each is exactly solved by its own contacts,
so no IK runs to build the database. Its seeds (:data:`LEARN_SEED`) are used nowhere else.
"""

from __future__ import annotations

import io
import math
import os
import zipfile
from collections.abc import Iterator
from concurrent.futures import Executor
from dataclasses import dataclass
from functools import cached_property
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from scipy.linalg.lapack import dgesdd
from scipy.spatial import cKDTree

from sahgrasp.contacts import GraspTarget
from sahgrasp.errors import SequenceFileError
from sahgrasp.fileio import write_bytes_atomic
from sahgrasp.hand import Hand, HandDescription, check_made_for
from sahgrasp.ik.compiled import compiled_tree
from sahgrasp.ik.initial import cross_floats

__all__ = [
    "CHUNK_SAMPLES",
    "FORMAT",
    "LEARN_SEED",
    "GraspDatabase",
    "GraspDatabaseError",
    "build_database",
    "default_database",
    "rigid_features",
    "target_key",
]

FORMAT = "sahgrasp-grasp-db-1"
"""Format tag stored in every database file."""
LEARN_SEED = 61_803_398
"""Seed of the shipped databases; no benchmark or test draws from it."""
CHUNK_SAMPLES = 2000
"""Entries per chunk of :func:`build_database` (the unit of work, checkpoint and resume)."""
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
    frame, centroid = _contact_frame(points)
    # Points and scaled normals in one product: (2F, 3) rows times the frame's axes.
    rows = np.concatenate([points - centroid, normals * NORMAL_WEIGHT_M])
    return np.asarray(rows.dot(frame.T).ravel())


def _contact_frame(
    points: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Rows: the axes of :func:`rigid_features`' frame in world, shape (3, 3); the centroid (3,).

    In Python floats: on a few 3-vectors numpy's fixed cost per call (several microseconds for
    ``np.sum``, ``np.stack``, fancy indexing) is many times the arithmetic; this was about 60 us
    in numpy and is about 10 in floats (docs/ik.md, "Where the time goes").
    """
    rows = points.tolist()
    n = len(rows)
    centroid = [sum(column) / n for column in zip(*rows, strict=True)]
    x = _unit([a - c for a, c in zip(rows[0], centroid, strict=True)])
    side = [a - b for a, b in zip(rows[-1], rows[1], strict=True)]
    along = sum(a * b for a, b in zip(side, x, strict=True))
    y = _unit([a - along * b for a, b in zip(side, x, strict=True)])
    return np.array([x, y, cross_floats(x, y)]), np.array(centroid)


def _unit(v: list[float]) -> list[float]:
    norm = max(math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]), 1e-12)
    return [v[0] / norm, v[1] / norm, v[2] / norm]


def kabsch(source: NDArray[np.float64], target: NDArray[np.float64]) -> pin.SE3:
    """The rigid transform ``T`` minimising ``sum |T source_i - target_i|^2`` (rows are points).

    LAPACK's ``dgesdd`` directly: ``np.linalg.svd``'s checks cost twice the 3 x 3 decomposition.
    """
    scale = 1.0 / len(source)
    cs, ct = source.sum(axis=0) * scale, target.sum(axis=0) * scale
    # The centred source sums to zero, so the target needs no centring in the covariance.
    U, _, Vt, info = dgesdd((source - cs).T.dot(target))
    if info != 0:
        raise np.linalg.LinAlgError(f"dgesdd failed ({info}) on a 3 x 3 covariance")
    R = U.dot(Vt).T
    if _det3(R) < 0.0:  # a reflection: flip the axis of the smallest singular value
        Vt[2] *= -1.0
        R = U.dot(Vt).T
    return pin.SE3(R, ct - R.dot(cs))


def _det3(M: NDArray[np.float64]) -> float:
    """Determinant of a 3 x 3 matrix, in plain floats (np.linalg.det costs ~10 us here)."""
    (a, b, c), (d, e, f), (g, h, i) = M.tolist()
    return float(a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g))


def target_key(hand: Hand, target: GraspTarget) -> NDArray[np.float64] | None:
    """The database key (:func:`rigid_features`) of ``target``; None without every finger."""
    if set(target.fingers) != set(hand.fingers):
        return None
    contacts = [target.contact(f) for f in hand.fingers]
    points = np.array([c.point for c in contacts])
    # Target normals point into the fingertips; the features use the fingertips' outward ones.
    normals = -np.array([c.normal for c in contacts])
    return np.asarray(rigid_features(points, normals))


@dataclass(frozen=True)
class GraspDatabase:
    """Solved grasps of one hand, looked up by :func:`rigid_features` of their contacts.

    Attributes:
        hand: Hand name.
        hand_digest: :meth:`HandDescription.digest` of the hand it was made for.
        configurations: Configurations ``q``, shape (n, nq) (float32: they are starts only).
        features: :func:`rigid_features` of their contacts, shape (n, 6 F) (float32).
        seed: Seed the entries were drawn from.
    """

    hand: str
    hand_digest: str
    configurations: NDArray[np.float32]
    features: NDArray[np.float32]
    seed: int

    @cached_property
    def tree(self) -> cKDTree:
        """The k-d tree of the features, built on first use."""
        return cKDTree(self.features.astype(np.float64))  # float64 queries are faster

    def check_hand(self, hand: Hand) -> None:
        """Raise :class:`GraspDatabaseError` unless this database was made for ``hand``."""
        check_made_for(
            hand, "grasp database", self.hand, self.hand_digest, GraspDatabaseError,
            "build one with `sahgrasp learn --hand ...`",
        )  # fmt: skip

    def starts(self, hand: Hand, target: GraspTarget, count: int) -> Iterator[NDArray[np.float64]]:
        """The ``count`` nearest entries' configurations, each wrist moved onto ``target``.

        Lazy: a start is aligned only when the solver asks for it. Requires a target with a
        contact for every finger of the hand (else: no starts).
        """
        key = target_key(hand, target)
        if count <= 0 or key is None:
            return
        _, index = self.tree.query(key, k=min(count, len(self.features)), eps=QUERY_EPS)
        # Rows (p_i, r_i) per finger, the order of Hand.contact_stack.
        contacts = [target.contact(f) for f in hand.fingers]
        goal = np.array([row for c in contacts for row in (c.point, c.centre(hand.radius_m))])
        for i in np.atleast_1d(index).tolist():
            yield self._moved(hand, i, goal)

    def _moved(self, hand: Hand, i: int, goal: NDArray[np.float64]) -> NDArray[np.float64]:
        q = self.configurations[i].astype(np.float64)
        # The compiled tree's stack: a quarter of Hand.contact_stack's cost, equal to 1e-12.
        source = np.empty((2 * len(hand.fingers), 3))
        compiled_tree(hand).stack(q, np.arange(len(hand.fingers)), source, None)
        wrist = kabsch(source, goal) * hand.wrist_pose(q)
        hand.wrist_part(q)[:] = pin.SE3ToXYZQUAT(wrist)
        return q

    def to_bytes(self) -> bytes:
        """The ``.npz`` file content."""
        buffer = io.BytesIO()
        np.savez(
            buffer,
            format=np.array(FORMAT),
            hand=np.array(self.hand),
            hand_digest=np.array(self.hand_digest),
            seed=np.array(self.seed),
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
        try:
            with np.load(path, allow_pickle=False) as data:
                if str(data["format"]) != FORMAT:
                    raise ValueError(f"format is {str(data['format'])!r}, not {FORMAT}")
                db = cls(
                    str(data["hand"]), str(data["hand_digest"]),
                    np.asarray(data["configurations"], dtype=np.float32),
                    np.asarray(data["features"], dtype=np.float32), int(data["seed"]),
                )  # fmt: skip
        except FileNotFoundError as exc:
            raise GraspDatabaseError(f"grasp database {path} not found") from exc
        except (OSError, KeyError, ValueError, TypeError, EOFError, zipfile.BadZipFile) as exc:
            raise GraspDatabaseError(
                f"{path} is not a valid sahgrasp grasp database ({exc}); build one with "
                "`sahgrasp learn --hand ... --out FILE`"
            ) from exc
        db.validate(str(path))
        return db

    def validate(self, origin: str) -> None:
        """Raise :class:`GraspDatabaseError` on inconsistent shapes or non-finite values."""
        n = len(self.configurations)
        ok = (
            n > 0
            and self.configurations.ndim == 2
            and self.features.shape[0] == n
            and self.features.ndim == 2
            and bool(np.isfinite(self.configurations).all() and np.isfinite(self.features).all())
        )
        if not ok:
            raise GraspDatabaseError(
                f"{origin}: a grasp database needs n > 0 finite configurations (n, nq) and "
                f"features (n, 6F); got {self.configurations.shape} and {self.features.shape}"
            )


def sample_chunk(
    description: HandDescription, digest: str, seed: int, chunk: int, samples: int
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Entries of chunk ``chunk``: ``samples`` random collision-free configurations and features.

    A pure function of its arguments (seeded by ``[seed, chunk]``), so any executor may run it.
    """
    from sahgrasp.ik.batch import worker_hand  # the workers' hand cache

    hand = worker_hand(description, digest)
    rng = np.random.default_rng([seed, chunk])
    q = np.array([hand.random_configuration(rng, collision_free=True) for _ in range(samples)])
    states = [hand.contact_state(x) for x in q]
    points = np.array([s.points for s in states])
    normals = np.array([s.normals for s in states])
    return q.astype(np.float32), rigid_features(points, normals).astype(np.float32)


def build_database(
    hand: Hand,
    samples: int,
    out: str | os.PathLike[str],
    seed: int = LEARN_SEED,
    executor: Executor | None = None,
    progress: Any = None,
) -> GraspDatabase:
    """Build a database of ``samples`` entries and write it to ``out`` (atomic, resumable).

    Work is split into chunks of :data:`CHUNK_SAMPLES`; each finished chunk is saved in
    ``<out>.parts/`` and a rerun with the same arguments skips it, so an interrupted build
    resumes where it stopped. The result does not depend on the executor or on interruptions.

    Args:
        hand: The hand.
        samples: Entries (>= 1).
        out: The ``.npz`` file to write.
        seed: Seed of the entries (default :data:`LEARN_SEED`).
        executor: Where the chunks run (None: in this process).
        progress: Called with (chunks done, chunks) after each chunk.
    """
    parts = Path(f"{out}.parts")
    parts.mkdir(parents=True, exist_ok=True)
    digest = hand.description.digest()
    sizes = [min(CHUNK_SAMPLES, samples - s) for s in range(0, samples, CHUNK_SAMPLES)]
    names = [parts / f"{seed}-{i}-{n}-{digest[:16]}.npz" for i, n in enumerate(sizes)]
    todo = [i for i, name in enumerate(names) if not name.is_file()]
    args = [(hand.description, digest, seed, i, sizes[i]) for i in todo]
    results: Any = iter(())
    if args:
        results = (
            (sample_chunk(*a) for a in args)
            if executor is None
            else executor.map(sample_chunk, *zip(*args, strict=True))
        )
    done = len(names) - len(todo)
    for i, (q, features) in zip(todo, results, strict=True):
        part = GraspDatabase(hand.description.name, digest, q, features, seed)
        write_bytes_atomic(names[i], part.to_bytes())
        done += 1
        if progress is not None:
            progress(done, len(names))
    chunks = [GraspDatabase.load(name) for name in names]
    db = GraspDatabase(
        hand.description.name, digest,
        np.concatenate([c.configurations for c in chunks]),
        np.concatenate([c.features for c in chunks]), seed,
    )  # fmt: skip
    db.save(out)
    for name in names:
        name.unlink()
    parts.rmdir()
    return db


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
