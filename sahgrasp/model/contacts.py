"""Contact targets: a point on the object and the object's outward unit normal there, per finger.

A fingertip of radius ``R`` satisfies a target when the contact point on the fingertip sphere equals
the target point and the sphere centre equals ``point + R * normal``. Targets are given in the
``world`` frame. A grasp gives contacts for a subset of the hand's fingers (at least two, the
thumb among them when the hand has one); the fingers without a contact are free. This module
validates targets and reads/writes the targets JSON format (``docs/how-to/file-formats.md``),
including the
object a problem grasps (:class:`ObjectSpec`, built once per source by :class:`ObjectCache`).

A mesh path inside a targets file is confined to the file's folder and below: it is resolved
(symbolic links followed) and refused when it lands elsewhere, unless the reader opts in with
``allow_outside_paths=True``. A file named by a shared targets file thus cannot make a run read,
and ``sahgrasp demo --html`` embed, any mesh the user can read.
"""

from __future__ import annotations

import difflib
import errno
import hashlib
import json
import math
import numbers
import os
import re
import reprlib
import stat
from collections import Counter, OrderedDict
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp.core.errors import InvalidTargetError
from sahgrasp.core.fileio import read_json, write_json_atomic
from sahgrasp.model.hands import DEFAULT_HAND, HANDS

__all__ = [
    "MAX_PATH_CHARS",
    "NORMAL_TOLERANCE",
    "QUATERNION_TOLERANCE",
    "ContactTarget",
    "GraspTarget",
    "InvalidProblem",
    "ObjectCache",
    "ObjectSpec",
    "TargetsFile",
    "load_targets",
    "object_spec",
    "problem_from_json",
    "problem_from_line",
    "read_problems",
    "read_targets_document",
    "save_targets",
    "targets_hand",
]

NORMAL_TOLERANCE = 1e-6
"""Largest accepted deviation of a normal's length from 1."""

QUATERNION_TOLERANCE = 1e-6
"""Largest accepted deviation of an object placement quaternion's length from 1."""

MAX_PATH_CHARS = 4096
"""Longest accepted mesh path in a targets file (Linux's PATH_MAX): a longer one is refused."""

_MESH_SUFFIXES = (".stl", ".obj", ".ply")
"""Mesh files :func:`sahgrasp.objects.load_mesh` reads (checked here without importing it)."""

_DOCUMENT_KEYS = ("hand", "object", "problems")
_PROBLEM_KEYS = ("name", "contacts", "object")
_CONTACT_KEYS = ("finger", "point", "normal")
_BOM = b"\xef\xbb\xbf"

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

    def load(self, cache: ObjectCache | None = None) -> Any:
        """Build the :class:`sahgrasp.objects.GraspObject` at its placement.

        Args:
            cache: Where an object built before for the same source (catalog name, or mesh file
                and scale) is taken from and placed, instead of being built again.

        Raises:
            InvalidTargetError: Unknown catalog name.
            MeshFileError: The mesh file cannot be read as a closed object-sized mesh.
        """
        if cache is not None:
            return cache.load(self)
        return self._build(self.placement())

    def _build(self, T_world_object: NDArray[np.float64]) -> Any:
        from sahgrasp.objects import load_mesh, load_object

        if self.mesh is None:
            assert self.name is not None
            return load_object(self.name, T_world_object)
        return load_mesh(self.mesh, scale=self.scale, T_world_object=T_world_object)

    def _source(self) -> tuple[Any, ...]:
        """What the built object depends on besides its placement (a mesh file's identity too).

        Raises:
            OSError: The mesh file cannot be looked at.
        """
        if self.mesh is None:
            return ("name", self.name)
        info = os.stat(self.mesh)
        return ("mesh", self.mesh, self.scale, info.st_ino, info.st_size, info.st_mtime_ns)


