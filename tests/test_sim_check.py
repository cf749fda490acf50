"""``sahgrasp check``: the hold test of a results file, its output and its input errors."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("mujoco")

from sahgrasp.ik import solve_ik
from sahgrasp.model.hand import load_hand
from sahgrasp.objects import paper_grasp
from sahgrasp.sim import HoldSettings
from sahgrasp.sim.batch import check_grasps, read_grasps

ROOT = Path(__file__).resolve().parents[1]


def sahgrasp(*args: object, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "sahgrasp", *map(str, args)],
        capture_output=True, encoding="utf-8", cwd=cwd,
        env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=300,
    )  # fmt: skip


def one_line_error(done: subprocess.CompletedProcess[str], pattern: str) -> None:
    assert "Traceback" not in done.stderr, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert re.search(pattern, lines[0]), lines[0]
    assert done.returncode == 2


def in_process(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, cwd: Path, *args: str
) -> subprocess.CompletedProcess[str]:
    """``sahgrasp ARGS`` run by this interpreter (no start-up cost), as a completed process."""
    from sahgrasp.cli import main

    monkeypatch.chdir(cwd)
    code = main(list(args))
    out, err = capsys.readouterr()
    return subprocess.CompletedProcess(list(args), code, out, err)


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``targets.json`` (the can grasp, and the can grasp 15 cm off) and ``results.json``."""
    folder = tmp_path_factory.mktemp("check")
    hand = load_hand("sah")
    can = paper_grasp("can").to_dict()
    result = solve_ik(hand, paper_grasp("can")).to_dict(hand)
    off = {**can, "name": "can off", "object": {"name": "can", "xyz": [0.0, 0.0, 0.15]}}
    targets = {"hand": "sah", "problems": [{**can, "object": {"name": "can"}}, off]}
    (folder / "targets.json").write_text(json.dumps(targets))
    (folder / "one.json").write_text(json.dumps({**targets, "problems": targets["problems"][:1]}))
    results = {"hand": "sah", "results": [result, {**result, "name": "can off"}]}
    (folder / "results.json").write_text(json.dumps(results))
    plan = {"object": {"name": "can"}, "grasps": [{"rank": 1, **result}]}
    (folder / "plan.json").write_text(json.dumps(plan))
    return folder


def test_check_reports_every_grasp_and_the_hold_rate(files: Path) -> None:
    done = sahgrasp("check", "targets.json", "results.json", "--json", "-", cwd=files)
    assert done.returncode == 1, done.stderr  # the can moved off its grasp does not hold
    document = json.loads(done.stdout)
    first, off = document["results"]
    assert first["name"] == "can" and first["holds"] and first["checked"]
    assert [d["direction"] for d in first["directions"]] == ["+x", "-x", "+y", "-y", "+z", "-z"]
    assert off["name"] == "can off" and not off["holds"] and off["reason"] == "no contact"
    summary = document["summary"]
    assert (summary["checked"], summary["holds"], summary["hold_rate"]) == (2, 1, 0.5)
    assert summary["objects"]["can"]["checked"] == 2
    assert document["settings"]["friction"] == 0.6
    assert "1/2 grasps hold" in done.stderr


def test_check_of_a_planners_results(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, files: Path
) -> None:
    done = in_process(capsys, monkeypatch, files, "check", "plan.json")
    assert done.returncode == 0, done.stderr
    assert "1/1 grasps hold" in done.stdout


@pytest.mark.slow
def test_planners_results_name_their_fingers_repairs_and_meshes(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, files: Path
) -> None:
    plan = json.loads((files / "plan.json").read_text())
    plan["object"]["repairs"] = ["merged 3 duplicate vertices"]  # a note, not a key
    plan["grasps"][0]["fingers"] = ["thumb", "index", "middle"]
    (files / "plan3.json").write_text(json.dumps(plan))
    done = in_process(capsys, monkeypatch, files, "check", "plan3.json", "--json", "-")
    entry = json.loads(done.stdout)["results"][0]
    assert entry["contact_fingers"] == ["thumb", "index", "middle"]
    # A planner names its mesh by an absolute path: outside the folder only when allowed.
    mug = {"mesh": str(ROOT / "examples" / "meshes" / "mug.stl")}
    (files / "mug.json").write_text(json.dumps({**plan, "object": mug}))
    one_line_error(in_process(capsys, monkeypatch, files, "check", "mug.json"), "outside")
    done = in_process(capsys, monkeypatch, files, "check", "mug.json", "--allow-any-mesh-path")
    assert done.returncode in (0, 1), done.stderr
    assert "grasps hold" in done.stdout


