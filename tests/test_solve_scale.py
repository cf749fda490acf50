"""``sahgrasp solve`` at scale: JSON Lines, resume after a kill, workers and Dask, objects."""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sahgrasp.ik import IKResult, IKSettings, random_problems, solve_many
from sahgrasp.model.contacts import ContactTarget, GraspTarget
from sahgrasp.model.hand import Hand, load_hand

psutil = pytest.importorskip("psutil")

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
MUG = ROOT / "examples" / "meshes" / "mug.stl"
SEED = 4141
PROBLEMS = 2000
"""Problems of the targets file (the issue's kill-and-resume test is on 2,000)."""
INVALID = 2 * PROBLEMS // 100
"""Malformed lines among them: two in every 100 problems."""
"""Seed of this file's random problems (used nowhere else)."""


def sahgrasp(*args: Any, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "sahgrasp", *map(str, args)], cwd=cwd, env=ENV,
        capture_output=True, encoding="utf-8", timeout=300,
    )  # fmt: skip


def start(*args: Any, cwd: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "sahgrasp", *map(str, args)], cwd=cwd, env=ENV,
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, encoding="utf-8",
    )  # fmt: skip


def lines(path: Path) -> list[dict[str, Any]]:
    """A results file's lines without their timings (the only part that may differ)."""
    out = [json.loads(line) for line in path.read_text().splitlines()]
    for entry in out:
        entry.pop("time_ms", None)
        entry.pop("setup_ms", None)
    return out


@pytest.fixture(scope="module")
def hand() -> Hand:
    return load_hand("sah")


@pytest.fixture(scope="module")
def problems(hand: Hand) -> list[GraspTarget]:
    return random_problems(hand, PROBLEMS, seed=SEED)


