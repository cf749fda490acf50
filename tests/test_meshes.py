"""Objects from mesh files (sahgrasp.objects.mesh_file): the shipped meshes, repairs, bad files."""

from __future__ import annotations

import importlib.util
import re
import tempfile
from pathlib import Path
from types import ModuleType

import coal
import numpy as np
import pinocchio as pin
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from sahgrasp.core.errors import SahGraspError
from sahgrasp.ik import solve_ik
from sahgrasp.model.hand import Hand
from sahgrasp.objects import MeshFileError, load_mesh

MESHES = Path(__file__).resolve().parents[1] / "examples" / "meshes"


@pytest.fixture(scope="module", params=["mug.stl", "bottle.obj"])
def shipped(request: pytest.FixtureRequest) -> Path:
    return MESHES / str(request.param)


def _box_file(tmp_path: Path, name: str, mesh: trimesh.Trimesh | None = None) -> Path:
    path = tmp_path / name
    (trimesh.creation.box((0.05, 0.04, 0.03)) if mesh is None else mesh).export(path)
    return path


@pytest.mark.slow
def test_shipped_meshes_are_small_and_closed(shipped: Path) -> None:
    assert shipped.stat().st_size < 200_000
    obj = load_mesh(shipped)
    solid = obj.solids[0]
    assert solid.trimesh.is_watertight and solid.trimesh.volume > 0
    assert 0 < len(obj.collision_shapes()) < len(solid.faces)  # joined prisms (test_objects_pieces)
    assert obj.mesh().faces.shape == solid.faces.shape


@pytest.mark.slow
def test_signed_distance_matches_the_mesh(shipped: Path) -> None:
    """Outside: the distance to the triangles; inside: negative (checked with trimesh)."""
    obj = load_mesh(shipped)
    surface = obj.solids[0].trimesh
    rng = np.random.default_rng(0)
    points = rng.uniform(surface.bounds[0] - 0.01, surface.bounds[1] + 0.01, (300, 3))
    expected = -trimesh.proximity.signed_distance(surface, points)  # trimesh: positive inside
    ours = obj.signed_distance(points)
    outside = expected > 0
    assert outside.sum() > 50 and (~outside).sum() > 10
    assert np.abs(ours[outside] - expected[outside]).max() < 0.2e-3
    assert (ours[~outside] < 0).all()


def test_surface_samples_lie_on_the_surface_with_outward_normals(shipped: Path) -> None:
    solid = load_mesh(shipped).solids[0]
    points, normals = solid.sample_surface(200, seed=1)
    assert np.abs(trimesh.proximity.signed_distance(solid.trimesh, points)).max() < 1e-9
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)
    outside = trimesh.proximity.signed_distance(solid.trimesh, points + 1e-3 * normals)
    assert (outside < 0).mean() > 0.95  # off an edge the normal of one face can point inside
    nearest, at = solid.nearest_surface(points + 2e-4 * normals)
    back = np.all(np.isclose(nearest, points, atol=1e-6), axis=1) & np.all(at == normals, axis=1)
    assert back.mean() > 0.95  # near an edge or the rim another face can be as near


def test_hull_is_one_piece_and_units_are_checked(tmp_path: Path) -> None:
    path = _box_file(tmp_path, "box.ply")
    assert len(load_mesh(path, collision="hull").collision_shapes()) == 1
    millimetres = trimesh.creation.box((50.0, 40.0, 30.0))
    path = _box_file(tmp_path, "box_mm.stl", millimetres)
    with pytest.raises(MeshFileError, match="scale=1e-3"):
        load_mesh(path)
    box = load_mesh(path, scale=1e-3, T_world_object=np.diag([1.0, 1.0, 1.0, 1.0]))
    assert np.ptp(box.mesh().vertices_m, axis=0) == pytest.approx([0.05, 0.04, 0.03])
    with pytest.raises(MeshFileError, match="collision geometry"):
        load_mesh(path, scale=1e-3, collision="bvh")
    with pytest.raises(MeshFileError, match="scale"):
        load_mesh(path, scale=-1.0)


def test_repairs_are_made_and_reported(tmp_path: Path) -> None:
    box = trimesh.creation.box((0.05, 0.04, 0.03))
    faces = np.vstack([box.faces[:-1][:, ::-1], box.faces[:1]])  # inside-out, a hole, a duplicate
    degenerate = np.array([[0, 0, 1]])
    broken = trimesh.Trimesh(box.vertices, np.vstack([faces, degenerate]), process=False)
    obj = load_mesh(_box_file(tmp_path, "broken.obj", broken))
    repairs = " ".join(obj.solids[0].repairs)
    for what in ("degenerate or duplicate", "filled holes", "outward"):
        assert what in repairs
    assert obj.solids[0].trimesh.volume == pytest.approx(0.05 * 0.04 * 0.03)
    assert obj.repairs == obj.solids[0].repairs  # what the object reports (a planner's output)


BOX_M3 = 0.05 * 0.04 * 0.03


