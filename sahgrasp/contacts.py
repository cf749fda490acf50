"""Contact targets: a point on the object and the object's outward unit normal there, per finger.

A fingertip of radius ``R`` satisfies a target when the contact point on the fingertip sphere equals
the target point and the sphere centre equals ``point + R * normal`` (conventions.md). Targets are
given in the ``world`` frame. This module validates them and reads/writes the targets JSON format.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp.errors import InvalidTargetError
from sahgrasp.fileio import write_json_atomic

__all__ = [
    "NORMAL_TOLERANCE",
    "ContactTarget",
    "GraspTarget",
    "TargetsFile",
    "load_targets",
    "save_targets",
]

NORMAL_TOLERANCE = 1e-6
"""Largest accepted deviation of a normal's length from 1 (conventions.md)."""


def _vector3(value: ArrayLike, what: str) -> NDArray[np.float64]:
    try:
        vec = np.array(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise InvalidTargetError(f"{what} must be 3 numbers, got {value!r}") from exc
    if vec.shape != (3,):
        raise InvalidTargetError(f"{what} must have 3 components [m], got {vec.size}")
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
            raise InvalidTargetError(f"finger must be a non-empty name, got {finger!r}")
        point_v = _vector3(point, f"{finger} contact point")
        normal_v = _vector3(normal, f"{finger} contact normal")
        norm = float(np.linalg.norm(normal_v))
        if abs(norm - 1.0) > NORMAL_TOLERANCE:
            raise InvalidTargetError(
                f"{finger} contact normal has length {norm:.9g}; it must be a unit vector "
                f"(tolerance {NORMAL_TOLERANCE:g}), normals are not normalised silently"
            )
        object.__setattr__(self, "finger", finger)
        object.__setattr__(self, "point", point_v)
        object.__setattr__(self, "normal", normal_v)

    def centre(self, radius_m: float) -> NDArray[np.float64]:
        """Return the fingertip-sphere centre ``r* = p* + R n*`` [m] that satisfies this contact."""
        return self.point + radius_m * self.normal

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form of conventions.md."""
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
        contacts_t = tuple(contacts)
        if not contacts_t:
            raise InvalidTargetError(f"grasp {name!r} has no contacts; give one per finger")
        fingers = [c.finger for c in contacts_t]
        repeated = sorted({f for f in fingers if fingers.count(f) > 1})
        if repeated:
            raise InvalidTargetError(
                f"grasp {name!r} names finger(s) {repeated} more than once; each finger once"
            )
        object.__setattr__(self, "name", str(name))
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
        """Return the JSON form of conventions.md."""
        return {"name": self.name, "contacts": [c.to_dict() for c in self.contacts]}

    @classmethod
    def from_dict(cls, data: Any) -> GraspTarget:
        """Build from the JSON form of conventions.md, raising :class:`InvalidTargetError`."""
        if not isinstance(data, dict) or "contacts" not in data:
            raise InvalidTargetError(
                f"a problem must be an object with 'name' and 'contacts', got {data!r:.200}"
            )
        name = str(data.get("name", "unnamed"))
        raw = data["contacts"]
        if not isinstance(raw, list):
            raise InvalidTargetError(f"problem {name!r}: 'contacts' must be a list")
        contacts = []
        for item in raw:
            if not isinstance(item, dict) or not {"finger", "point", "normal"} <= item.keys():
                raise InvalidTargetError(
                    f"problem {name!r}: each contact needs 'finger', 'point' and 'normal', "
                    f"got {item!r:.200}"
                )
            contacts.append(ContactTarget(item["finger"], item["point"], item["normal"]))
        return cls(name, contacts)


@dataclass(frozen=True)
class TargetsFile:
    """Contents of a targets JSON file: the hand name (or description path) and the problems."""

    hand: str
    problems: tuple[GraspTarget, ...] = field(default_factory=tuple)


def load_targets(path: str | os.PathLike[str]) -> TargetsFile:
    """Read a targets file (conventions.md, "Targets file").

    Raises:
        InvalidTargetError: The file is missing, is not JSON, or holds an invalid target.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InvalidTargetError(f"cannot read targets file {path}: {exc.strerror}") from exc
    try:
        data = json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        raise InvalidTargetError(f"targets file {path} is not valid JSON: {exc}") from exc
    if not isinstance(data, dict) or not isinstance(data.get("problems"), list):
        raise InvalidTargetError(
            f"targets file {path} must be an object with 'hand' and a 'problems' list"
        )
    problems = tuple(GraspTarget.from_dict(p) for p in data["problems"])
    return TargetsFile(hand=str(data.get("hand", "sah")), problems=problems)


def _reject_constant(name: str) -> float:
    raise InvalidTargetError(f"targets hold {name}; every number must be finite")


def save_targets(path: str | os.PathLike[str], hand: str, problems: Iterable[GraspTarget]) -> None:
    """Write a targets file atomically."""
    write_json_atomic(path, {"hand": hand, "problems": [p.to_dict() for p in problems]})