class ObjectCache:
    """The objects of targets-file specs, built once per source and placed as each spec says.

    An object is kept by what it is (a catalog name, or a mesh file -- its path, size and
    modification time -- with its scale), not by where it is: a spec with another placement
    gets the same solids, whose collision pieces are built once, at its own transform
    (:meth:`sahgrasp.objects.GraspObject.placed`). A mesh of 20,000 triangles takes seconds and
    hundreds of megabytes to build; nine placements of it are one build.

    Args:
        size: Most objects kept; the least recently used is dropped first.

    Raises:
        InvalidTargetError: ``size`` is not a positive integer.
    """

    def __init__(self, size: int = 8) -> None:
        if isinstance(size, bool) or not isinstance(size, int) or size < 1:
            raise InvalidTargetError(f"ObjectCache size must be an integer >= 1, got {size!r}")
        self.size = size
        self._built: OrderedDict[tuple[Any, ...], Any] = OrderedDict()

    def __len__(self) -> int:
        return len(self._built)

    def load(self, spec: ObjectSpec) -> Any:
        """The object of ``spec`` at its placement, built unless an object of its source is kept.

        Raises:
            InvalidTargetError: Unknown catalog name.
            MeshFileError: The mesh file cannot be read as a closed object-sized mesh.
        """
        try:
            source = spec._source()
        except OSError:  # the loader names what is wrong with the file
            return spec.load()
        built = self._built.pop(source, None)
        if built is None:
            built = spec._build(np.eye(4))
        self._built[source] = built
        while len(self._built) > self.size:
            self._built.popitem(last=False)
        return built.placed(spec.placement())


_OBJECT_KEYS = ("name", "mesh", "scale", "xyz", "quat")


def object_spec(
    data: Any, folder: str | os.PathLike[str], *, allow_outside_paths: bool = False
) -> ObjectSpec | None:
    """Parse a targets file's ``object`` (docs/how-to/file-formats.md); ``null`` means no object.

    Args:
        data: The JSON value.
        folder: The targets file's folder: a relative ``mesh`` path is relative to it.
        allow_outside_paths: Accept a ``mesh`` that resolves outside ``folder`` (an absolute
            path, ``..``, a symbolic link leading out); by default it is refused.

    Raises:
        InvalidTargetError: Not an object with exactly one of ``name`` (a catalog object) and
            ``mesh`` (an existing STL, OBJ or PLY file, inside ``folder`` unless allowed), an
            unknown key, ``scale`` not a finite number > 0 or given with ``name``, or ``xyz`` /
            ``quat`` not 3 / 4 finite numbers, the quaternion not of unit length (to 1e-6).
    """
    if data is None:
        return None
    if not isinstance(data, dict) or len({"name", "mesh"} & data.keys()) != 1:
        raise InvalidTargetError(
            f"'object' must be an object with either 'name' (a catalog object) or 'mesh' (a mesh "
            f"file), and optional 'xyz' [m] and 'quat' [x, y, z, w], got {_preview(data)}"
        )
    _check_keys(data, _OBJECT_KEYS, lambda: "'object'")
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
        if "scale" in data:
            raise InvalidTargetError(
                "object 'scale' is the unit of a mesh file; a catalog object ('name') is in "
                "metres already: remove 'scale'"
            )
        return ObjectSpec(name=_catalog_name(data["name"]), mesh=None, **placed)
    path = _mesh_path(data["mesh"], Path(folder), allow_outside_paths)
    return ObjectSpec(name=None, mesh=path, scale=_scale(data.get("scale", 1.0)), **placed)


def _scale(value: Any) -> float:
    if not _is_number(value):
        raise InvalidTargetError(
            f"object 'scale' must be a number, the mesh file's unit in metres (0.001 for "
            f"millimetres), got {_preview(value)}"
        )
    try:
        scale = float(value)
    except OverflowError:
        scale = math.inf
    if not (math.isfinite(scale) and scale > 0):
        raise InvalidTargetError(
            f"object 'scale' must be a finite number > 0, the mesh file's unit in metres (0.001 "
            f"for millimetres), got {_preview(value)}"
        )
    return scale


