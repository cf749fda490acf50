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
sequence (docs/methods/ik.md, "The learned start"). Grasp entries need the hand's reach, known for
the
SAH only. The seeds (:data:`LEARN_SEED`) are used nowhere else.
"""

from __future__ import annotations

import io
import os
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from sahgrasp.core.errors import SequenceFileError
from sahgrasp.core.fileio import write_bytes_atomic
from sahgrasp.ik._lm import rigid_key
from sahgrasp.ik.compiled import compiled_tree
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import Hand, check_made_for
from sahgrasp.model.hands import data_file, hand_entry

if TYPE_CHECKING:
    pass

__all__ = [
    "CHUNK_SAMPLES",
    "FORMAT",
    "LEARN_SEED",
    "PRIMITIVES_PER_CHUNK",
    "SETS_PER_PRIMITIVE",
    "GraspDatabase",
    "GraspDatabaseError",
    "contact_key",
    "default_database",
    "rigid_features",
    "target_key",
]

FORMAT = "sahgrasp-grasp-db-1"
"""Format tag stored in every database file."""
LEARN_SEED = 61_803_398
"""Seed of the shipped databases; no benchmark or test draws from it."""
CHUNK_SAMPLES = 2000
"""Random entries per chunk of :func:`~sahgrasp.ik.learning.build_database` (the unit of work,
checkpoint, resume)."""
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
99% of the exact two nearest (docs/methods/ik.md, "Cost")."""


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
            empty_ok: Accept a database without entries (a chunk of
                :func:`~sahgrasp.ik.learning.build_database`).
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


def default_database(hand: Hand) -> GraspDatabase | None:
    """The shipped database of ``hand``, None if none; read once per hand (``hand.cache``).

    The file is the one the hand's registry entry names (:data:`sahgrasp.model.hands.HANDS`,
    under ``sahgrasp/data/grasps``). A shipped file made for another version of the hand is not
    used (None): the learned start then falls back to the sequence.

    Raises:
        GraspDatabaseError: The shipped file is corrupt.
    """
    return hand.cache.get("default_database", lambda: _shipped_database(hand))


def _shipped_database(hand: Hand) -> GraspDatabase | None:
    entry = hand_entry(hand.description.name)
    if entry is None or entry.database is None:
        return None
    shipped = data_file(entry.database)
    if not shipped.is_file():
        return None
    with shipped.open("rb") as stream:
        db = GraspDatabase.load(io.BytesIO(stream.read()))
    return db if db.hand_digest == hand.description.digest() else None
