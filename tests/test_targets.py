"""Targets files: the document, its problems (valid or with their reason), their objects."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from sahgrasp.core.errors import InvalidTargetError
from sahgrasp.model.contacts import ContactTarget, GraspTarget
from sahgrasp.model.hand import Hand
from sahgrasp.objects.targets import (
    InvalidProblem,
    build_object,
    load_targets,
    read_problems,
    save_targets,
)

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
    from sahgrasp.objects.targets import object_spec

    can = object_spec({"name": "can", "xyz": [0.1, 0, 0], "quat": [0, 0, 1, 0]}, ".")
    assert can is not None and build_object(can).name == "can"
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
        ({"name": "can", "size": 2}, r"unknown key\(s\) 'size'"),
        ({"name": "can", "scale": 2}, r"'scale' is the unit of a mesh file"),
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
    from sahgrasp.objects.targets import object_spec

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


# --- What a targets file may read: mesh paths confined to its folder -----------------------

CONTACTS = [
    {"finger": "thumb", "point": [0.0, 0.0, 0.0], "normal": [1.0, 0.0, 0.0]},
    {"finger": "index", "point": [0.0, 0.0, 0.01], "normal": [1.0, 0.0, 0.0]},
]


def _targets(folder: Path, *meshes: object, **document: object) -> Path:
    """``folder/t.json`` with one problem per mesh path (its object ``{"mesh": path}``)."""
    folder.mkdir(parents=True, exist_ok=True)
    problems = [{"name": f"p{i}", "contacts": CONTACTS, "object": {"mesh": m}}
                for i, m in enumerate(meshes)]  # fmt: skip
    path = folder / "t.json"
    path.write_text(json.dumps({"hand": "sah", **document, "problems": problems}))
    return path


def _details(path: Path, **options: bool) -> list[str]:
    """Per problem: the reason it is invalid, or ``"valid"``."""
    return [p.detail if isinstance(p, InvalidProblem) else "valid"
            for p in read_problems(path, **options)[1]]  # fmt: skip


def test_mesh_paths_are_confined_to_the_targets_folder(tmp_path: Path) -> None:
    import shutil

    folder, outside = tmp_path / "shared", tmp_path / "private"
    (folder / "meshes").mkdir(parents=True)
    outside.mkdir()
    shutil.copy(MUG, folder / "meshes" / "mug.stl")
    shutil.copy(MUG, outside / "secret.stl")
    (folder / "escape.stl").symlink_to(outside / "secret.stl")
    (folder / "inside.stl").symlink_to(folder / "meshes" / "mug.stl")
    meshes = [
        "meshes/mug.stl",
        str(folder / "meshes" / "mug.stl"),  # absolute, but inside: allowed
        "inside.stl",  # a link that stays inside
        str(outside / "secret.stl"),
        "../private/secret.stl",
        "meshes/../../private/secret.stl",
        "escape.stl",  # a link leading out: resolved, then compared
    ]
    path = _targets(folder, *meshes)
    details = _details(path)
    assert details[:3] == ["valid"] * 3
    for detail in details[3:]:
        assert "outside the targets file's folder" in detail and "--allow-any-mesh-path" in detail
    assert _details(path, allow_outside_paths=True) == ["valid"] * len(meshes)
    with pytest.raises(InvalidTargetError, match="outside the targets file's folder"):
        load_targets(path)
    assert len(load_targets(path, allow_outside_paths=True).problems) == len(meshes)
    # The file's default object is checked the same way: the whole file is refused.
    default = _targets(folder, "meshes/mug.stl", object={"mesh": "../private/secret.stl"})
    with pytest.raises(InvalidTargetError, match="outside the targets file's folder"):
        read_problems(default)


@pytest.mark.slow
def test_solve_and_demo_take_the_option_to_allow_outside_meshes(tmp_path: Path) -> None:
    """``sahgrasp solve``: the refused problem is invalid input; the option lets it load."""
    from sahgrasp.cli import main

    folder = tmp_path / "t"
    pinky = [{**CONTACTS[0]}, {**CONTACTS[1], "finger": "pinky"}]  # refused after its object
    folder.mkdir()
    (folder / "t.json").write_text(json.dumps({"hand": "sah", "problems": [
        {"name": "out", "contacts": pinky, "object": {"mesh": str(MUG)}}]}))  # fmt: skip
    details = []
    for extra in ([], ["--allow-any-mesh-path"]):
        out = tmp_path / "out.json"
        assert main(["solve", str(folder / "t.json"), "--json", str(out), *extra]) == 1
        details.append(json.loads(out.read_text())["results"][0]["detail"])
    assert "outside the targets file's folder" in details[0]
    assert "unknown finger" in details[1]  # the mesh was read, the finger refused
    from sahgrasp.cli import _parser

    for command in (["demo", "--targets", "t.json"], ["solve", "t.json"]):
        parsed = _parser().parse_args([*command, "--allow-any-mesh-path"])
        assert parsed.allow_any_mesh_path and not _parser().parse_args(command).allow_any_mesh_path


# --- Unknown keys, unreachable paths, byte-order marks ---------------------------------------


@pytest.mark.parametrize(
    ("problem", "message"),
    [
        ({"contacts": CONTACTS, "Object": {"name": "can"}}, r"'Object' \(did you mean 'object'"),
        ({"contacts": CONTACTS, "objcet": {"name": "can"}}, r"'objcet' \(did you mean 'object'"),
        ({"contacts": [{**CONTACTS[0], "Normal": [0, 0, 1]}, CONTACTS[1]]}, r"a contact has"),
        ({"contacts": CONTACTS, "object": {"name": "can", "XYZ": [0, 0, 0]}}, r"'XYZ'"),
    ],
)
def test_unknown_keys_make_a_problem_invalid(tmp_path: Path, problem: dict, message: str) -> None:
    path = _write(tmp_path, {"hand": "sah", "problems": [problem, {"contacts": CONTACTS}]})
    first, second = read_problems(path)[1]
    assert isinstance(first, InvalidProblem) and isinstance(second, GraspTarget)
    assert "unknown key(s)" in first.detail and "valid keys" in first.detail
    assert re.search(message, first.detail), first.detail


def test_unknown_document_keys_refuse_the_file(tmp_path: Path) -> None:
    path = _write(tmp_path, {"hand": "sah", "Object": {"name": "can"}, "problems": []})
    with pytest.raises(InvalidTargetError, match=r"unknown key\(s\) 'Object'.*'object'"):
        read_problems(path)


def test_unreachable_mesh_paths_make_only_their_problem_invalid(tmp_path: Path) -> None:
    import shutil

    shutil.copy(MUG, tmp_path / "mug.stl")
    (tmp_path / "loop1.stl").symlink_to(tmp_path / "loop2.stl")
    (tmp_path / "loop2.stl").symlink_to(tmp_path / "loop1.stl")
    (tmp_path / "folder.stl").mkdir()
    meshes = ["loop1.stl", "a\0b.stl", "m" * 5000 + ".stl", "n" * 300 + ".stl", "folder.stl",
              "mug.stl", "\ud800.stl"]  # fmt: skip
    details = _details(_targets(tmp_path, *meshes))
    expected = ["loop of symbolic links", "NUL byte", "5004 characters long", "too long",
                "not a regular file", "valid", "not found|not a valid file name"]  # fmt: skip
    for detail, reason in zip(details, expected, strict=True):
        assert re.search(reason, detail), detail
        assert len(detail) < 400 and "\n" not in detail
    # The run goes on: each such problem is invalid input, the command ends with status 1.
    from sahgrasp.cli import main

    path = _targets(tmp_path, *meshes[:5])
    assert main(["solve", str(path), "--json", str(tmp_path / "out.json")]) == 1
    results = json.loads((tmp_path / "out.json").read_text())["results"]
    assert [r["reason"] for r in results] == ["invalid_input"] * 5
    assert "loop of symbolic links" in results[0]["detail"]


def test_a_byte_order_mark_is_skipped_in_json_and_json_lines(tmp_path: Path) -> None:
    from sahgrasp.ik.stream import open_targets
    from sahgrasp.objects.targets import problem_from_line

    line = json.dumps({"name": "bom", "contacts": CONTACTS}).encode()
    found = problem_from_line(b"\xef\xbb\xbf" + line, 0)
    assert isinstance(found, GraspTarget) and found.name == "bom"
    (tmp_path / "t.jsonl").write_bytes(b"\xef\xbb\xbf" + line + b"\n" + line + b"\n")
    read = list(open_targets(tmp_path / "t.jsonl").problems)
    assert all(isinstance(p, GraspTarget) for p in read), read
    document = json.dumps({"hand": "sah", "problems": [json.loads(line)]}).encode()
    (tmp_path / "t.json").write_bytes(b"\xef\xbb\xbf" + document)
    assert isinstance(read_problems(tmp_path / "t.json")[1][0], GraspTarget)


def test_json_lines_targets_confine_mesh_paths_too(tmp_path: Path) -> None:
    from sahgrasp.ik.stream import open_targets

    lines = [{"hand": "sah"}, {"contacts": CONTACTS, "object": {"mesh": str(MUG)}}]
    path = tmp_path / "t.jsonl"
    path.write_text("".join(json.dumps(line) + "\n" for line in lines))
    (refused,) = open_targets(path).problems
    assert isinstance(refused, InvalidProblem) and "outside" in refused.detail
    (allowed,) = open_targets(path, allow_outside_paths=True).problems
    assert isinstance(allowed, GraspTarget) and allowed.object_spec is not None


# --- The object's scale, one build per mesh file ------------------------------------------


def test_a_mesh_object_takes_its_unit_as_scale(tmp_path: Path) -> None:
    import trimesh

    from sahgrasp.objects.targets import object_spec

    trimesh.creation.box((50.0, 40.0, 30.0)).export(tmp_path / "box_mm.stl")
    spec = object_spec({"mesh": "box_mm.stl", "scale": 0.001}, tmp_path)
    assert spec is not None and spec.scale == 0.001
    assert object_spec(spec.to_dict(), tmp_path) == spec
    box = build_object(spec)
    assert np.ptp(box.mesh().vertices_m, axis=0) == pytest.approx([0.05, 0.04, 0.03])
    for bad in (0, -1e-3, "0.001", True, 1e400, [1]):
        with pytest.raises(InvalidTargetError, match="'scale' must be"):
            object_spec({"mesh": "box_mm.stl", "scale": bad}, tmp_path)
    with pytest.raises(InvalidTargetError, match="catalog object"):
        object_spec({"name": "can", "scale": 0.001}, tmp_path)


def test_placements_of_one_mesh_share_one_build(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import shutil

    import sahgrasp.objects as objects
    from sahgrasp.ik.batch import worker_obstacle
    from sahgrasp.objects.targets import ObjectCache, object_spec

    shutil.copy(MUG, tmp_path / "mug.stl")
    loads = []
    real = objects.load_mesh
    monkeypatch.setattr(objects, "load_mesh", lambda *a, **k: loads.append(a) or real(*a, **k))
    specs = [object_spec({"mesh": "mug.stl", "xyz": [0.1 * i, 0, 0]}, tmp_path) for i in range(3)]
    cache = ObjectCache(size=2)
    placed = [build_object(spec, cache) for spec in specs if spec is not None]
    assert len(loads) == 1 and len({id(o.solids[0]) for o in placed}) == 1
    assert [o.T_world_object[0, 3] for o in placed] == pytest.approx([0.0, 0.1, 0.2])
    can = object_spec({"name": "can"}, tmp_path)
    cup = object_spec({"name": "cup"}, tmp_path)
    assert can is not None and cup is not None
    build_object(can, cache), build_object(cup, cache)
    assert len(cache) == 2  # bounded: the mug was dropped
    build_object(specs[0], cache)  # type: ignore[arg-type]
    assert len(loads) == 2
    # A worker solving problems of new placements builds the mesh once too.
    loads.clear()
    moved = [object_spec({"mesh": "mug.stl", "xyz": [0, 0.1 * i, 0]}, tmp_path) for i in (1, 2)]
    first, second = (worker_obstacle(s, s.key()) for s in moved if s is not None)
    assert len(loads) <= 1 and first.solids[0] is second.solids[0]  # type: ignore[union-attr]
    with pytest.raises(InvalidTargetError, match="size"):
        ObjectCache(size=0)


def test_saved_targets_name_meshes_relative_to_their_folder(tmp_path: Path) -> None:
    import shutil

    from sahgrasp.objects.targets import object_spec

    shutil.copy(MUG, tmp_path / "mug.stl")
    spec = object_spec({"mesh": "mug.stl", "scale": 1.0}, tmp_path)
    problem = GraspTarget("p", [ContactTarget(**c) for c in CONTACTS], spec)
    save_targets(tmp_path / "saved.json", "sah", [problem])
    saved = json.loads((tmp_path / "saved.json").read_text())
    assert saved["problems"][0]["object"]["mesh"] == "mug.stl"
    assert load_targets(tmp_path / "saved.json").problems == (problem,)
    assert spec is not None and spec.to_dict(relative_to=tmp_path.parent)["mesh"].endswith(
        f"{tmp_path.name}/mug.stl"
    )
    (tmp_path / "elsewhere").mkdir()
    save_targets(tmp_path / "elsewhere" / "saved.json", "sah", [problem])  # the mesh is outside
    saved = json.loads((tmp_path / "elsewhere" / "saved.json").read_text())
    assert saved["problems"][0]["object"]["mesh"] == str(tmp_path / "mug.stl")


# --- Contacts for a subset of the fingers ---------------------------------------------------


def test_a_three_finger_can_grasp_of_the_atlas_paper_solves_from_a_targets_file(
    tmp_path: Path, sah: Hand
) -> None:
    """The can grasp (thumb, index, middle) as a targets file: the ring finger is free, clear."""
    from sahgrasp.ik.batch import solve_many
    from sahgrasp.objects import HandObjectClearance, can_patches, load_object

    grasp = can_patches().target()
    assert grasp.fingers == ("thumb", "index", "middle")
    document = {"hand": "sah", "object": {"name": "can"}, "problems": [grasp.to_dict()]}
    path = _write(tmp_path, document)
    targets = load_targets(path)
    (problem,) = targets.problems
    assert problem.free_fingers(sah.fingers) == ("ring",)
    (result,) = solve_many(sah, list(targets.problems))
    assert result.success and result.collision_free, result.reason
    assert result.fingers == ("thumb", "index", "middle")
    can = load_object("can")
    checker = HandObjectClearance(sah, can)
    clearance = checker.clearance(result.q, contacts=grasp.fingers)
    assert clearance.clear()  # no link inside the can, the contact tips within d_min
    ring = [d for link, d in clearance.links_m.items() if link.startswith("ring")]
    assert ring and min(ring) > 0.0  # the free finger keeps off the can
    assert checker.place_free_fingers(result.q, ("ring",)).clear  # and off the other links
