"""Targets files: the document (hand, default object, problems), its objects, built and cached.

A targets file (``docs/how-to/file-formats.md``, "Targets") names a hand, an optional default
object and the problems, each a :class:`~sahgrasp.model.contacts.GraspTarget` that may name its
own object: a catalog object (:data:`sahgrasp.objects.OBJECT_NAMES`) or a mesh file, placed in
the world. This module reads and writes such files, checks the objects they name and builds them
(:func:`build_object`, once per source with :class:`ObjectCache`). It sits in
:mod:`sahgrasp.objects` because it needs both the contacts (:mod:`sahgrasp.model.contacts`) and
the objects' catalog and mesh reader, and ``objects`` already builds on ``model``.

A mesh path inside a targets file is confined to the file's folder and below: it is resolved
(symbolic links followed) and refused when it lands elsewhere, unless the reader opts in with
``allow_outside_paths=True``. A file named by a shared targets file thus cannot make a run read,
and ``sahgrasp demo --html`` embed, any mesh the user can read.
"""

from __future__ import annotations

import errno
import json
import math
import os
import stat
from collections import OrderedDict
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

# The package, whose names load on first use: the catalog is read when a file names a catalog
# object, the mesh reader (trimesh) when a file names a mesh, not when the IK imports this module.
from sahgrasp import objects
from sahgrasp.core.errors import InvalidTargetError
from sahgrasp.core.fileio import read_json, write_json_atomic
from sahgrasp.model.contacts import (
    ContactTarget,
    GraspTarget,
    ObjectSpec,
    _check_keys,
    _clean_name,
    _is_number,
    _preview,
    _vector3,
)
from sahgrasp.model.hands import DEFAULT_HAND, HANDS
from sahgrasp.objects.body import GraspObject

__all__ = [
    "MAX_PATH_CHARS",
    "QUATERNION_TOLERANCE",
    "InvalidProblem",
    "ObjectCache",
    "TargetsFile",
    "build_object",
    "load_targets",
    "object_spec",
    "problem_from_dict",
    "problem_from_json",
    "problem_from_line",
    "read_problems",
    "read_targets_document",
    "save_targets",
    "targets_hand",
]

QUATERNION_TOLERANCE = 1e-6
"""Largest accepted deviation of an object placement quaternion's length from 1."""

MAX_PATH_CHARS = 4096
"""Longest accepted mesh path in a targets file (Linux's PATH_MAX): a longer one is refused."""

_MESH_SUFFIXES = (".stl", ".obj", ".ply")
"""Mesh files :func:`sahgrasp.objects.load_mesh` reads (checked here without loading it)."""

_DOCUMENT_KEYS = ("hand", "object", "problems")
_PROBLEM_KEYS = ("name", "contacts", "object")
_CONTACT_KEYS = ("finger", "point", "normal")
_BOM = b"\xef\xbb\xbf"


def build_object(spec: ObjectSpec, cache: ObjectCache | None = None) -> GraspObject:
    """Build the object ``spec`` names at its placement.

    Args:
        spec: The object, as a targets file names it.
        cache: Where an object built before for the same source (catalog name, or mesh file
            and scale) is taken from and placed, instead of being built again.

    Raises:
        InvalidTargetError: Unknown catalog name.
        MeshFileError: The mesh file cannot be read as a closed object-sized mesh.
    """
    if cache is not None:
        return cache.load(spec)
    return _build(spec, spec.placement())


def _build(spec: ObjectSpec, T_world_object: NDArray[np.float64]) -> GraspObject:
    if spec.mesh is None:
        assert spec.name is not None
        return objects.load_object(spec.name, T_world_object)
    return objects.load_mesh(spec.mesh, scale=spec.scale, T_world_object=T_world_object)


def _source(spec: ObjectSpec) -> tuple[Any, ...]:
    """What the built object depends on besides its placement (a mesh file's identity too).

    Raises:
        OSError: The mesh file cannot be looked at.
    """
    if spec.mesh is None:
        return ("name", spec.name)
    info = os.stat(spec.mesh)
    return ("mesh", spec.mesh, spec.scale, info.st_ino, info.st_size, info.st_mtime_ns)


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
        self._built: OrderedDict[tuple[Any, ...], GraspObject] = OrderedDict()

    def __len__(self) -> int:
        return len(self._built)

    def load(self, spec: ObjectSpec) -> GraspObject:
        """The object of ``spec`` at its placement, built unless an object of its source is kept.

        Raises:
            InvalidTargetError: Unknown catalog name.
            MeshFileError: The mesh file cannot be read as a closed object-sized mesh.
        """
        try:
            source = _source(spec)
        except OSError:  # the loader names what is wrong with the file
            return _build(spec, spec.placement())
        built = self._built.pop(source, None)
        if built is None:
            built = _build(spec, np.eye(4))
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
    if not isinstance(name, str) or name not in objects.OBJECT_NAMES:
        raise InvalidTargetError(
            f"unknown object {_preview(name)}; valid names are {list(objects.OBJECT_NAMES)}"
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


def problem_from_dict(
    data: Any,
    folder: str | os.PathLike[str] = ".",
    default: ObjectSpec | None = None,
    *,
    allow_outside_paths: bool = False,
) -> GraspTarget:
    """A problem from its JSON form (docs/how-to/file-formats.md), or raise InvalidTargetError.

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
    return GraspTarget(name, contacts, spec)


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
        return problem_from_dict(raw, folder, default, allow_outside_paths=allow_outside_paths)
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
