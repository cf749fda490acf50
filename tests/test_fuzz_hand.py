"""Fuzzing ``load_hand``: random edits of the SAH URDF and random hand descriptions.

Every input must give a typed :class:`HandModelError` or a working hand (finite contact state and
a collision answer at the neutral configuration): never another exception, a crash or a hang.
The URDF cases run in a child process, so that a crash inside Pinocchio fails this test with the
offending edit instead of killing pytest.
"""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sahgrasp.core.errors import HandModelError
from sahgrasp.model.hand import load_hand, sah_description

pytestmark = pytest.mark.slow  # random hands built and solved: several seconds

ROOT = Path(__file__).resolve().parents[1]
URDF_EXAMPLES = 200
DESCRIPTION_EXAMPLES = 100

_NUMBERS = ("0", "-0", "nan", "inf", "-inf", "1e300", "-1", "1e-300", "3.5", "x", "")
_TYPES = ("revolute", "prismatic", "fixed", "continuous", "floating", "planar", "spherical", "")
_NAMES = ("palm", "index_tip", "index_j3", "thumb_j0", "", "a\x9bb", "a\u202eb", "a b")
_EDITS = ("delete", "duplicate", "rename", "number", "swap_parents", "type", "move", "truncate")
_LIMIT = 1 << 16

# An edit: (kind, element index, second index, value index, free text); indices wrap around.
edit = st.tuples(
    st.sampled_from(_EDITS),
    st.integers(0, _LIMIT),
    st.integers(0, _LIMIT),
    st.integers(0, _LIMIT),
    st.text(st.characters(exclude_categories=("Cs",)), max_size=6),
)


def _apply(root: ET.Element, change: tuple[str, int, int, int, str]) -> bytes | None:
    """Apply one edit in place; return bytes instead when the edit is on the text itself."""
    kind, i, j, k, text = change
    elements = list(root.iter())
    parents = {child: parent for parent in elements for child in parent}
    element, other = elements[i % len(elements)], elements[j % len(elements)]
    joints = root.findall("joint")
    if kind == "delete" and element in parents:
        parents[element].remove(element)
    elif kind == "duplicate" and element in parents:
        parents[element].append(copy.deepcopy(element))
    elif kind == "rename" and element.attrib:
        key = sorted(element.attrib)[k % len(element.attrib)]
        names = [*_NAMES, text, *(e.get("name", "") for e in elements)]
        element.set(key, names[j % len(names)])
    elif kind == "number" and element.attrib:
        key = sorted(element.attrib)[j % len(element.attrib)]
        values = element.attrib[key].split() or [""]
        values[k % len(values)] = _NUMBERS[k % len(_NUMBERS)]
        element.set(key, " ".join(values))
    elif kind == "swap_parents" and len(joints) > 1:
        a, b = joints[i % len(joints)].find("parent"), joints[j % len(joints)].find("parent")
        if a is not None and b is not None:
            a.attrib, b.attrib = b.attrib, a.attrib
    elif kind == "type" and joints:
        joints[i % len(joints)].set("type", _TYPES[k % len(_TYPES)])
    elif kind == "move" and element in parents and element not in other.iter():
        parents[element].remove(element)
        other.append(element)
    elif kind == "truncate":
        data = ET.tostring(root)
        return data[: i % len(data)]
    return None


def _edited_urdf(changes: list[tuple[str, int, int, int, str]]) -> bytes:
    root = ET.fromstring(sah_description().urdf_path.read_bytes())
    for change in changes:
        data = _apply(root, change)
        if data is not None:
            return data
    return ET.tostring(root)


def _typed_error_or_working_hand(source: Path) -> str:
    try:
        hand = load_hand(source)
    except HandModelError as exc:
        assert str(exc).isprintable(), str(exc)
        return "refused"
    q = hand.configuration()
    state = hand.contact_state(q)
    for values in (state.points, state.centres, state.normals):
        assert np.isfinite(values).all(), values
    assert hand.in_collision(q) in (True, False)
    return "loaded"


def _description(urdf: str) -> dict[str, Any]:
    return {
        "name": "fuzz",
        "urdf": urdf,
        "fingertip_radius_m": 0.01,
        "contact_pitch_limits_rad": [-0.26, 1.4],
        "contact_yaw_limits_rad": [-0.6, 0.6],
        "fingers": [
            {"name": f, "tip_link": f"{f}_tip", "tip_axis": [0, 1, 0], "pad_axis": [1, 0, 0]}
            for f in ("thumb", "index", "middle", "ring")
        ],
    }


