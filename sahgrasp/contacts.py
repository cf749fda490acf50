"""Contact targets: a point on the object and the object's outward unit normal there, per finger.

A fingertip of radius ``R`` satisfies a target when the contact point on the fingertip sphere equals
the target point and the sphere centre equals ``point + R * normal``. Targets are given in the
``world`` frame. This module validates them and reads/writes the targets JSON format
(``docs/formats.md``), including the object a problem grasps (:class:`ObjectSpec`).
"""

from __future__ import annotations

import hashlib
import json
import math
import numbers
import os
import re
import reprlib
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp.errors import InvalidTargetError
from sahgrasp.fileio import read_json, write_json_atomic

__all__ = [
    "NORMAL_TOLERANCE",
    "QUATERNION_TOLERANCE",
    "ContactTarget",
    "GraspTarget",
    "InvalidProblem",
    "ObjectSpec",
    "TargetsFile",
    "load_targets",
    "object_spec",
    "problem_from_json",
    "read_problems",
    "save_targets",
    "targets_hand",
]

NORMAL_TOLERANCE = 1e-6
"""Largest accepted deviation of a normal's length from 1."""

QUATERNION_TOLERANCE = 1e-6
"""Largest accepted deviation of an object placement quaternion's length from 1."""

_MESH_SUFFIXES = (".stl", ".obj", ".ply")
"""Mesh files :func:`sahgrasp.objects.load_mesh` reads (checked here without importing it)."""

_SURROGATE = re.compile("[\ud800-\udfff]")
_PREVIEW = reprlib.Repr()
_PREVIEW.maxlevel, _PREVIEW.maxstring, _PREVIEW.maxother = 3, 60, 60


def _preview(value: Any) -> str:
    """A short repr of user data for a message, whatever its size or depth."""
    return _PREVIEW.repr(value)


def _clean_name(name: str) -> str:
    """``name`` with each lone surrogate (JSON allows them, UTF-8 does not) replaced by U+FFFD."""
    return _SURROGATE.sub("\ufffd", name)


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
        """Return the JSON form of ``docs/formats.md``."""
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
        mesh: Absolute path of the mesh file (STL, OBJ, PLY; coordinates in metres), or None.
        xyz: Position of the object frame in the world [m].
        quat: Orientation of the object frame in the world, unit quaternion ``[x, y, z, w]``.
    """

    name: str | None
    mesh: str | None
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quat: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)

    def __str__(self) -> str:
        return repr(self.name) if self.mesh is None else f"mesh {self.mesh}"

    def key(self) -> str:
        """A string equal for equal specs (SHA-256 of the JSON form)."""
        text = json.dumps(self.to_dict(), sort_keys=True)
        return hashlib.sha256(text.encode("utf-8")).hexdigest()

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form of ``docs/formats.md`` (the mesh path absolute)."""
        source = {"name": self.name} if self.mesh is None else {"mesh": self.mesh}
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

    def load(self) -> Any:
        """Build the :class:`sahgrasp.objects.GraspObject` at its placement.

        Raises:
            InvalidTargetError: Unknown catalog name.
            MeshFileError: The mesh file cannot be read as a closed object-sized mesh.
        """
        from sahgrasp.objects import load_mesh, load_object

        if self.mesh is None:
            assert self.name is not None
            return load_object(self.name, self.placement())
        return load_mesh(self.mesh, T_world_object=self.placement())


_OBJECT_KEYS = ("name", "mesh", "xyz", "quat")


def object_spec(data: Any, folder: str | os.PathLike[str]) -> ObjectSpec | None:
    """Parse a targets file's ``object`` (``docs/formats.md``); ``null`` means no object.

    Args:
        data: The JSON value.
        folder: The targets file's folder: a relative ``mesh`` path is relative to it.

    Raises:
        InvalidTargetError: Not an object with exactly one of ``name`` (a catalog object) and
            ``mesh`` (an existing STL, OBJ or PLY file), an unknown key, or ``xyz`` / ``quat``
            not 3 / 4 finite numbers, the quaternion not of unit length (to 1e-6).
    """
    if data is None:
        return None
    if not isinstance(data, dict) or len({"name", "mesh"} & data.keys()) != 1:
        raise InvalidTargetError(
            f"'object' must be an object with either 'name' (a catalog object) or 'mesh' (a mesh "
            f"file), and optional 'xyz' [m] and 'quat' [x, y, z, w], got {_preview(data)}"
        )
    unknown = sorted(str(k) for k in data.keys() - set(_OBJECT_KEYS))
    if unknown:
        raise InvalidTargetError(
            f"'object' has unknown key(s) {unknown}; valid: {list(_OBJECT_KEYS)}"
        )
    xyz = _vector3(data.get("xyz", [0.0, 0.0, 0.0]), "object 'xyz'")
    quat = _vector3(data.get("quat", [0.0, 0.0, 0.0, 1.0]), "object 'quat'", 4, " [x, y, z, w]")
    norm = float(np.linalg.norm(quat))
    if abs(norm - 1.0) > QUATERNION_TOLERANCE:
        raise InvalidTargetError(
            f"object 'quat' has length {norm:.9g}; it must be a unit quaternion [x, y, z, w] "
            f"(tolerance {QUATERNION_TOLERANCE:g})"
        )
    placed: dict[str, Any] = {"xyz": tuple(xyz.tolist()), "quat": tuple(quat.tolist())}
    if "name" in data:
        return ObjectSpec(name=_catalog_name(data["name"]), mesh=None, **placed)
    return ObjectSpec(name=None, mesh=_mesh_path(data["mesh"], Path(folder)), **placed)


