import json
from pathlib import Path

import numpy as np
import pytest

from sahgrasp.contacts import ContactTarget, GraspTarget, load_targets, save_targets
from sahgrasp.errors import InvalidTargetError

FINGERS = ("thumb", "index", "middle", "ring")


def _grasp() -> GraspTarget:
    return GraspTarget(
        "box",
        [ContactTarget(f, [0.01 * i, 0.0, 0.1], [0.0, -1.0, 0.0]) for i, f in enumerate(FINGERS)],
    )


def test_roundtrip(tmp_path: Path) -> None:
    path = tmp_path / "t.json"
    save_targets(path, "sah", [_grasp()])
    loaded = load_targets(path)
    assert loaded.hand == "sah"
    assert loaded.problems == (_grasp(),)


def test_centre_is_offset_along_normal() -> None:
    c = ContactTarget("thumb", [0, 0, 0], [0, 0, 1])
    np.testing.assert_allclose(c.centre(0.01), [0, 0, 0.01])


@pytest.mark.parametrize(
    ("point", "normal", "match"),
    [
        ([0, 0, float("nan")], [0, 0, 1], "NaN"),
        ([0, 0, float("inf")], [0, 0, 1], "NaN or inf"),
        ([0, 0, 0], [0, 0, 2], "unit vector"),
        ([0, 0], [0, 0, 1], "3 components"),
        ([0, 0, 0], "up", "3 numbers"),
    ],
)
def test_invalid_contact(point: list, normal: object, match: str) -> None:
    with pytest.raises(InvalidTargetError, match=match):
        ContactTarget("thumb", point, normal)  # type: ignore[arg-type]


def test_repeated_unknown_and_missing_fingers() -> None:
    c = ContactTarget("thumb", [0, 0, 0], [0, 0, 1])
    with pytest.raises(InvalidTargetError, match="more than once"):
        GraspTarget("g", [c, c])
    with pytest.raises(InvalidTargetError, match=r"unknown finger.*valid fingers"):
        GraspTarget("g", [ContactTarget("pinky", [0, 0, 0], [0, 0, 1])]).check_fingers(FINGERS)
    with pytest.raises(InvalidTargetError, match="missing contact"):
        GraspTarget("g", [c]).check_fingers(FINGERS)


def test_file_errors(tmp_path: Path) -> None:
    with pytest.raises(InvalidTargetError, match="cannot read"):
        load_targets(tmp_path / "nope.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(InvalidTargetError, match="not valid JSON"):
        load_targets(bad)
    bad.write_text(
        '{"hand": "sah", "problems": [{"name": "a", "contacts": [{"finger": "thumb", '
        '"point": [0, 0, NaN], "normal": [0, 0, 1]}]}]}'
    )
    with pytest.raises(InvalidTargetError, match="finite"):
        load_targets(bad)
    bad.write_text(json.dumps({"hand": "sah", "problems": [{"name": "a", "contacts": [{}]}]}))
    with pytest.raises(InvalidTargetError, match="needs 'finger'"):
        load_targets(bad)
