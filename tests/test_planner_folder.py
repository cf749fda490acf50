"""Planning a folder of meshes: JSON Lines, the same on 1 and 2 workers, resumed after a kill."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import trimesh
from polling import until

from sahgrasp.cli import main


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("objects")
    trimesh.creation.box(extents=(0.05, 0.06, 0.08)).export(root / "a_box.stl")
    trimesh.creation.cylinder(radius=0.03, height=0.1, sections=40).export(root / "b_cyl.stl")
    trimesh.creation.icosphere(subdivisions=2, radius=0.035).export(root / "c_ball.ply")
    (root / "notes.txt").write_text("not a mesh\n")
    return root


def _documents(path: Path) -> list[dict[str, Any]]:
    lines = path.read_text().splitlines()
    assert json.loads(lines[0])["format"]  # the header
    return [json.loads(line) for line in lines[1:]]


def _without_times(doc: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in doc.items() if k != "summary"}


ARGS = ["--candidates", "4", "--grasps", "2", "--quiet"]


@pytest.mark.slow
def test_folder_is_the_same_on_one_and_two_workers(folder: Path, tmp_path: Path) -> None:
    one, two = tmp_path / "one.jsonl", tmp_path / "two.jsonl"
    assert main(["plan", str(folder), "--json", str(one), *ARGS]) == 0
    assert main(["plan", str(folder), "--json", str(two), "--workers", "2", *ARGS]) == 0
    a, b = _documents(one), _documents(two)
    assert [d["object"]["mesh"] for d in a] == sorted(str(p) for p in folder.glob("*.[sp]*"))
    assert [_without_times(d) for d in a] == [_without_times(d) for d in b]
    assert all(d["grasps"] for d in a)


@pytest.fixture(scope="module")
def slow_middle(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Three meshes whose second takes seconds to plan: a kill after the first is not a race."""
    root = tmp_path_factory.mktemp("slow_middle")
    trimesh.creation.box(extents=(0.05, 0.06, 0.08)).export(root / "a_box.stl")
    torus = trimesh.creation.torus(0.045, 0.015, major_sections=160, minor_sections=60)
    torus.export(root / "b_torus.obj")  # 19,200 triangles
    trimesh.creation.icosphere(subdivisions=2, radius=0.035).export(root / "c_ball.ply")
    return root


@pytest.mark.slow
def test_folder_resumed_after_a_kill_gives_the_same_documents(
    slow_middle: Path, tmp_path: Path
) -> None:
    # One worker plans the files in name order: the header and the box's document are written
    # while the torus is still being planned, seconds before the run could end.
    folder = slow_middle
    whole = tmp_path / "whole.jsonl"
    assert main(["plan", str(folder), "--json", str(whole), *ARGS]) == 0
    out = tmp_path / "cut.jsonl"
    part = Path(str(out) + ".part")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    process = subprocess.Popen(
        [sys.executable, "-m", "sahgrasp", "plan", str(folder), "--json", str(out), *ARGS],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        assert until(lambda: part.exists() and len(part.read_text().splitlines()) >= 2, 120)
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    before = part.read_text().splitlines()
    assert not out.exists() and len(before) < 4  # stopped before the end
    assert main(["plan", str(folder), "--json", str(out), "--resume", *ARGS]) == 0
    after = out.read_text().splitlines()
    assert after[: len(before)] == before  # the finished objects were kept, not planned again
    assert [_without_times(d) for d in _documents(out)] == [
        _without_times(d) for d in _documents(whole)
    ]


def test_folder_needs_json_lines(folder: Path, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    assert main(["plan", str(folder), "--json", str(tmp_path / "x.json"), *ARGS]) == 2
    assert "JSON Lines" in capsys.readouterr().err


def test_folder_with_a_broken_mesh_reports_it_and_exits_1(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    trimesh.creation.box(extents=(0.05, 0.06, 0.08)).export(tmp_path / "good.stl")
    (tmp_path / "bad.stl").write_text("solid nothing\nendsolid nothing\n")
    out = tmp_path / "out.jsonl"
    assert main(["plan", str(tmp_path), "--json", str(out), *ARGS]) == 1
    docs = _documents(out)
    assert "error" in docs[0] and docs[0]["object"]["mesh"].endswith("bad.stl")
    assert docs[1]["grasps"]
    assert "bad.stl: refused" in capsys.readouterr().err
