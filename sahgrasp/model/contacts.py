"""Contact targets: a point on the object and the object's outward unit normal there, per finger.

A fingertip of radius ``R`` satisfies a target when the contact point on the fingertip sphere equals
the target point and the sphere centre equals ``point + R * normal``. Targets are given in the
``world`` frame. A grasp gives contacts for a subset of the hand's fingers (at least two, the
thumb among them when the hand has one); the fingers without a contact are free. This module
validates targets and writes their JSON form (``docs/how-to/file-formats.md``), including the
object a problem grasps as a plain description (:class:`ObjectSpec`: a catalog name or a mesh file,
placed). Reading targets files, checking an object's catalog name and mesh path, and building the
object belong to :mod:`sahgrasp.objects.targets`, which knows the objects; this module imports
nothing of :mod:`sahgrasp.objects`.
"""

from __future__ import annotations

import difflib
import hashlib
import json
import math
import numbers
import os
import re
import reprlib
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp import _moved
from sahgrasp.core.errors import InvalidTargetError

__all__ = [
    "NORMAL_TOLERANCE",
    "ContactTarget",
    "GraspTarget",
    "ObjectSpec",
]

NORMAL_TOLERANCE = 1e-6
"""Largest accepted deviation of a normal's length from 1."""

_SURROGATE = re.compile("[\ud800-\udfff]")
_PREVIEW = reprlib.Repr()
_PREVIEW.maxlevel, _PREVIEW.maxstring, _PREVIEW.maxother = 3, 60, 60


def _preview(value: Any) -> str:
    """A short repr of user data for a message, whatever its size or depth."""
    return _PREVIEW.repr(value)


def _clean_name(name: str) -> str:
    """``name`` with each lone surrogate (JSON allows them, UTF-8 does not) replaced by U+FFFD."""
    return _SURROGATE.sub("\ufffd", name)


def _check_keys(data: dict[Any, Any], valid: Sequence[str], where: Callable[[], str]) -> None:
    """Raise naming each key of ``data`` not in ``valid`` (and the nearest valid key), if any.

    A misspelt key (``"Object"``, ``"objcet"``) must not be ignored: the problem would be solved
    without what it names. ``where`` names the place for the message, built only then.
    """
    if data.keys() <= frozenset(valid):  # the usual case, at C speed
        return
    unknown = [key for key in data if key not in valid]
    hints = []
    for key in map(str, unknown):
        near = difflib.get_close_matches(key.lower(), valid, n=1, cutoff=0.6)
        hints.append(f"{_preview(key)} (did you mean {near[0]!r}?)" if near else _preview(key))
    raise InvalidTargetError(
        f"{where()} has unknown key(s) {', '.join(hints)}; valid keys: {list(valid)}"
    )


def _is_number(value: Any) -> bool:
    kind = type(value)
    if kind is float or kind is int:  # what JSON gives: no ABC check (a tenth of parsing a problem)
        return True
    return isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)


def _vector3(value: ArrayLike, what: str, size: int = 3, unit: str = " [m]") -> NDArray[np.float64]:
    items = np.asarray(value).reshape(-1).tolist() if isinstance(value, np.ndarray) else value
    if not isinstance(items, list | tuple) or not all(map(_is_number, items)):
        raise InvalidTargetError(f"{what} must be {size} numbers{unit}, got {_preview(value)}")
    if len(items) != size:
        raise InvalidTargetError(f"{what} must have {size} components{unit}, got {len(items)}")
    try:
        finite = all(map(math.isfinite, items))
    except OverflowError:
        raise InvalidTargetError(
            f"{what} holds a number too large for a float: {_preview(items)}; all must be finite"
        ) from None
    if not finite:
        raise InvalidTargetError(
            f"{what} holds NaN or inf: {[float(v) for v in items]}; all must be finite"
        )
    vec = np.array(items, dtype=np.float64)
    vec.setflags(write=False)
    return vec