def run_urdf_fuzz(examples: int) -> None:
    """Hypothesis over URDF edits (in the child process); prints each case before loading it."""
    folder = Path(tempfile.mkdtemp(prefix="sahgrasp-fuzz-"))
    (folder / "hand.json").write_text(json.dumps(_description("hand.urdf")))
    outcomes = {"refused": 0, "loaded": 0}

    @settings(
        max_examples=examples,
        deadline=None,
        database=None,
        derandomize=True,
        suppress_health_check=list(HealthCheck),
    )
    @given(st.lists(edit, min_size=1, max_size=4))
    def check(changes: list[tuple[str, int, int, int, str]]) -> None:
        (folder / "hand.urdf").write_bytes(_edited_urdf(changes))
        print(ascii(changes), flush=True)
        outcomes[_typed_error_or_working_hand(folder / "hand.json")] += 1

    check()
    print(json.dumps(outcomes))


def test_random_urdf_edits_give_typed_errors_or_working_hands() -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    run = subprocess.run(
        [sys.executable, __file__, str(URDF_EXAMPLES)],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    last = run.stdout.strip().splitlines()[-1:] or ["(none)"]
    assert run.returncode == 0, f"last case {last[0]}\n{run.stderr[-3000:]}"
    outcomes = json.loads(last[0])
    # Not vacuous: some edits must be refused and some must leave a working hand.
    assert outcomes["refused"] > 0 and outcomes["loaded"] > 0, outcomes


json_value = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(10**400), 10**400)
    | st.floats()
    | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner),
    max_leaves=12,
)
_FINGER_KEYS = tuple(_description("")["fingers"][0])
_KEYS = (*_FINGER_KEYS, *_description(""))


@settings(
    max_examples=DESCRIPTION_EXAMPLES,
    deadline=None,
    derandomize=True,
    suppress_health_check=list(HealthCheck),
)
@given(
    st.lists(st.tuples(st.sampled_from(_KEYS), st.integers(0, 4), json_value), max_size=3),
    st.one_of(st.none(), json_value, st.binary(max_size=64)),
)
def test_random_descriptions_give_typed_errors_or_working_hands(
    edits: list[tuple[str, int, Any]], replacement: Any
) -> None:
    data = _description(str(sah_description().urdf_path))
    fingers = data["fingers"]  # kept: edits of finger keys go here even if "fingers" is replaced
    for key, finger, value in edits:
        # A key of a finger edits one finger; a top-level key replaces or deletes the value.
        target = fingers[finger % 4] if key in _FINGER_KEYS else data
        if value is None:
            target.pop(key, None)
        else:
            target[key] = value
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "hand.json"
        if isinstance(replacement, bytes):
            path.write_bytes(replacement)
        elif replacement is not None:
            path.write_text(json.dumps(replacement))
        else:
            path.write_text(json.dumps(data, allow_nan=True))
        _typed_error_or_working_hand(path)


def test_hand_paths_that_name_no_file_say_why(tmp_path: Path) -> None:
    """A link loop, a NUL byte, a name too long: one line each, never "unknown hand"."""
    (tmp_path / "a.json").symlink_to(tmp_path / "b.json")
    (tmp_path / "b.json").symlink_to(tmp_path / "a.json")
    cases = {
        str(tmp_path / "a.json"): "is a loop of symbolic links",
        "hand\0.json": "not a valid file name",
        "h" * 5000 + ".json": r"\(5005 characters\) is a path too long",
        str(tmp_path / "none.json"): "not found",
        str(tmp_path): "unknown hand",  # no suffix: a name, not a file
    }
    for hand, reason in cases.items():
        with pytest.raises(HandModelError, match=reason) as error:
            load_hand(hand)
        assert len(str(error.value)) < 400 and str(error.value).isprintable()


def test_a_broken_hand_mesh_is_one_plain_line(tmp_path: Path) -> None:
    """coal's multi-line error, without its source file and escaped newlines."""
    urdf = sah_description().urdf_path.read_text()
    collision = '<collision><geometry><mesh filename="broken.stl"/></geometry></collision>'
    end = urdf.index("</link>")
    (tmp_path / "hand.urdf").write_text(urdf[:end] + collision + urdf[end:])
    (tmp_path / "broken.stl").write_bytes(b"solid x\nfacet normal garbage\n")
    (tmp_path / "hand.json").write_text(json.dumps(_description("hand.urdf")))
    with pytest.raises(HandModelError, match="does not load in Pinocchio") as error:
        load_hand(tmp_path / "hand.json")
    message = str(error.value)
    assert "broken.stl" in message and message.isprintable()
    assert "\\n" not in message and "From file" not in message and ".cpp" not in message


if __name__ == "__main__":
    run_urdf_fuzz(int(sys.argv[1]))