@pytest.mark.parametrize(
    ("args", "pattern"),
    [
        (["results.json"], r"holds no objects: give the targets file"),
        (["one.json", "results.json"], r"has 2 results but targets file .* has 1 problems"),
        (["plan.json", "results.json"], r"must be an object with 'hand' and a 'problems' list"),
        (["targets.json", "results.json", "--json", "targets.json"], r"input"),
        (["targets.json", "missing.json"], r"cannot read results file"),
        (["targets.json", "results.json", "--friction", "-1"], r"--friction"),
    ],
)
def test_check_input_errors(
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    files: Path,
    args: list[str],
    pattern: str,
) -> None:
    one_line_error(in_process(capsys, monkeypatch, files, "check", *args), pattern)


def test_mismatched_names_are_refused(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path, files: Path
) -> None:
    results = json.loads((files / "results.json").read_text())
    results["results"][1]["name"] = "other"
    (tmp_path / "results.json").write_text(json.dumps(results))
    (tmp_path / "targets.json").write_text((files / "targets.json").read_text())
    done = in_process(capsys, monkeypatch, tmp_path, "check", "targets.json", "results.json")
    one_line_error(done, r"result 1 is 'other' but problem 1 .* is 'can off'")


def test_a_mesh_named_in_the_targets_is_an_input(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path, files: Path
) -> None:
    mesh = tmp_path / "mug.stl"
    mesh.write_bytes((ROOT / "examples" / "meshes" / "mug.stl").read_bytes())
    targets = json.loads((files / "one.json").read_text())
    targets["problems"][0]["object"] = {"mesh": "mug.stl"}
    (tmp_path / "targets.json").write_text(json.dumps(targets))
    (tmp_path / "results.json").write_text((files / "results.json").read_text())
    args = ("check", "targets.json", "results.json", "--json", "mug.stl")
    one_line_error(in_process(capsys, monkeypatch, tmp_path, *args), r"input")
    assert mesh.read_bytes() == (ROOT / "examples" / "meshes" / "mug.stl").read_bytes()


def _light(files: Path) -> list[Any]:
    hand = load_hand("sah")
    grasps = read_grasps(hand, files / "results.json", files / "targets.json")
    return grasps


@pytest.mark.slow
def test_same_results_on_one_and_two_workers(files: Path) -> None:
    grasps = _light(files) * 9  # 18 grasps: chunks on both workers
    settings = HoldSettings(squeeze_n=1.0)
    one = check_grasps("sah", grasps, settings, workers=1)
    two = check_grasps("sah", grasps, settings, workers=2)
    strip = [{**r.to_dict(), "time_s": 0} for r in one if not isinstance(r, str)]
    assert strip == [{**r.to_dict(), "time_s": 0} for r in two if not isinstance(r, str)]


def test_without_mujoco_one_line_names_the_extra(tmp_path: Path) -> None:
    blocked = "import sys; sys.modules['mujoco'] = None; "
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    imported = subprocess.run(
        [sys.executable, "-c", blocked + "import sahgrasp; import sahgrasp.sim"],
        capture_output=True, text=True, env=env,
    )  # fmt: skip
    assert imported.returncode == 1
    assert 'pip install "sahgrasp[sim]"' in imported.stderr.strip().splitlines()[-1]
    run = "from sahgrasp.cli import main; sys.exit(main(['check', 't.json', 'r.json']))"
    done = subprocess.run(
        [sys.executable, "-c", blocked + run], capture_output=True, text=True, env=env,
        cwd=tmp_path,
    )  # fmt: skip
    one_line_error(done, r'needs MuJoCo: pip install "sahgrasp\[sim\]"')


def test_cli_defaults_are_the_library_defaults() -> None:
    from sahgrasp.cli import _parser
    from sahgrasp.cli.check import _settings

    args = _parser().parse_args(["check", "t.json", "r.json"])
    assert _settings(args) == HoldSettings()
    light = _parser().parse_args(["check", "t.json", "r.json", "--light"])
    assert _settings(light).squeeze_n == 1.0


def test_soft_friction_option_lets_friction_creep(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, files: Path
) -> None:
    from sahgrasp.cli import _parser
    from sahgrasp.cli.check import _settings
    from sahgrasp.sim import soft_friction

    args = _parser().parse_args(["check", "t.json", "r.json", "--soft-friction"])
    assert _settings(args) == soft_friction(HoldSettings())
    assert (_settings(args).impratio, _settings(args).noslip_iterations) == (1.0, 0)
    done = in_process(
        capsys, monkeypatch, files, "check", "plan.json", "--soft-friction", "--json", "-"
    )
    assert done.returncode in (0, 1), done.stderr
    document = json.loads(done.stdout)
    assert document["settings"]["noslip_iterations"] == 0
    assert document["settings"]["impratio"] == 1.0