@dataclass(frozen=True)
class ContactTarget:
    """One finger's contact: object surface point and outward unit surface normal, in ``world``.

    Attributes:
        finger: Finger name, e.g. ``"thumb"``.
        point: Contact point on the object [m], shape (3,).
        normal: Outward unit normal of the object at ``point``, shape (3,).
    """

    finger: str
    point: NDArray[np.float64]
    normal: NDArray[np.float64]

    def __init__(self, finger: str, point: ArrayLike, normal: ArrayLike) -> None:
        if not isinstance(finger, str) or not finger:
            raise InvalidTargetError(f"finger must be a non-empty name, got {_preview(finger)}")
        point_v = _vector3(point, f"{finger!r} contact point")
        normal_v = _vector3(normal, f"{finger!r} contact normal")
        norm = math.hypot(*normal_v.tolist())
        if abs(norm - 1.0) > NORMAL_TOLERANCE:
            raise InvalidTargetError(
                f"{finger!r} contact normal has length {norm:.9g}; it must be a unit vector "
                f"(tolerance {NORMAL_TOLERANCE:g}), normals are not normalised silently"
            )
        object.__setattr__(self, "finger", finger)
        object.__setattr__(self, "point", point_v)
        object.__setattr__(self, "normal", normal_v)

    def __reduce__(self) -> tuple[Any, ...]:
        # Six floats pickle several times faster than two small arrays: the chunks of a batch
        # cross to the workers pickled, and the parent's pickling competes with their solving.
        return (ContactTarget, (self.finger, self.point.tolist(), self.normal.tolist()))

    def centre(self, radius_m: float) -> NDArray[np.float64]:
        """Return the fingertip-sphere centre ``r* = p* + R n*`` [m] that satisfies this contact."""
        return self.point + radius_m * self.normal

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form of ``docs/how-to/file-formats.md``."""
        return {"finger": self.finger, "point": self.point.tolist(), "normal": self.normal.tolist()}

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ContactTarget):
            return NotImplemented
        return (
            self.finger == other.finger
            and np.array_equal(self.point, other.point)
            and np.array_equal(self.normal, other.normal)
        )

    def __hash__(self) -> int:
        return hash((self.finger, self.point.tobytes(), self.normal.tobytes()))


@dataclass(frozen=True)
class ObjectSpec:
    """The object a problem of a targets file grasps: a catalog object or a mesh file, placed.

    Attributes:
        name: Catalog object name (:data:`sahgrasp.objects.OBJECT_NAMES`), or None for a mesh.
        mesh: Absolute path of the mesh file (STL, OBJ, PLY), or None.
        xyz: Position of the object frame in the world [m].
        quat: Orientation of the object frame in the world, unit quaternion ``[x, y, z, w]``.
        scale: The mesh file's unit in metres (``0.001`` for a file in millimetres); 1 for a
            catalog object.
    """

    name: str | None
    mesh: str | None
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quat: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    scale: float = 1.0

    def __str__(self) -> str:
        if self.mesh is None:
            return repr(self.name)
        return f"mesh {self.mesh}" + (f" (scale {self.scale:g})" if self.scale != 1.0 else "")

    def key(self) -> str:
        """A string equal for equal specs (SHA-256 of the JSON form)."""
        text = json.dumps(self.to_dict(), sort_keys=True)
        return hashlib.sha256(text.encode("utf-8")).hexdigest()

    def to_dict(self, relative_to: str | os.PathLike[str] | None = None) -> dict[str, Any]:
        """Return the JSON form of ``docs/how-to/file-formats.md``.

        Args:
            relative_to: The folder of the file the form goes into: a mesh in it (or below) is
                written relative to it, so that the file reads back without allowing outside
                paths. Otherwise, and by default, the mesh path is absolute.
        """
        mesh = self.mesh
        if mesh is not None and relative_to is not None:
            base = os.path.realpath(relative_to).rstrip(os.sep) + os.sep
            if mesh.startswith(base):
                mesh = Path(mesh).relative_to(base).as_posix()
        source: dict[str, Any] = {"name": self.name} if mesh is None else {"mesh": mesh}
        if self.mesh is not None and self.scale != 1.0:
            source["scale"] = self.scale
        return {**source, "xyz": list(self.xyz), "quat": list(self.quat)}

    def placement(self) -> NDArray[np.float64]:
        """The object's placement in the world, a 4x4 matrix."""
        x, y, z, w = np.array(self.quat) / np.linalg.norm(self.quat)
        T = np.eye(4)
        T[:3, :3] = [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
        T[:3, 3] = self.xyz
        return T

    def load(self, cache: Any = None) -> Any:
        """Build the object at its placement (deprecated: :func:`sahgrasp.objects.build_object`).

        Raises:
            InvalidTargetError: Unknown catalog name.
            MeshFileError: The mesh file cannot be read as a closed object-sized mesh.
        """
        return _moved.moved_attribute(__name__, "ObjectSpec.load")(self, cache)


@dataclass(frozen=True)
class GraspTarget:
    """A precision grasp to reach: one :class:`ContactTarget` per finger, fingers all distinct.

    The contacts may be for a subset of the hand's fingers: at least two, the thumb among them
    when the hand has one (:meth:`check_fingers`). The others are free: the IK places them clear
    of the object and of the hand (:func:`sahgrasp.ik.solve_ik`).

    Attributes:
        name: Problem name (e.g. the object).
        contacts: The contacts, one per finger that touches the object.
        object_spec: The object grasped, as a targets file names it (None: no object).
    """

    name: str
    contacts: tuple[ContactTarget, ...]
    object_spec: ObjectSpec | None = None

    def __init__(
        self, name: str, contacts: Iterable[ContactTarget], object_spec: ObjectSpec | None = None
    ) -> None:
        if not isinstance(name, str):
            raise InvalidTargetError(
                f"a grasp's name must be a string, got {type(name).__name__}: "
                "GraspTarget(name, contacts[, object_spec])"
            )
        name = _clean_name(name)
        if isinstance(contacts, str | bytes) or not isinstance(contacts, Iterable):
            raise InvalidTargetError(
                f"grasp {name!r}: contacts must be an iterable of ContactTarget, "
                f"got {type(contacts).__name__}"
            )
        contacts_t = tuple(contacts)
        wrong = sorted({type(c).__name__ for c in contacts_t if not isinstance(c, ContactTarget)})
        if wrong:
            raise InvalidTargetError(
                f"grasp {name!r}: every contact must be a ContactTarget, got {wrong}"
            )
        if not contacts_t:
            raise InvalidTargetError(
                f"grasp {name!r} has no contacts; give one for each finger that touches the object"
            )
        repeated = sorted(f for f, n in Counter(c.finger for c in contacts_t).items() if n > 1)
        if repeated:
            raise InvalidTargetError(
                f"grasp {name!r} names finger(s) {repeated} more than once; each finger once"
            )
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "contacts", contacts_t)
        object.__setattr__(self, "object_spec", object_spec)

    @property
    def fingers(self) -> tuple[str, ...]:
        """Finger names in the order the contacts were given."""
        return tuple(c.finger for c in self.contacts)

    def contact(self, finger: str) -> ContactTarget:
        """Return the contact of ``finger``."""
        for c in self.contacts:
            if c.finger == finger:
                return c
        raise InvalidTargetError(
            f"grasp {self.name!r} has no contact for finger {finger!r}; it has {list(self.fingers)}"
        )

    def check_fingers(self, valid: Sequence[str]) -> None:
        """Raise unless the contacts are for fingers of a hand with the ``valid`` fingers.

        Every contact's finger must be one of ``valid``; at least two fingers need a contact,
        the thumb among them when ``valid`` has a ``thumb`` (the IK hangs the hand from it).
        The fingers without a contact are free (:meth:`free_fingers`).

        Raises:
            InvalidTargetError: An unknown finger, fewer than two contacts, or no thumb contact.
        """
        fingers = self.fingers
        unknown = [f for f in fingers if f not in valid]
        if unknown:
            raise InvalidTargetError(
                f"grasp {self.name!r}: unknown finger(s) {unknown}; valid fingers are {list(valid)}"
            )
        if len(fingers) < 2:
            raise InvalidTargetError(
                f"grasp {self.name!r} has a contact for {list(fingers)} only; a grasp needs "
                f"contacts for at least two of {list(valid)} (the others are left free)"
            )
        if "thumb" in valid and "thumb" not in fingers:
            raise InvalidTargetError(
                f"grasp {self.name!r}: missing contact for the thumb; a grasp gives contacts for "
                f"the thumb and at least one other finger of {list(valid)} (the others are free)"
            )

    def free_fingers(self, valid: Sequence[str]) -> tuple[str, ...]:
        """The fingers of ``valid`` (a hand's, in its order) without a contact: left free."""
        return tuple(f for f in valid if f not in self.fingers)

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form of ``docs/how-to/file-formats.md``."""
        data: dict[str, Any] = {"name": self.name, "contacts": [c.to_dict() for c in self.contacts]}
        if self.object_spec is not None:
            data["object"] = self.object_spec.to_dict()
        return data

    @classmethod
    def from_dict(
        cls,
        data: Any,
        folder: str | os.PathLike[str] = ".",
        default: ObjectSpec | None = None,
        *,
        allow_outside_paths: bool = False,
    ) -> GraspTarget:
        """Build from the JSON form (deprecated: :func:`sahgrasp.objects.problem_from_dict`).

        Raises:
            InvalidTargetError: As :func:`sahgrasp.objects.problem_from_dict`.
        """
        read = _moved.moved_attribute(__name__, "GraspTarget.from_dict")
        target: GraspTarget = read(data, folder, default, allow_outside_paths=allow_outside_paths)
        return target


def __getattr__(name: str) -> Any:
    # The names that moved to sahgrasp.objects.targets, for one release (sahgrasp._moved).
    return _moved.moved_attribute(__name__, name)