def _box(offset: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> trimesh.Trimesh:
    box = trimesh.creation.box((0.05, 0.04, 0.03))
    box.apply_translation(offset)
    return box


def test_meshes_as_users_have_them_are_repaired_and_say_how(tmp_path: Path) -> None:
    """Several bodies, inconsistent winding, duplicate vertices, a triangular hole."""
    far = _box((0.1, 0.0, 0.0))
    two = trimesh.Trimesh(  # the second body inside out
        np.vstack([_box().vertices, far.vertices]),
        np.vstack([_box().faces, far.faces[:, ::-1] + 8]),
        process=False,
    )
    faces = _box().faces.copy()
    faces[:3] = faces[:3, ::-1]
    mixed = trimesh.Trimesh(_box().vertices, faces, process=False)
    soup = trimesh.Trimesh(_box().triangles.reshape(-1, 3), np.arange(36).reshape(-1, 3))
    holed = trimesh.Trimesh(_box().vertices, _box().faces[1:], process=False)
    cases = {
        "two.obj": (two, ["2 separate bodies", "outward"], 2 * BOX_M3),
        "mixed.ply": (mixed, ["flipped 3 of 12 triangles to face outward"], BOX_M3),
        "soup.stl": (soup, ["merged 28 duplicate vertices"], BOX_M3),
        "holed.stl": (holed, ["filled holes"], BOX_M3),
    }
    for name, (mesh, said, volume) in cases.items():
        solid = load_mesh(_box_file(tmp_path, name, mesh)).solids[0]
        for words in said:
            assert any(words in repair for repair in solid.repairs), (name, solid.repairs)
        assert solid.trimesh.is_watertight and solid.trimesh.is_winding_consistent
        assert solid.trimesh.volume == pytest.approx(volume), name


def _one_line(error: pytest.ExceptionInfo[MeshFileError]) -> str:
    message = str(error.value)
    assert "\n" not in message and len(message) < 600
    return message


def test_meshes_that_cannot_be_solids_are_refused_with_what_is_wrong(tmp_path: Path) -> None:
    sphere = trimesh.creation.icosphere(2, 0.04)
    cap = trimesh.Trimesh(sphere.vertices, sphere.faces[sphere.triangles_center[:, 2] < 0.03])
    with pytest.raises(MeshFileError) as open_error:
        load_mesh(_box_file(tmp_path, "cap.stl", cap))
    message = _one_line(open_error)
    assert re.search(
        r"it is open: \d+ edges bound one triangle only, in 1 hole, the largest", message
    )
    assert "closed surface" in message
    touching = trimesh.util.concatenate([_box(), _box((0.05, 0.04, 0.0))])  # along an edge
    touching.merge_vertices()
    with pytest.raises(MeshFileError) as manifold_error:
        load_mesh(_box_file(tmp_path, "touching.stl", touching))
    message = _one_line(manifold_error)
    assert "not a manifold surface: 1 edge shared by more than two triangles" in message
    assert "0 edges" not in message


def test_a_file_in_millimetres_is_refused_unless_its_scale_is_given(tmp_path: Path) -> None:
    path = _box_file(tmp_path, "mm.stl", trimesh.creation.box((50.0, 40.0, 30.0)))
    with pytest.raises(MeshFileError, match=r"millimetres.*scale=1e-3.*\"scale\": 0.001"):
        load_mesh(path)
    assert load_mesh(path, scale=1e-3).solids[0].trimesh.volume == pytest.approx(BOX_M3)
    for scale in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(MeshFileError, match="scale must be a finite factor > 0"):
            load_mesh(path, scale=scale)


@pytest.fixture
def no_parsing(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail the test if trimesh is asked to parse a file."""

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("the file was parsed")

    monkeypatch.setattr(trimesh, "load", refuse)


def test_sizes_are_checked_before_parsing(tmp_path: Path, no_parsing: None) -> None:
    """A 65 MB STL of 1.3 million triangles is refused unread (a sparse file, no disk used)."""
    big = tmp_path / "big.stl"
    with big.open("wb") as f:
        f.write(b"\0" * 80 + (1_300_000).to_bytes(4, "little"))
        f.truncate(84 + 50 * 1_300_000)
    with pytest.raises(MeshFileError, match=r"holds 65000084 bytes, more than .* it was not read"):
        load_mesh(big)
    box = _box()
    stated = {"box.stl": 12, "box.ply": 12, "box.obj": 12}
    for name, faces in stated.items():
        path = _box_file(tmp_path, name, box)
        with pytest.raises(MeshFileError, match=f"declares {faces} triangles, more than max_faces"):
            load_mesh(path, max_faces=10)
    ascii_stl = tmp_path / "ascii.stl"
    ascii_stl.write_bytes(trimesh.exchange.stl.export_stl_ascii(box).encode())
    with pytest.raises(MeshFileError, match="declares 12 triangles"):
        load_mesh(ascii_stl, max_faces=11)


def test_mesh_paths_that_name_no_file_are_refused_in_one_line(tmp_path: Path) -> None:
    import os

    (tmp_path / "loop1.stl").symlink_to(tmp_path / "loop2.stl")
    (tmp_path / "loop2.stl").symlink_to(tmp_path / "loop1.stl")
    os.mkfifo(tmp_path / "pipe.stl")  # reading it would block
    cases = {
        "loop1.stl": "loop of symbolic links",
        "a\0b.stl": "not a valid file name",
        "p" * 5000 + ".stl": "too long",
        "pipe.stl": "not a regular file",
    }
    for name, reason in cases.items():
        with pytest.raises(MeshFileError, match=reason) as error:
            load_mesh(tmp_path / name)
        assert len(_one_line(error)) < 400
    for path in (None, "", 3):
        with pytest.raises(MeshFileError, match="path must be the path of an STL, OBJ or PLY"):
            load_mesh(path)  # type: ignore[arg-type]
    with pytest.raises(MeshFileError, match="max_faces must be an integer >= 1"):
        load_mesh(tmp_path / "pipe.stl", max_faces=0)


def _bad_files(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    tube = trimesh.creation.cylinder(0.03, 0.1, sections=24)
    tube = trimesh.Trimesh(tube.vertices, tube.faces[np.abs(tube.face_normals[:, 2]) < 0.5])
    (tmp_path / "empty.stl").write_bytes(b"")
    (tmp_path / "garbage.obj").write_text("this is not a mesh\n")
    (tmp_path / "nan.obj").write_text("v nan 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n")
    (tmp_path / "points.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n"
    )
    (tmp_path / "box.step").write_text("ISO-10303-21;")
    flat = trimesh.Trimesh([[0, 0, 0], [0.05, 0, 0], [0, 0.05, 0]], [[0, 1, 2], [0, 2, 1]])
    return {
        "missing": (tmp_path / "missing.stl", "not found"),
        "suffix": (tmp_path / "box.step", "unsupported"),
        "empty": (tmp_path / "empty.stl", "no triangles|not a readable"),
        "garbage": (tmp_path / "garbage.obj", "no triangles|not a readable"),
        "nan": (tmp_path / "nan.obj", "NaN"),
        "points": (tmp_path / "points.ply", "no triangles|not a readable"),
        "open": (_box_file(tmp_path, "tube.stl", tube), "it is open: 48 edges .* in 2 holes"),
        "flat": (_box_file(tmp_path, "flat.stl", flat), "is open|manifold|no volume|flat"),
    }


@pytest.mark.parametrize(
    "case", ["missing", "suffix", "empty", "garbage", "nan", "points", "open", "flat"]
)
def test_bad_files_get_a_typed_error(tmp_path: Path, case: str) -> None:
    path, message = _bad_files(tmp_path)[case]
    with pytest.raises(MeshFileError, match=message) as info:
        load_mesh(path)
    assert isinstance(info.value, SahGraspError)


def test_too_many_triangles_is_refused(shipped: Path) -> None:
    with pytest.raises(MeshFileError, match=r"max_faces = 100 .*decimate"):
        load_mesh(shipped, max_faces=100)


def _example() -> ModuleType:
    path = MESHES.parent / "grasp_mesh.py"
    spec = importlib.util.spec_from_file_location("example_grasp_mesh", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_mesh_example_solves_a_clear_grasp(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "mesh.html"
    assert _example().main(["--html", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "IK: solved" in printed and "clear of the object" in printed
    assert "MeshCat.Viewer" in out.read_text(encoding="utf-8")


@pytest.mark.slow
def test_mesh_example_grasp_checked_with_coal(sah: Hand) -> None:
    """The example's grasp, re-checked link by link with coal against the mug's prisms."""
    obj = load_mesh(MESHES / "mug.stl")
    target = _example().side_grasp(obj.solids[0], "mug")
    result = solve_ik(sah, target, obstacle=obj)  # as the example solves it
    assert result.success
    gm = sah.collision.geometry_model
    gd = pin.GeometryData(gm)
    pin.updateGeometryPlacements(sah.model, sah.model.createData(), gm, gd, result.q)
    tips = {f.tip_link for f in sah.description.fingers}
    pieces = [(s.geometry, s.transform(obj.T_world_object)) for s in obj.collision_shapes()]
    for i, geometry in enumerate(gm.geometryObjects):
        link = sah.model.frames[geometry.parentFrame].name
        at = coal.Transform3s(gd.oMg[i].rotation, gd.oMg[i].translation)
        nearest = min(
            coal.distance(
                p, T, geometry.geometry, at, coal.DistanceRequest(), coal.DistanceResult()
            )
            for p, T in pieces
        )
        assert nearest >= (-1.5e-3 if link in tips else -0.2e-3), link


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    suffix=st.sampled_from([".stl", ".obj", ".ply"]),
    head=st.sampled_from([b"", b"solid x\n", b"ply\nformat ascii 1.0\n", b"v 0 0 0\nf 1 1 1\n"]),
    payload=st.binary(max_size=300),
)
def test_random_bytes_give_a_mesh_or_a_typed_error(
    suffix: str, head: bytes, payload: bytes
) -> None:
    """Whatever a mesh file holds: an object or a one-line MeshFileError, never another error."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"random{suffix}"
        path.write_bytes(head + payload)
        try:
            load_mesh(path, max_faces=200)
        except MeshFileError as exc:
            assert "\n" not in str(exc) and len(str(exc)) < 800
