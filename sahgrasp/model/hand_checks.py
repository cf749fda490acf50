"""Checks of hand descriptions and URDFs, run before anything reaches Pinocchio.

Pinocchio's URDF parser trusts its input: a link with two parent joints crashes the process, and
zero axes, inverted or infinite limits, NaN placements or deeply nested XML give tracebacks far from
their cause, or silently wrong kinematics. Everything here raises :class:`HandModelError` with a
message naming what is wrong and what is valid.

Names (links, joints, fingers, the hand) must be printable: control characters and ANSI escape
sequences are refused rather than sanitized, so a name shown in a message or a result is the name
in the file. Messages show a rejected value with ``repr`` so that nothing reaches a terminal raw.
"""

from __future__ import annotations

import math
import os
import sys
import tempfile
import threading
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any, cast

from sahgrasp.core import fileio
from sahgrasp.core.errors import HandModelError

__all__ = [
    "MAX_MAGNITUDE",
    "MAX_XML_DEPTH",
    "check_name",
    "check_urdf",
    "native_message",
    "native_stderr",
    "number",
    "numbers",
    "read_json",
    "shown",
    "shown_path",
]

MAX_XML_DEPTH = 32
"""Deepest element nesting accepted in a URDF (real ones nest about 5 deep; Pinocchio's C++
parser recurses per level, so a very deep file would exhaust its stack)."""

MAX_MAGNITUDE = 1e3
"""Largest magnitude [m or rad] of a URDF length, angle or limit: beyond it, a value is a unit
mistake, and sums of such values overflow to inf in the kinematics."""

_MOVABLE = ("revolute", "prismatic")
_JOINT_TYPES = (*_MOVABLE, "fixed")
_REFUSED_TYPES = {
    "continuous": "it has no limits; give it type revolute with <limit lower upper>",
    "floating": "sahgrasp adds the wrist's free flyer itself; a hand URDF has 1-DoF joints",
    "planar": "sahgrasp models hands of 1-DoF revolute/prismatic joints",
}
# (tag, attribute) -> (count, strictly positive): the numbers Pinocchio's URDF parser reads.
_NUMBERS: dict[tuple[str, str], tuple[int, bool]] = {
    ("origin", "xyz"): (3, False),
    ("origin", "rpy"): (3, False),
    ("axis", "xyz"): (3, False),
    ("limit", "lower"): (1, False),
    ("limit", "upper"): (1, False),
    ("mimic", "multiplier"): (1, False),
    ("mimic", "offset"): (1, False),
    ("box", "size"): (3, True),
    ("cylinder", "radius"): (1, True),
    ("cylinder", "length"): (1, True),
    ("sphere", "radius"): (1, True),
    ("mesh", "scale"): (3, False),
}
# Never used by the kinematics, and large values are common placeholders ("no limit"): they only
# need to be finite.
_FINITE_ONLY = {("mass", "value"), ("limit", "effort"), ("limit", "velocity")} | {
    ("inertia", a) for a in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
}


_STDERR_LOCK = threading.Lock()


@contextmanager
def native_stderr() -> Iterator[list[str]]:
    """Capture what native code writes to file descriptor 2 while the block runs.

    Pinocchio's URDF parser (urdfdom) reports some errors only there, and then drops the faulty
    element (a link's collision shape, say) instead of failing: the caller must see those lines.
    The list is filled when the block exits. Captures are serialized by a lock, since file
    descriptor 2 is shared by the whole process; what other threads write meanwhile is captured
    too.
    """
    lines: list[str] = []
    with _STDERR_LOCK, tempfile.TemporaryFile() as log:
        sys.stderr.flush()
        try:
            saved = os.dup(2)
        except OSError:  # no file descriptor 2 (a daemon): nothing to capture, nothing shown
            yield lines
            return
        os.dup2(log.fileno(), 2)
        try:
            yield lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            log.seek(0)
            lines.extend(log.read().decode("utf-8", "replace").splitlines())


_NATIVE_SOURCE = ("From file:", "in function:", "at line:")


def native_message(text: str) -> str:
    r"""A native library's error text as one terminal-safe line, without where it was raised.

    coal and Pinocchio raise multi-line messages that start with the C++ source file, function
    and line (``From file: /project/src/mesh_loader/assimp.cpp``): of no use to a user, and
    shown with literal ``\n`` once escaped. The remaining lines (``message: ...``, hints) are
    joined with ``"; "``.
    """
    kept = []
    for line in text.splitlines():
        line = line.strip()
        if line and not line.startswith(_NATIVE_SOURCE):
            kept.append(line.removeprefix("message:").strip())
    return shown("; ".join(kept))


def shown(value: object) -> str:
    """``value`` as text safe for a terminal: itself if printable, else its escaped ``ascii``."""
    text = str(value)
    return text if text.isprintable() else ascii(text)


def shown_path(path: object, limit: int = 120) -> str:
    """A path for a message (:func:`shown`), its middle cut when longer than ``limit``."""
    text = shown(path)
    if len(text) <= limit:
        return text
    half = (limit - 30) // 2
    return f"{text[:half]}...{text[-half:]} ({len(text)} characters)"