def _catalog_name(name: Any) -> str:
    from sahgrasp.objects.catalog import OBJECT_NAMES  # heavy: only when a file names an object

    if not isinstance(name, str) or name not in OBJECT_NAMES:
        raise InvalidTargetError(
            f"unknown object {_preview(name)}; valid names are {list(OBJECT_NAMES)}"
        )
    return name


_OUTSIDE_REMEDY = (
    "mesh paths in a targets file are confined to its folder and below (absolute paths, '..' and "
    "symbolic links leading out are refused): move the mesh there, or allow other paths with "
    "--allow-any-mesh-path (API: allow_outside_paths=True)"
)


def _mesh_path(mesh: Any, folder: Path, allow_outside: bool) -> str:
    """The resolved path of a targets file's ``mesh`` (module docstring), or the reason not."""
    if not isinstance(mesh, str) or not mesh:
        raise InvalidTargetError(f"object 'mesh' must be a file path, got {_preview(mesh)}")
    shown = _preview(_clean_name(mesh))
    if "\0" in mesh:
        raise InvalidTargetError(f"object mesh {shown} holds a NUL byte; no file path does")
    if len(mesh) > MAX_PATH_CHARS:
        raise InvalidTargetError(
            f"object mesh path is {len(mesh)} characters long ({shown}); a path has at most "
            f"{MAX_PATH_CHARS}"
        )
    if os.path.splitext(mesh)[1].lower() not in _MESH_SUFFIXES:
        raise InvalidTargetError(
            f"object mesh {shown}: unsupported type; use one of {list(_MESH_SUFFIXES)}"
        )
    # Strings and os.path rather than pathlib: a file of a million problems resolves a path each.
    looked_for = os.path.join(folder, mesh)
    try:
        resolved = os.path.realpath(looked_for, strict=True)
        info = os.stat(resolved)
        base = os.path.realpath(folder)
    except OSError as exc:
        raise InvalidTargetError(_unreachable(shown, looked_for, exc)) from None
    except ValueError:  # a lone surrogate: not encodable as a file name
        raise InvalidTargetError(f"object mesh {shown} is not a valid file name") from None
    if not allow_outside and not resolved.startswith(base.rstrip(os.sep) + os.sep):
        raise InvalidTargetError(
            f"object mesh {shown} resolves to {_preview(resolved)}, outside the targets file's "
            f"folder {_preview(base)}; {_OUTSIDE_REMEDY}"
        )
    if not stat.S_ISREG(info.st_mode):
        raise InvalidTargetError(
            f"object mesh {shown} is not a regular file (a folder, pipe or device); give a mesh "
            "file"
        )
    if os.path.splitext(resolved)[1].lower() not in _MESH_SUFFIXES:
        raise InvalidTargetError(
            f"object mesh {shown} is a link to {_preview(resolved)}, of unsupported type; "
            f"use one of {list(_MESH_SUFFIXES)}"
        )
    return resolved


def _unreachable(shown: str, looked_for: str, exc: OSError) -> str:
    """Why the mesh path ``shown`` cannot be resolved, in one line."""
    if exc.errno == errno.ELOOP:
        return f"object mesh {shown} is a loop of symbolic links; give the file itself"
    if exc.errno in (errno.ENOENT, errno.ENOTDIR):
        return f"object mesh {shown} not found (looked for {_preview(looked_for)})"
    if exc.errno == errno.ENAMETOOLONG:
        return f"object mesh {shown}: a name in the path is too long for the file system"
    return f"object mesh {shown} cannot be read: {exc.strerror or exc}"


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
        name = _clean_name(str(name))
        contacts_t = tuple(contacts)
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
        """Build from the JSON form (docs/how-to/file-formats.md), or raise InvalidTargetError.

        Args:
            data: The JSON value.
            folder: Folder a relative object ``mesh`` path is relative to (and confined to).
            default: The object of a problem without an ``object`` key.
            allow_outside_paths: Accept an object ``mesh`` outside ``folder`` (see
                :func:`object_spec`).
        """
        if not isinstance(data, dict) or "contacts" not in data:
            raise InvalidTargetError(
                f"a problem must be an object with 'name' and 'contacts', got {_preview(data)}"
            )
        name = data.get("name", "unnamed")
        if not isinstance(name, str):
            raise InvalidTargetError(f"a problem's 'name' must be a string, got {_preview(name)}")
        _check_keys(data, _PROBLEM_KEYS, lambda: f"problem {_clean_name(name)!r}")
        raw = data["contacts"]
        if not isinstance(raw, list):
            raise InvalidTargetError(f"problem {_clean_name(name)!r}: 'contacts' must be a list")
        contacts = [_contact_from_dict(item, name) for item in raw]
        spec = (
            object_spec(data["object"], folder, allow_outside_paths=allow_outside_paths)
            if "object" in data
            else default
        )
        return cls(name, contacts, spec)


