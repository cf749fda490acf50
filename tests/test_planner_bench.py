"""``sahgrasp bench plan``: its document, its table and its command."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import trimesh

from sahgrasp.bench import plan as bench_plan
from sahgrasp.bench.report import summary_table
from sahgrasp.cli import main


@pytest.mark.slow
def test_bench_plan_document_and_table(tmp_path: Path) -> None:
    box = tmp_path / "box.stl"
    trimesh.creation.box(extents=(0.05, 0.06, 0.08)).export(box)
    doc = bench_plan.run(objects=["can"], meshes=[str(box)], test_meshes=False, candidates=4,
                         grasps=2, workers=(), atlas=False, quiet=True, commands=False)  # fmt: skip
    assert doc["benchmark"] == "plan"
    assert [r["object"] for r in doc["objects"]] == ["can", "box.stl"]
    assert doc["summary"]["returned_failing_recheck"] == 0
    for row in doc["objects"]:
        assert row["candidates"] == 4 and row["verified"] <= 4
        assert 0.0 <= row["force_closure_share"] <= 1.0
    table = summary_table(doc)
    assert "bench plan: sah, 2 objects" in table and "re-check fails" in table
    verified = [r["verify_physics"] for r in doc["objects"]]
    if verified[0] is None:  # without MuJoCo
        return
    for v in verified:
        # Batches of 4 candidates up to 4 x 4, only while fewer than 2 grasps hold.
        assert v["candidates"] in (4, 8, 12, 16) and v["max_candidates"] == 16
        assert v["returned"] == 2 or v["candidates"] == 16
        assert v["returned_first_batch"] <= v["returned"] <= v["hold_passed"] <= v["hold_checked"]
        assert v["dexgraspbench"]["checked"] == v["returned"] == len(v["margins"])
        assert all(0.0 < m <= 1.0 for m in v["margins"])
        assert (v["time_to_first_hold_s"] is None) == (v["returned"] == 0)
    summary = doc["summary"]["verify_physics"]
    assert summary["returned"] == sum(v["returned"] for v in verified)
    assert "plan --verify physics: objects with 2 holding grasps" in table


def test_test_meshes_are_graspable_sizes(tmp_path: Path) -> None:
    scales = bench_plan.write_test_meshes(tmp_path)
    assert sorted(scales) == sorted(bench_plan.TEST_MESHES)
    for name, scale in scales.items():
        mesh = trimesh.load(tmp_path / name, force="mesh")
        extent = float(max(mesh.extents)) * scale
        assert 0.04 <= extent <= 0.15 + 1e-6, (name, extent)  # float32 STL coordinates
        assert mesh.is_watertight, name


@pytest.mark.slow
def test_bench_plan_command_writes_json(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "bench.json"
    argv = ["bench", "plan", "--objects", "bottle", "--no-test-meshes", "--mesh",
            str(Path(__file__).resolve().parent.parent / "examples" / "meshes" / "bottle.obj"),
            "--candidates", "3", "--grasps", "1", "--workers", "--no-atlas", "--no-commands",
            "--quiet", "--json", str(out)]  # fmt: skip
    assert main(argv) == 0
    assert json.loads(out.read_text())["summary"]["objects"] == 2
    assert "objects with a verified force-closure grasp" in capsys.readouterr().out


@pytest.mark.slow
def test_bench_plan_times_the_command_from_its_process_start(tmp_path: Path) -> None:
    doc = bench_plan.run(objects=["can"], test_meshes=False, meshes=[], candidates=6, grasps=1,
                         workers=(), atlas=False, quiet=True)  # fmt: skip
    can = doc["objects"][0]
    assert "command_error" not in can
    # The same plan (same settings and seed) in a fresh process, which also starts up.
    assert can["time_to_first_s"] is not None and can["command_time_to_first_s"] is not None
    assert can["command_time_to_first_s"] > can["time_to_first_s"]
    assert can["command_s"] > can["command_time_to_first_s"]
