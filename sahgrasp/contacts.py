"""Contact targets: a point on the object and the object's outward unit normal there, per finger.

A fingertip of radius ``R`` satisfies a target when the contact point on the fingertip sphere equals
the target point and the sphere centre equals ``point + R * normal``. Targets are given in the
``world`` frame. This module validates them and reads/writes the targets JSON format
(``docs/formats.md``).
"""

from __future__ import annotations

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
    "ContactTarget",
    "GraspTarget",
    "InvalidProblem",
    "TargetsFile",
    "load_targets",
    "read_problems",
    "save_targets",
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


def _is_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)


def _vector3(value: ArrayLike, what: str) -> NDArray[np.float64]:
    items = np.asarray(value).reshape(-1).tolist() if isinstance(value, np.ndarray) else value
    if not isinstance(items, list | tuple) or not all(_is_number(v) for v in items):
        raise InvalidTargetError(f"{what} must be 3 numbers [m], got {_preview(value)}")
    if len(items) != 3:
        raise InvalidTargetError(f"{what} must have 3 components [m], got {len(items)}")
    try:
        vec = np.array(items, dtype=np.float64)
    except OverflowError:
        raise InvalidTargetError(
            f"{what} holds a number too large for a float: {_preview(items)}; all must be finite"
        ) from None
    if not np.all(np.isfinite(vec)):
        raise InvalidTargetError(f"{what} holds NaN or inf: {vec.tolist()}; all must be finite")
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
        norm = float(np.linalg.norm(normal_v))
        if abs(norm - 1.0) > NORMAL_TOLERANCE:
            raise InvalidTargetError(
                f"{finger!r} contact normal has length {norm:.9g}; it must be a unit vector "
                f"(tolerance {NORMAL_TOLERANCE:g}), normals are not normalised silently"
            )
        object.__setattr__(self, "finger", finger)
        object.__setattr__(self, "point", point_v)
        object.__setattr__(self, "normal", normal_v)

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
class GraspTarget:
    """A precision grasp to reach: one :class:`ContactTarget` per finger, fingers all distinct.

    Attributes:
        name: Problem name (e.g. the object).
        contacts: The contacts, one per finger.
    """

    name: str
    contacts: tuple[ContactTarget, ...]

    def __init__(self, name: str, contacts: Iterable[ContactTarget]) -> None:
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
        unknown = [f for f in self.fingers if f not in valid]
        if unknown:
            raise InvalidTargetError(
                f"grasp {self.name!r}: unknown finger(s) {unknown}; valid fingers are {list(valid)}"
            )
        missing = [f for f in valid if f not in self.fingers]
        if missing:
            raise InvalidTargetError(
                f"grasp {self.name!r}: missing contact(s) for {missing}; "
                f"give one contact for each of {list(valid)}"
            )

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form of ``docs/formats.md``."""
        return {"name": self.name, "contacts": [c.to_dict() for c in self.contacts]}

    @classmethod
    def from_dict(cls, data: Any) -> GraspTarget:
        """Build from the JSON form of ``docs/formats.md``, raising :class:`InvalidTargetError`."""
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
        return cls(name, [_contact_from_dict(item, name) for item in raw])


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


def _problem(raw: Any, index: int) -> GraspTarget | InvalidProblem:
    if isinstance(raw, dict) and "name" not in raw:
        raw = {**raw, "name": f"problem-{index}"}
    try:
        return GraspTarget.from_dict(raw)
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
        InvalidTargetError: The file is missing, a folder, not UTF-8 JSON, nested too deeply, or
            not an object with a string ``hand`` and a ``problems`` list.
    """
    path = Path(path)
    data = read_json(path, "targets file", InvalidTargetError)
    if not isinstance(data, dict) or not isinstance(data.get("problems"), list):
        raise InvalidTargetError(
            f"targets file {path} must be an object with 'hand' and a 'problems' list"
        )
    hand = data.get("hand", "sah")
    if not isinstance(hand, str) or not hand:
        raise InvalidTargetError(
            f"targets file {path}: 'hand' must be 'sah', 'allegro' or a hand-description path, "
            f"got {_preview(hand)}"
        )
    if Path(hand).suffix and not Path(hand).is_absolute():
        hand = str(path.parent / hand)
    return hand, [_problem(raw, i) for i, raw in enumerate(data["problems"])]


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