def _contact_from_dict(item: Any, problem: str) -> ContactTarget:
    if not isinstance(item, dict) or not {"finger", "point", "normal"} <= item.keys():
        raise InvalidTargetError(
            f"problem {_clean_name(problem)!r}: each contact needs 'finger', 'point' and 'normal', "
            f"got {_preview(item)}"
        )
    _check_keys(item, _CONTACT_KEYS, lambda: f"problem {_clean_name(problem)!r}: a contact")
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
    raw: Any,
    index: int,
    folder: str | os.PathLike[str] = ".",
    default: ObjectSpec | None = None,
    *,
    allow_outside_paths: bool = False,
) -> GraspTarget | InvalidProblem:
    """One problem of a targets file, or an :class:`InvalidProblem` with the reason.

    Args:
        raw: The problem's JSON value.
        index: Its index in the file (from 0): a problem without a name is ``problem-<index>``.
        folder: The targets file's folder (relative mesh paths, confined to it).
        default: The file's default object.
        allow_outside_paths: Accept a mesh outside ``folder`` (see :func:`object_spec`).
    """
    if isinstance(raw, dict) and "name" not in raw:
        raw = {**raw, "name": f"problem-{index}"}
    try:
        return GraspTarget.from_dict(raw, folder, default, allow_outside_paths=allow_outside_paths)
    except InvalidTargetError as exc:
        name = raw.get("name") if isinstance(raw, dict) else None
        shown = _clean_name(name) if isinstance(name, str) else f"problem-{index}"
        return InvalidProblem(shown, str(exc))


def problem_from_line(
    line: bytes,
    index: int,
    folder: str | os.PathLike[str] = ".",
    default: ObjectSpec | None = None,
    *,
    allow_outside_paths: bool = False,
) -> GraspTarget | InvalidProblem:
    """One problem line of a JSON Lines targets file (without its newline), or why it is invalid.

    A UTF-8 byte-order mark at the start of the line (an editor's, at the start of the file)
    is skipped, as :func:`sahgrasp.core.fileio.read_json` skips it at the start of a document.

    Args:
        line: The line's bytes.
        index: The problem's index (from 0): a problem without a name is ``problem-<index>``.
        folder: The targets file's folder (relative mesh paths, confined to it).
        default: The file's default object (from its header line).
        allow_outside_paths: Accept a mesh outside ``folder`` (see :func:`object_spec`).
    """
    if line.startswith(_BOM):
        line = line[len(_BOM) :]
    name = f"problem-{index}"
    try:
        raw = json.loads(line.decode("utf-8"))
    except UnicodeDecodeError:
        return InvalidProblem(name, "line is not UTF-8 text")
    except (ValueError, RecursionError) as exc:
        return InvalidProblem(name, f"line is not a JSON value ({type(exc).__name__}: {exc})")
    return problem_from_json(raw, index, folder, default, allow_outside_paths=allow_outside_paths)