def check_name(what: str, value: object) -> str:
    """Return ``value`` if it is a non-empty printable string, else raise.

    Raises:
        HandModelError: ``value`` is not a string, is empty, or holds control characters.
    """
    if not isinstance(value, str) or not value or not value.isprintable():
        raise HandModelError(
            f"{what} must be a non-empty string of printable characters (no control characters "
            f"or escape sequences), got {value!r}"
        )
    return value


def number(what: str, value: object) -> float:
    """``value`` as a finite float; JSON booleans and strings are refused.

    Raises:
        HandModelError: ``value`` is not a finite int or float.
    """
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise HandModelError(f"{what} must be a number, got {value!r}")
    try:
        out = float(value)
    except OverflowError:
        out = math.inf
    if not math.isfinite(out):
        raise HandModelError(f"{what} must be finite, got {shown(value)[:40]}")
    return out


def numbers(what: str, values: object, count: int) -> tuple[float, ...]:
    """``values`` as ``count`` finite floats (see :func:`number`).

    Raises:
        HandModelError: Not a list of ``count`` finite numbers.
    """
    if not isinstance(values, list | tuple) or len(values) != count:
        raise HandModelError(f"{what} must be a list of {count} numbers, got {values!r}"[:300])
    return tuple(number(f"{what}[{i}]", v) for i, v in enumerate(values))


def read_json(path: Path, what: str) -> Any:
    """Parse a UTF-8 JSON file; every way it can fail is a :class:`HandModelError`.

    Raises:
        HandModelError: Unreadable, not UTF-8 (binary, UTF-16), not JSON, or nested too deeply.
    """
    return fileio.read_json(path, what, HandModelError)


def check_urdf(data: bytes, where: str) -> str:
    """Check that URDF ``data`` is a tree Pinocchio can load, and return it as text.

    Args:
        data: The URDF file's bytes.
        where: How to name the file in messages.

    Raises:
        HandModelError: Not UTF-8, not well-formed, DOCTYPE/ENTITY declarations, nested deeper
            than :data:`MAX_XML_DEPTH`, or a rule of :func:`_check_robot` broken.
    """
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise HandModelError(
            f"URDF {where} is not UTF-8 text (byte {exc.start}); save it as UTF-8"
        ) from None
    if "<!DOCTYPE" in text or "<!ENTITY" in text:
        raise HandModelError(
            f"URDF {where} declares a DOCTYPE or ENTITY; a URDF must not (the XML parsers "
            "sahgrasp and Pinocchio use would read it differently)"
        )
    _check_robot(_parse(data, where), where)
    return text


def _parse(data: bytes, where: str) -> ET.Element:
    parser = ET.XMLPullParser(events=("start", "end"))  # type: ignore[var-annotated]
    depth, root = 0, None
    try:
        for start in range(0, len(data), 1 << 16):
            parser.feed(data[start : start + (1 << 16)])
            # "start"/"end" events only: each is (event, element).
            for event, element in cast("Iterator[tuple[str, ET.Element]]", parser.read_events()):
                depth += 1 if event == "start" else -1
                root = element if root is None else root
                if depth > MAX_XML_DEPTH:
                    raise HandModelError(
                        f"URDF {where} nests elements more than {MAX_XML_DEPTH} deep"
                    )
        parser.close()
    except ET.ParseError as exc:
        raise HandModelError(f"URDF {where} is not well-formed XML ({exc})") from None
    if root is None:
        raise HandModelError(f"URDF {where} is empty")
    return root


def _check_robot(robot: ET.Element, where: str) -> None:
    """One root link, at most one parent joint per link, no cycle, valid joints and numbers."""
    if robot.tag != "robot":
        raise HandModelError(f"URDF {where} has root element <{shown(robot.tag)}>, not <robot>")
    for element in robot.iter():
        if "name" in element.attrib:
            check_name(f"URDF {where}: <{shown(element.tag)}> name", element.attrib["name"])
        _check_numbers(element, where)
    links = _unique_names(robot.findall("link"), "link", where)
    joints = {
        name: element
        for name, element in zip(
            _unique_names(robot.findall("joint"), "joint", where),
            robot.findall("joint"),
            strict=True,
        )
    }
    parent_of: dict[str, tuple[str, str]] = {}  # child link -> (joint, parent link)
    for name, joint in joints.items():
        parent, child = (_joint_link(joint, name, end, links, where) for end in ("parent", "child"))
        if child in parent_of:
            raise HandModelError(
                f"URDF {where}: link {child!r} has two parent joints ({parent_of[child][0]!r} "
                f"and {name!r}); a URDF is a tree, every link has at most one parent joint"
            )
        parent_of[child] = (name, parent)
        _check_joint(joint, name, joints, where)
    _check_connected(links, parent_of, where)


def _unique_names(elements: list[ET.Element], kind: str, where: str) -> list[str]:
    names: list[str] = []
    for element in elements:
        name = element.get("name")
        if name is None:
            raise HandModelError(f"URDF {where}: a <{kind}> has no name attribute")
        if name in names:
            raise HandModelError(f"URDF {where}: two {kind}s are named {name!r}")
        names.append(name)
    return names