def _catalog_name(name: Any) -> str:
    from sahgrasp.objects.catalog import OBJECT_NAMES  # heavy: only when a file names an object

    if not isinstance(name, str) or name not in OBJECT_NAMES:
        raise InvalidTargetError(
            f"unknown object {_preview(name)}; valid names are {list(OBJECT_NAMES)}"
        )
    return name


def _mesh_path(mesh: Any, folder: Path) -> str:
    if not isinstance(mesh, str) or not mesh:
        raise InvalidTargetError(f"object 'mesh' must be a file path, got {_preview(mesh)}")
    path = (folder / mesh).resolve()
    if path.suffix.lower() not in _MESH_SUFFIXES:
        raise InvalidTargetError(
            f"object mesh {mesh!r}: unsupported type; use one of {list(_MESH_SUFFIXES)}"
        )
    if not path.is_file():
        raise InvalidTargetError(f"object mesh {mesh!r} not found (looked for {path})")
    return str(path)


@dataclass(frozen=True)
class GraspTarget:
    """A precision grasp to reach: one :class:`ContactTarget` per finger, fingers all distinct.

    Attributes:
        name: Problem name (e.g. the object).
        contacts: The contacts, one per finger.
        object_spec: The object grasped, as a targets file names it (None: no object).
    """

    name: str
    contacts: tuple[ContactTarget, ...]
    object_spec: ObjectSpec | None = None

    def __init__(
        self, name: str, contacts: Iterable[ContactTarget], object_spec: ObjectSpec | None = None
    ) -> None:
        name = _clean_name(str(name))
        contacts_t = tuple(contacts)
        if not contacts_t:
            raise InvalidTargetError(f"grasp {name!r} has no contacts; give one per finger")
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
        """Raise unless the grasp has exactly one contact for each of the ``valid`` fingers."""
        fingers = self.fingers
        unknown = [f for f in fingers if f not in valid]
        if unknown:
            raise InvalidTargetError(
                f"grasp {self.name!r}: unknown finger(s) {unknown}; valid fingers are {list(valid)}"
            )
        missing = [f for f in valid if f not in fingers]
        if missing:
            raise InvalidTargetError(
                f"grasp {self.name!r}: missing contact(s) for {missing}; "
                f"give one contact for each of {list(valid)}"
            )

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form of ``docs/formats.md``."""
        data: dict[str, Any] = {"name": self.name, "contacts": [c.to_dict() for c in self.contacts]}
        if self.object_spec is not None:
            data["object"] = self.object_spec.to_dict()
        return data

    @classmethod
    def from_dict(
        cls, data: Any, folder: str | os.PathLike[str] = ".", default: ObjectSpec | None = None
    ) -> GraspTarget:
        """Build from the JSON form of ``docs/formats.md``, raising :class:`InvalidTargetError`.

        Args:
            data: The JSON value.
            folder: Folder a relative object ``mesh`` path is relative to.
            default: The object of a problem without an ``object`` key.
        """
        if not isinstance(data, dict) or "contacts" not in data:
            raise InvalidTargetError(
                f"a problem must be an object with 'name' and 'contacts', got {_preview(data)}"
            )
        name = data.get("name", "unnamed")
        if not isinstance(name, str):
            raise InvalidTargetError(f"a problem's 'name' must be a string, got {_preview(name)}")
        raw = data["contacts"]
        if not isinstance(raw, list):
            raise InvalidTargetError(f"problem {_clean_name(name)!r}: 'contacts' must be a list")
        contacts = [_contact_from_dict(item, name) for item in raw]
        spec = object_spec(data["object"], folder) if "object" in data else default
        return cls(name, contacts, spec)


def _contact_from_dict(item: Any, problem: str) -> ContactTarget:
    if not isinstance(item, dict) or not {"finger", "point", "normal"} <= item.keys():
        raise InvalidTargetError(
            f"problem {_clean_name(problem)!r}: each contact needs 'finger', 'point' and 'normal', "
            f"got {_preview(item)}"
        )
    return ContactTarget(item["finger"], item["point"], item["normal"])


@dataclass(frozen=True)
class InvalidProblem:
    """A problem of a targets file that failed validation: nothing to solve, only the reason.

    Attributes:
        name: The problem's name, or ``problem-<index>`` when it has none.
        detail: Why it is invalid (the :class:`InvalidTargetError` message).
    """

    name: str
    detail: str


@dataclass(frozen=True)
class TargetsFile:
    """Contents of a targets JSON file: the hand name (or description path) and the problems."""

    hand: str
    problems: tuple[GraspTarget, ...] = field(default_factory=tuple)


def problem_from_json(
    raw: Any, index: int, folder: str | os.PathLike[str] = ".", default: ObjectSpec | None = None
) -> GraspTarget | InvalidProblem:
    """One problem of a targets file, or an :class:`InvalidProblem` with the reason.

    Args:
        raw: The problem's JSON value.
        index: Its index in the file (from 0): a problem without a name is ``problem-<index>``.
        folder: The targets file's folder (relative mesh paths).
        default: The file's default object.
    """
    if isinstance(raw, dict) and "name" not in raw:
        raw = {**raw, "name": f"problem-{index}"}
    try:
        return GraspTarget.from_dict(raw, folder, default)
    except InvalidTargetError as exc:
        name = raw.get("name") if isinstance(raw, dict) else None
        shown = _clean_name(name) if isinstance(name, str) else f"problem-{index}"
        return InvalidProblem(shown, str(exc))


def read_problems(path: str | os.PathLike[str]) -> tuple[str, list[GraspTarget | InvalidProblem]]:
    """Read a targets file; a problem that fails validation is kept as an :class:`InvalidProblem`.

    A problem without a name is called ``problem-<index>`` (from 0, in file order). A relative
    hand-description path in the file (a ``hand`` with a suffix, such as
    ``hands/my_hand.json``) is resolved against the targets file's folder.

    Returns:
        The hand (``"sah"``, ``"allegro"`` or a description path) and the problems in file order.

    Raises:
        InvalidTargetError: The file is missing, a folder, not UTF-8 JSON, nested too deeply,
            not an object with a string ``hand`` and a ``problems`` list, or its default
            ``object`` is invalid.
    """
    path = Path(path)
    data = read_json(path, "targets file", InvalidTargetError)
    if not isinstance(data, dict) or not isinstance(data.get("problems"), list):
        raise InvalidTargetError(
            f"targets file {path} must be an object with 'hand' and a 'problems' list"
        )
    hand = targets_hand(data, path)
    default = object_spec(data.get("object"), path.parent)
    problems = data["problems"]
    return hand, [problem_from_json(raw, i, path.parent, default) for i, raw in enumerate(problems)]


def targets_hand(data: dict[str, Any], path: Path) -> str:
    """A targets file's ``hand``, a relative description path resolved against its folder.

    Raises:
        InvalidTargetError: ``hand`` is not a non-empty string.
    """
    hand = data.get("hand", "sah")
    if not isinstance(hand, str) or not hand:
        raise InvalidTargetError(
            f"targets file {path}: 'hand' must be 'sah', 'allegro' or a hand-description path, "
            f"got {_preview(hand)}"
        )
    if Path(hand).suffix and not Path(hand).is_absolute():
        hand = str(path.parent / hand)
    return hand


def load_targets(path: str | os.PathLike[str]) -> TargetsFile:
    """Read a targets file (``docs/formats.md``, "Targets"), every problem valid.

    Raises:
        InvalidTargetError: The file cannot be read (see :func:`read_problems`) or holds an invalid
            problem.
    """
    hand, problems = read_problems(path)
    valid = []
    for problem in problems:
        if isinstance(problem, InvalidProblem):
            raise InvalidTargetError(f"targets file {path}: {problem.detail}")
        valid.append(problem)
    return TargetsFile(hand=hand, problems=tuple(valid))


def save_targets(path: str | os.PathLike[str], hand: str, problems: Iterable[GraspTarget]) -> None:
    """Write a targets file atomically."""
    write_json_atomic(path, {"hand": hand, "problems": [p.to_dict() for p in problems]})
