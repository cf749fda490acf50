import json
from pathlib import Path

import numpy as np
import pytest

from sahgrasp.contacts import (
    ContactTarget,
    GraspTarget,
    InvalidProblem,
    load_targets,
    read_problems,
    save_targets,
)
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


@pytest.mark.parametrize(
    ("point", "match"),
    [
        (["0.1", 0, 0], "3 numbers"),
        ([True, 0, 0], "3 numbers"),
        ([None, 0, 0], "3 numbers"),
        ([[0, 0, 0]], "3 numbers"),
        ({"x": 0}, "3 numbers"),
        ([10**400, 0, 0], "too large for a float"),
        ([1e400, 0, 0], "NaN or inf"),
        ([0, 0, 0, 0], "3 components"),
    ],
)
def test_points_must_be_three_real_numbers(point: object, match: str) -> None:
    with pytest.raises(InvalidTargetError, match=match):
        ContactTarget("thumb", point, [0, 0, 1])  # type: ignore[arg-type]


def test_numpy_inputs_still_accepted() -> None:
    c = ContactTarget("thumb", np.array([[0.0], [0.0], [1.0]]), np.array([0, 0, 1], dtype=np.int64))
    np.testing.assert_array_equal(c.point, [0, 0, 1])
    with pytest.raises(InvalidTargetError, match="3 numbers"):
        ContactTarget("thumb", np.array([True, False, True]), [0, 0, 1])


def test_lone_surrogate_in_a_name_becomes_a_replacement_character() -> None:
    g = GraspTarget("bad\ud800name", [ContactTarget("thumb", [0, 0, 0], [0, 0, 1])])
    assert g.name == "bad\ufffdname"
    g.name.encode("utf-8")


def _write(tmp_path: Path, data: object) -> Path:
    path = tmp_path / "targets.json"
    path.write_text(json.dumps(data))
    return path


def test_read_problems_keeps_invalid_problems_with_their_reason(tmp_path: Path) -> None:
    good = _grasp().to_dict()
    nameless = {"contacts": []}
    path = _write(
        tmp_path, {"hand": "sah", "problems": [good, 42, nameless, {"name": 7, "contacts": []}]}
    )
    hand, problems = read_problems(path)
    assert hand == "sah"
    assert problems[0] == _grasp()
    assert [(p.name, p.detail[:30]) for p in problems[1:]] == [  # type: ignore[union-attr]
        ("problem-1", "a problem must be an object wi"),
        ("problem-2", "grasp 'problem-2' has no conta"),
        ("problem-3", "a problem's 'name' must be a s"),
    ]
    assert all(isinstance(p, InvalidProblem) for p in problems[1:])
    with pytest.raises(InvalidTargetError, match="must be an object with 'name'"):
        load_targets(path)


def test_relative_hand_path_is_resolved_against_the_targets_file(tmp_path: Path) -> None:
    path = _write(tmp_path, {"hand": "hands/mine.json", "problems": []})
    assert read_problems(path)[0] == str(tmp_path / "hands" / "mine.json")
    assert read_problems(_write(tmp_path, {"hand": "allegro", "problems": []}))[0] == "allegro"
    assert (
        read_problems(_write(tmp_path, {"hand": "/abs/h.json", "problems": []}))[0] == "/abs/h.json"
    )


@pytest.mark.parametrize("hand", [3, None, "", ["sah"]])
def test_hand_must_be_a_name_or_path(tmp_path: Path, hand: object) -> None:
    with pytest.raises(InvalidTargetError, match="'hand' must be"):
        read_problems(_write(tmp_path, {"hand": hand, "problems": []}))


MUG = Path(__file__).resolve().parents[1] / "examples" / "meshes" / "mug.stl"


def test_an_object_spec_names_a_catalog_object_or_a_mesh_placed_in_the_world() -> None:
    from sahgrasp.contacts import object_spec

    can = object_spec({"name": "can", "xyz": [0.1, 0, 0], "quat": [0, 0, 1, 0]}, ".")
    assert can is not None and can.load().name == "can"
    np.testing.assert_allclose(can.placement()[:3, :3], np.diag([-1.0, -1.0, 1.0]), atol=1e-15)
    mug = object_spec({"mesh": MUG.name}, MUG.parent)
    assert mug is not None and mug.mesh == str(MUG) and mug.key() != can.key()
    assert object_spec(mug.to_dict(), "/") == mug and object_spec(None, ".") is None


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ({"name": "teapot"}, r"unknown object 'teapot'; valid names are \['fork'"),
        ({"name": "can", "mesh": "m.stl"}, r"either 'name' \(a catalog object\) or 'mesh'"),
        ({"xyz": [0, 0, 0]}, r"either 'name'"),
        ({"name": "can", "scale": 2}, r"unknown key\(s\) \['scale'\]"),
        ({"name": "can", "xyz": [0, 0, "1"]}, r"object 'xyz' must be 3 numbers \[m\]"),
        ({"name": "can", "quat": [0, 0, 1]}, r"'quat' must have 4 components \[x, y, z, w\]"),
        ({"name": "can", "quat": [0, 0, 0, 1.01]}, r"length 1.01; it must be a unit quaternion"),
        ({"name": "can", "xyz": [0, 0, float("nan")]}, r"NaN or inf"),
        ({"mesh": "mug.txt"}, r"unsupported type; use one of \['.stl'"),
        ({"mesh": "none.stl"}, r"object mesh 'none.stl' not found"),
        ("can", r"must be an object with either 'name'"),
    ],
)
def test_a_bad_object_spec_is_refused_with_the_reason(spec: object, message: str) -> None:
    from sahgrasp.contacts import object_spec

    with pytest.raises(InvalidTargetError, match=message):
        object_spec(spec, MUG.parent)


def test_targets_files_give_a_default_object_and_per_problem_ones(tmp_path: Path) -> None:
    contacts = [{"finger": "thumb", "point": [0, 0, 0], "normal": [0, 0, 1]}]
    objects = [None, {"name": "cup"}, {"name": "cup", "quat": [1, 1, 0, 0]}]
    problems = [{"contacts": contacts}] + [{"contacts": contacts, "object": o} for o in objects]
    path = tmp_path / "t.json"
    path.write_text(json.dumps({"hand": "sah", "object": {"name": "can"}, "problems": problems}))
    _, read = read_problems(path)
    names = [getattr(getattr(p, "object_spec", None), "name", None) for p in read[:3]]
    assert names == ["can", None, "cup"]
    assert isinstance(read[3], InvalidProblem) and "unit quaternion" in read[3].detail


def test_a_pickled_target_comes_back_equal_bit_for_bit_and_read_only() -> None:
    import pickle

    target = GraspTarget("p", [ContactTarget("thumb", [0.1, 1 / 3, -2e-300], [0.0, 0.6, 0.8])])
    back = pickle.loads(pickle.dumps(target, pickle.HIGHEST_PROTOCOL))
    assert back == target and back.contacts[0].point.tobytes() == target.contacts[0].point.tobytes()
    assert (
        not back.contacts[0].point.flags.writeable and not back.contacts[0].normal.flags.writeable
    )