@pytest.fixture(scope="module")
def targets(problems: list[GraspTarget], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The problems as JSON Lines, with a header line and malformed lines among them."""
    path = tmp_path_factory.mktemp("scale") / "targets.jsonl"
    rows = [json.dumps({"hand": "sah"})]
    for i, p in enumerate(problems):
        rows.append(json.dumps(p.to_dict()))
        if i % 100 == 7:
            rows += ["{not json", '{"name": "empty", "contacts": []}']
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.fixture(scope="module")
def reference(targets: Path) -> Path:
    """The uninterrupted run, on one worker."""
    out = targets.parent / "reference.jsonl"
    done = sahgrasp("solve", targets, "--json", out, "--quiet", cwd=targets.parent)
    assert done.returncode in (0, 1), done.stderr
    return out


@pytest.mark.slow
def test_a_killed_run_resumes_to_the_uninterrupted_output(targets: Path, reference: Path) -> None:
    out = targets.parent / "killed.jsonl"
    part = out.with_name(out.name + ".part")
    process = start("solve", targets, "--workers", "2", "--json", out, cwd=targets.parent)
    # Results written before the kill: at most half of them, so that the kill lands well before
    # the run's end however fast the solves are (near the end, 2 workers finish the last lines
    # within the polling interval, and the run is done before it is killed).
    stop_after = random.Random().randint(20, PROBLEMS // 2)
    deadline = time.monotonic() + 240
    while not (part.exists() and part.read_bytes().count(b"\n") > stop_after):
        assert process.poll() is None and time.monotonic() < deadline, process.stderr
        time.sleep(0.02)
    process.kill()
    process.wait()
    assert not out.exists()
    with part.open("ab") as stream:  # as if the kill had cut a line in the middle
        stream.write(b'{"name": "cut')
    done = sahgrasp("solve", targets, "--json", out, "--resume", cwd=targets.parent)
    assert done.returncode in (0, 1), done.stderr
    assert lines(out) == lines(reference)
    assert not part.exists()
    resumed = int(done.stdout.split(" resumed")[0].rsplit(" ", 1)[1])
    assert stop_after <= resumed < PROBLEMS + INVALID


def test_malformed_lines_get_invalid_input_in_order(reference: Path) -> None:
    entries = lines(reference)[1:]
    assert len(entries) == PROBLEMS + INVALID
    assert entries[8]["name"] == "problem-8" and "not a JSON value" in entries[8]["detail"]
    assert entries[9]["name"] == "empty" and "no contacts" in entries[9]["detail"]
    invalid = [e for e in entries if e["reason"] == "invalid_input"]
    assert len(invalid) == INVALID and all(e["joints"] is None for e in invalid)


def test_resume_refuses_an_output_of_other_settings(targets: Path, reference: Path) -> None:
    copy = targets.parent / "other.jsonl"
    shutil.copy(reference, copy)
    done = sahgrasp("solve", targets, "--json", copy, "--resume", "--inits", "3", cwd=copy.parent)
    assert done.returncode == 2
    assert "written with other settings (differing: settings)" in done.stderr
    assert lines(copy) == lines(reference)


def _same(a: list[IKResult], b: list[IKResult]) -> None:
    for x, y in zip(a, b, strict=True):
        assert (x.name, x.success, x.reason, x.inits_used, x.iterations) == (
            y.name, y.success, y.reason, y.inits_used, y.iterations
        )  # fmt: skip
        np.testing.assert_array_equal(x.q, y.q)


@pytest.mark.slow
def test_same_results_on_one_worker_two_workers_and_dask(
    hand: Hand, problems: list[GraspTarget]
) -> None:
    distributed = pytest.importorskip("dask.distributed")
    subset = problems[:20]
    settings = IKSettings(seed=3)
    one = solve_many(hand, subset, settings)
    _same(one, solve_many(hand, subset, settings, workers=2))
    with (
        distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True) as cluster,
        distributed.Client(cluster) as client,
    ):
        _same(one, solve_many(hand, subset, settings, executor=client))


@pytest.mark.slow
def test_a_killed_solve_leaves_no_worker(targets: Path) -> None:
    process = start("solve", targets, "--workers", "2", "--inits", "1000", cwd=targets.parent)
    for _ in range(600):
        workers = psutil.Process(process.pid).children(recursive=True)
        if len(workers) >= 2:
            break
        time.sleep(0.1)
    process.send_signal(signal.SIGKILL)
    process.wait()
    _, alive = psutil.wait_procs(workers, timeout=30)
    assert not [p for p in alive if p.status() != psutil.STATUS_ZOMBIE]


def _mug_grasp(xyz: list[float]) -> dict[str, Any]:
    """The shipped example's side grasp on the mug, with the mug moved by ``xyz``."""
    from sahgrasp.objects import load_mesh

    solid = load_mesh(MUG).solids[0]
    heights = {"thumb": 0.06, "index": 0.09, "middle": 0.06, "ring": 0.03}
    sides = {"thumb": -1.0, "index": 1.0, "middle": 1.0, "ring": 1.0}
    reach = np.array([[sides[f] * 0.5, 0.0, heights[f]] for f in heights])
    points, normals = solid.nearest_surface(reach)
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    contacts = [
        ContactTarget(f, p + xyz, n) for f, p, n in zip(heights, points, normals, strict=True)
    ]
    return {**GraspTarget("mug", contacts).to_dict(),
            "object": {"mesh": "meshes/mug.stl", "xyz": xyz, "quat": [0, 0, 0, 1]}}  # fmt: skip


@pytest.mark.slow
def test_targets_name_their_objects(tmp_path: Path) -> None:
    from sahgrasp.objects import paper_grasp

    (tmp_path / "meshes").mkdir()
    shutil.copy(MUG, tmp_path / "meshes" / "mug.stl")
    can = paper_grasp("can").to_dict()
    problems = [
        can,  # the file's default object
        _mug_grasp([0.1, -0.05, 0.02]),
        {**can, "name": "bad quat", "object": {"name": "can", "quat": [0, 0, 0, 2]}},
        {**can, "name": "no file", "object": {"mesh": "nothing.stl"}},
        {**can, "name": "both", "object": {"name": "can", "mesh": "m.stl"}},
        {**can, "name": "unknown", "object": {"name": "teapot"}},
    ]
    path = tmp_path / "objects.json"
    path.write_text(json.dumps({"hand": "sah", "object": {"name": "can"}, "problems": problems}))
    done = sahgrasp("solve", path, "--json", "out.json", cwd=tmp_path)
    assert done.returncode == 1, done.stderr
    results = json.loads((tmp_path / "out.json").read_text())["results"]
    assert [r["success"] for r in results[:2]] == [True, True]
    assert all(r["object_clearance_mm"] > -1.5 and r["closest_link"] for r in results[:2])
    details = [r["detail"] for r in results[2:]]
    assert "unit quaternion" in details[0] and "not found" in details[1]
    assert "either 'name'" in details[2] and "valid names are" in details[3]


def test_a_bad_default_object_is_a_one_line_error(tmp_path: Path) -> None:
    path = tmp_path / "t.jsonl"
    path.write_text(json.dumps({"hand": "sah", "object": {"name": "can", "xyz": [0, 0]}}) + "\n")
    done = sahgrasp("solve", path, cwd=tmp_path)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr.strip() == "sahgrasp: error: object 'xyz' must have 3 components [m], got 2"


def test_solve_many_takes_one_object_per_target(hand: Hand) -> None:
    from sahgrasp.core.errors import InvalidTargetError
    from sahgrasp.objects import load_object, paper_grasp

    can, grasp = load_object("can"), paper_grasp("can")
    with_can, alone = solve_many(hand, [grasp, grasp], obstacle=[can, None])
    assert with_can.object_clearance_m is not None and alone.object_clearance_m is None
    with pytest.raises(InvalidTargetError, match="1 objects for 2 targets"):
        solve_many(hand, [grasp, grasp], obstacle=[can])
    with pytest.raises(InvalidTargetError, match="obstacle must be a GraspObject"):
        solve_many(hand, [grasp], obstacle=["can"])  # type: ignore[list-item]