def _joint_link(joint: ET.Element, name: str, end: str, links: Iterable[str], where: str) -> str:
    element = joint.find(end)
    link = None if element is None else element.get("link")
    if link is None or link not in links:
        raise HandModelError(
            f"URDF {where}: joint {name!r} has {end} link {link!r}, which is not a link of the "
            f"URDF; its links are {sorted(links)[:40]}"
        )
    return link


def _check_joint(
    joint: ET.Element, name: str, joints: Mapping[str, ET.Element], where: str
) -> None:
    kind = joint.get("type")
    if kind in _REFUSED_TYPES:
        raise HandModelError(f"URDF {where}: joint {name!r} is {kind}: {_REFUSED_TYPES[kind]}")
    if kind not in _JOINT_TYPES:
        raise HandModelError(
            f"URDF {where}: joint {name!r} has type {kind!r}; valid: {list(_JOINT_TYPES)}"
        )
    if kind == "fixed":
        return
    axis = joint.find("axis")
    if axis is not None and not any(_floats(axis, "xyz", where)):
        raise HandModelError(f"URDF {where}: joint {name!r} has a zero axis; give a unit vector")
    limit = joint.find("limit")
    lower, upper = (
        (0.0, 0.0) if limit is None else (_float(limit, a, where) for a in ("lower", "upper"))
    )
    if not lower < upper:
        raise HandModelError(
            f"URDF {where}: joint {name!r} ({kind}) needs <limit lower upper> with lower < "
            f"upper, got lower={lower}, upper={upper}"
        )
    mimic = joint.find("mimic")
    if mimic is not None:
        _check_mimic(mimic, name, joints, where)


def _check_mimic(
    mimic: ET.Element, name: str, joints: Mapping[str, ET.Element], where: str
) -> None:
    leader = mimic.get("joint", "")
    if leader == name or leader not in joints or joints[leader].get("type") not in _MOVABLE:
        movable = sorted(n for n, j in joints.items() if j.get("type") in _MOVABLE and n != name)
        raise HandModelError(
            f"URDF {where}: joint {name!r} mimics {leader!r}, which is not another revolute or "
            f"prismatic joint of the URDF; valid: {movable[:40]}"
        )
    if joints[leader].find("mimic") is not None:
        raise HandModelError(
            f"URDF {where}: joint {name!r} mimics {leader!r}, itself a mimic joint; mimic the "
            "independent joint directly"
        )
    if "multiplier" in mimic.attrib and _float(mimic, "multiplier", where) == 0.0:
        raise HandModelError(
            f"URDF {where}: joint {name!r} has mimic multiplier 0 (it would never move); "
            "remove the joint or give a non-zero multiplier"
        )


def _check_connected(
    links: list[str], parent_of: Mapping[str, tuple[str, str]], where: str
) -> None:
    roots = [link for link in links if link not in parent_of]
    if len(roots) != 1:
        raise HandModelError(
            f"URDF {where} has {len(roots)} root links {roots[:10]} (links without a parent "
            "joint); a hand URDF is one tree with exactly one root, the palm"
        )
    children: dict[str, list[str]] = {}
    for child, (_, parent) in parent_of.items():
        children.setdefault(parent, []).append(child)
    reached, todo = {roots[0]}, [roots[0]]
    while todo:
        for child in children.get(todo.pop(), []):
            reached.add(child)
            todo.append(child)
    cycle = [link for link in links if link not in reached]
    if cycle:
        raise HandModelError(
            f"URDF {where}: links {cycle[:10]} form a cycle of joints, detached from the root "
            f"{roots[0]!r}; a URDF is a tree"
        )


def _check_numbers(element: ET.Element, where: str) -> None:
    for attribute in element.attrib:
        key = (element.tag, attribute)
        if key in _NUMBERS:
            count, positive = _NUMBERS[key]
            values = _floats(element, attribute, where, count)
            if any(abs(v) > MAX_MAGNITUDE for v in values):
                raise HandModelError(
                    f"URDF {where}: <{element.tag} {attribute}> = {values} exceeds "
                    f"{MAX_MAGNITUDE:g} (m or rad) in magnitude: a unit mistake?"
                )
            if positive and not all(v > 0 for v in values):
                raise HandModelError(
                    f"URDF {where}: <{element.tag} {attribute}> = {values} must be > 0"
                )
        elif key in _FINITE_ONLY:
            _floats(element, attribute, where, 1)


def _float(element: ET.Element, attribute: str, where: str) -> float:
    return _floats(element, attribute, where, 1)[0]


def _floats(element: ET.Element, attribute: str, where: str, count: int = 3) -> tuple[float, ...]:
    text = element.get(attribute, "")
    try:
        values = tuple(float(v) for v in text.split())
    except ValueError:
        values = ()
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise HandModelError(
            f"URDF {where}: <{shown(element.tag)} {attribute}> must be {count} finite "
            f"number(s), got {text[:80]!r}"
        )
    return values