def read_targets_document(
    path: str | os.PathLike[str], *, allow_outside_paths: bool = False
) -> tuple[str, ObjectSpec | None, list[GraspTarget | InvalidProblem]]:
    """Read a targets file; a problem that fails validation is kept as an :class:`InvalidProblem`.

    A problem without a name is called ``problem-<index>`` (from 0, in file order). A relative
    hand-description path in the file (a ``hand`` with a suffix, such as
    ``hands/my_hand.json``) is resolved against the targets file's folder. A UTF-8 byte-order
    mark before the document is skipped.

    Args:
        path: The targets file.
        allow_outside_paths: Accept object meshes outside the file's folder (an absolute path,
            ``..``, a link leading out); by default such a problem is invalid.

    Returns:
        The hand (a registered hand's name or a description path), the file's default object
        (None: none) and the problems in file order.

    Raises:
        InvalidTargetError: The file is missing, a folder, not UTF-8 JSON, nested too deeply,
            not an object with a string ``hand`` and a ``problems`` list, has a key besides
            ``hand``, ``object`` and ``problems``, or its default ``object`` is invalid.
    """
    path = Path(path)
    data = read_json(path, "targets file", InvalidTargetError)
    if not isinstance(data, dict) or not isinstance(data.get("problems"), list):
        raise InvalidTargetError(
            f"targets file {path} must be an object with 'hand' and a 'problems' list"
        )
    _check_keys(data, _DOCUMENT_KEYS, lambda: f"targets file {path}")
    hand = targets_hand(data, path)
    folder = path.parent
    default = object_spec(data.get("object"), folder, allow_outside_paths=allow_outside_paths)
    return (
        hand,
        default,
        [
            problem_from_json(raw, i, folder, default, allow_outside_paths=allow_outside_paths)
            for i, raw in enumerate(data["problems"])
        ],
    )


def read_problems(
    path: str | os.PathLike[str], *, allow_outside_paths: bool = False
) -> tuple[str, list[GraspTarget | InvalidProblem]]:
    """Read a targets file: its hand and its problems, as :func:`read_targets_document` does.

    Raises:
        InvalidTargetError: As :func:`read_targets_document`.
    """
    hand, _, problems = read_targets_document(path, allow_outside_paths=allow_outside_paths)
    return hand, problems


def targets_hand(data: dict[str, Any], path: Path) -> str:
    """A targets file's ``hand``, a relative description path resolved against its folder.

    Raises:
        InvalidTargetError: ``hand`` is not a non-empty string.
    """
    hand = data.get("hand", DEFAULT_HAND)
    if not isinstance(hand, str) or not hand:
        raise InvalidTargetError(
            f"targets file {path}: 'hand' must be one of {', '.join(map(repr, HANDS))} or a "
            "hand-description path, "
            f"got {_preview(hand)}"
        )
    if Path(hand).suffix and not Path(hand).is_absolute():
        hand = str(path.parent / hand)
    return hand


def load_targets(path: str | os.PathLike[str], *, allow_outside_paths: bool = False) -> TargetsFile:
    """Read a targets file (``docs/how-to/file-formats.md``, "Targets"), every problem valid.

    Args:
        path: The targets file.
        allow_outside_paths: Accept object meshes outside the file's folder (see
            :func:`read_targets_document`).

    Raises:
        InvalidTargetError: The file cannot be read (see :func:`read_targets_document`) or holds
            an invalid problem.
    """
    hand, problems = read_problems(path, allow_outside_paths=allow_outside_paths)
    valid = []
    for problem in problems:
        if isinstance(problem, InvalidProblem):
            raise InvalidTargetError(f"targets file {path}: {problem.detail}")
        valid.append(problem)
    return TargetsFile(hand=hand, problems=tuple(valid))


def save_targets(path: str | os.PathLike[str], hand: str, problems: Iterable[GraspTarget]) -> None:
    """Write a targets file atomically.

    A mesh inside the file's folder (or below) is written relative to it, so that the file
    reads back (and can be moved with its meshes); one elsewhere keeps its absolute path, which
    only a reader allowing outside paths accepts.
    """
    folder = Path(path).parent
    entries = []
    for problem in problems:
        entry = problem.to_dict()
        if problem.object_spec is not None:
            entry["object"] = problem.object_spec.to_dict(relative_to=folder)
        entries.append(entry)
    write_json_atomic(path, {"hand": hand, "problems": entries})
