"""Every example script runs to completion in --html mode (small settings), leaving no process."""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import psutil
import pytest
from polling import gone, until

from sahgrasp.cli import demo, main
from sahgrasp.objects import paper_grasp
from sahgrasp.viz import scene_commands

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
GRASPS = ("fork", "cup", "buddha", "coffee_cup", "can")
SMALL_ATLAS = {
    "can": ("optimize_sah", ["can", "--max-charts", "40"]),
    "bottle": ("optimize_sah", ["bottle", "--max-charts", "40"]),
    "planar": ("optimize_planar", ["--r", "0.3"]),
}

LIVE_TIMEOUT_S = 60.0
"""How long a live viewer's processes may take to start or end [s]."""


def load(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def children() -> set[int]:
    return {p.pid for p in psutil.Process().children(recursive=True)}


def run_main(name: str, args: list[str], tmp_path: Path) -> set[str]:
    """Run an example's main with ``--html``; the scene paths it drew."""
    out = tmp_path / f"{name}.html"
    before = children()
    code = load(name).main([*args, "--html", str(out)])
    assert code == 0
    assert children() == before, "a process outlived the example"
    html = out.read_text(encoding="utf-8")
    assert "MeshCat.Viewer" in html
    return {command["path"] for command in scene_commands(html) if command["type"] == "set_object"}


def test_every_script_is_tested_and_listed_in_the_readme() -> None:
    scripts = {p.stem for p in EXAMPLES.glob("*.py")}
    mesh = {"grasp_mesh", "plan_mug"}  # run by tests/test_meshes.py and tests/test_planner.py
    printed = {"refine_mug"}  # prints, draws no scene; run by tests/test_mesh_atlas.py
    assert scripts == {"grasp_paper_object"} | {s for s, _ in SMALL_ATLAS.values()} | mesh | printed
    readme = (EXAMPLES / "README.md").read_text(encoding="utf-8")
    for name in scripts:
        assert f"{name}.py" in readme, f"examples/README.md lists no {name}.py"
    shots = {f"grasp_{g}" for g in GRASPS} | {f"optimize_{a}" for a in SMALL_ATLAS} | mesh
    for shot in shots:
        assert f"img/{shot}.png" in readme, f"README shows no screenshot {shot}"
        assert (EXAMPLES / "img" / f"{shot}.png").is_file(), f"no screenshot {shot}"


@pytest.mark.parametrize("grasp", GRASPS)
def test_grasp_example(grasp: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    drawn = run_main("grasp_paper_object", [grasp], tmp_path)
    printed = capsys.readouterr().out
    assert printed.splitlines()[0].startswith(f"{grasp}: solved (converged), 1 initial")
    assert "(paper " in printed and "initial configurations:" in printed
    assert "contact errors: thumb" in printed and "object clearance:" in printed
    assert {f"/meshcat/{grasp}/object", f"/meshcat/{grasp}/contacts/thumb/disk"} <= drawn
    assert any(p.startswith(f"/meshcat/{grasp}/hand/visuals/") for p in drawn)


@pytest.mark.parametrize("name", sorted(SMALL_ATLAS))
def test_optimize_example(name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    script, args = SMALL_ATLAS[name]
    drawn = run_main(script, args, tmp_path)
    printed = capsys.readouterr().out
    assert "charts" in printed and "best grasp: chart" in printed and "paper" in printed
    assert "valid:" in printed and "worst grasp: chart" in printed
    assert {"/meshcat/atlas/charts", "/meshcat/atlas/best", "/meshcat/atlas/worst"} <= drawn
    for extreme in ("best", "worst"):  # each extreme grasp drawn beside the atlas
        assert any(p.startswith(f"/meshcat/{extreme}/") for p in drawn)


@pytest.mark.slow
def test_an_example_runs_on_its_own(tmp_path: Path) -> None:
    out = tmp_path / "fork.html"
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / "grasp_paper_object.py"), "fork", "--inits", "2",
         "--html", str(out)],
        capture_output=True, text=True, timeout=120, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "fork" in done.stdout and out.stat().st_size > 100_000


def meshcat_servers(pid: int) -> list[psutil.Process]:
    found = []
    try:
        kids = psutil.Process(pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return []
    for kid in kids:
        try:
            if any("meshcat_server" in part for part in kid.cmdline()):
                found.append(kid)
        except psutil.Error:  # ended, or a zombie (the stand-in browser)
            continue
    return found


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_a_signal_on_a_live_example_stops_its_server(signum: int, tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(EXAMPLES.parent), "BROWSER": "true"}  # no real browser
    script = subprocess.Popen(
        [sys.executable, str(EXAMPLES / "grasp_paper_object.py"), "fork", "--inits", "2"],
        stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        env=env, cwd=tmp_path,
    )  # fmt: skip
    try:
        assert until(lambda: bool(meshcat_servers(script.pid)), LIVE_TIMEOUT_S), (
            "no live server started"
        )
        (server,) = meshcat_servers(script.pid)
        assert until(
            lambda: bool(server.net_connections()), LIVE_TIMEOUT_S
        )  # serving: the script waits for Enter
        script.send_signal(signum)
        assert (
            until(lambda: script.poll() is not None, LIVE_TIMEOUT_S)
            and script.returncode == -signum
        )
        assert until(lambda: gone(server), LIVE_TIMEOUT_S), (
            "the meshcat server outlived the example"
        )
    finally:
        script.kill()
        script.communicate(timeout=10)


def test_demo_writes_every_grasp_into_one_scene(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    parser = argparse.ArgumentParser()
    demo.add_parser(parser.add_subparsers())
    args = parser.parse_args(["demo"])
    monkeypatch.chdir(tmp_path)
    before = children()
    assert args.run(args) == 0
    assert children() == before
    printed = capsys.readouterr().out
    assert [line.split()[0] for line in printed.splitlines()[1:6]] == list(GRASPS)
    html = (tmp_path / demo.DEFAULT_HTML).read_text(encoding="utf-8")
    drawn = {command["path"] for command in scene_commands(html) if command["type"] == "set_object"}
    for grasp in GRASPS:
        assert {f"/meshcat/grasps/{grasp}/object",
                f"/meshcat/grasps/{grasp}/contacts/thumb/disk"} <= drawn  # fmt: skip
        assert any(p.startswith(f"/meshcat/grasps/{grasp}/hand/visuals/") for p in drawn)


def test_a_missing_mesh_file_is_one_usage_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as stop:
        load("grasp_mesh").main(
            ["--mesh", str(tmp_path / "none.stl"), "--html", str(tmp_path / "x.html")]
        )
    assert stop.value.code == 2
    assert "mesh file not found" in capsys.readouterr().err
    assert not (tmp_path / "x.html").exists()


def _targets_file(folder: Path, problems: list[dict[str, object]], **top: object) -> Path:
    path = folder / "targets.json"
    path.write_text(json.dumps({"hand": "sah", **top, "problems": problems}), encoding="utf-8")
    return path


def _placed_grasp(name: str, xyz: list[float], problem: str) -> dict[str, object]:
    T = np.eye(4)
    T[:3, 3] = xyz
    return {**paper_grasp(name, T).to_dict(), "name": problem}


def test_demo_draws_every_problem_of_a_targets_file_with_its_object(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The file's default object, a problem's own object and a problem without one."""
    can = {"name": "can", "xyz": [0.1, 0.0, 0.0], "quat": [0.0, 0.0, 0.0, 1.0]}
    fork = {"name": "fork", "xyz": [0.0, 0.2, 0.0], "quat": [0.0, 0.0, 0.0, 1.0]}
    problems = [
        _placed_grasp("can", can["xyz"], "can grasp"),
        {**_placed_grasp("fork", fork["xyz"], "fork/grasp"), "object": fork},
        {**_placed_grasp("fork", fork["xyz"], "bare"), "object": None},
        {**_placed_grasp("fork", fork["xyz"], "bare"), "object": None},
    ]
    targets = _targets_file(tmp_path, problems, object=can)
    html = tmp_path / "scene.html"
    assert main(["demo", "--targets", str(targets), "--html", str(html)]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert [line.split()[:2] for line in printed[1:4]] == [
        ["can", "grasp"], ["fork/grasp", "fork"], ["bare", "-"],
    ]  # fmt: skip
    commands = scene_commands(html.read_text(encoding="utf-8"))
    placed = {
        c["path"]: np.reshape(c["matrix"], (4, 4)).T[:3, 3]
        for c in commands
        if c["type"] == "set_transform" and c["path"].endswith("/object")
    }
    assert set(placed) == {"/meshcat/grasps/can_grasp/object", "/meshcat/grasps/fork_grasp/object"}
    assert placed["/meshcat/grasps/can_grasp/object"] == pytest.approx(can["xyz"])
    assert placed["/meshcat/grasps/fork_grasp/object"] == pytest.approx(fork["xyz"])
    drawn = {c["path"] for c in commands if c["type"] == "set_object"}
    for grasp in ("can_grasp", "fork_grasp", "bare", "bare-2"):  # a name drawn twice
        assert f"/meshcat/grasps/{grasp}/contacts/thumb/disk" in drawn
        assert any(p.startswith(f"/meshcat/grasps/{grasp}/hand/visuals/") for p in drawn)


def test_demo_targets_exit_codes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    html = str(tmp_path / "scene.html")
    far = _placed_grasp("can", [0.0, 0.0, 0.0], "far")
    far["contacts"][0]["point"] = [1.0, 0.0, 0.0]  # type: ignore[index]
    unsolved = _targets_file(tmp_path, [far])
    assert main(["demo", "--targets", str(unsolved), "--html", html, "--inits", "1"]) == 1
    assert "no (" in capsys.readouterr().out
    missing_mesh = {"mesh": "none.stl"}
    bad = _targets_file(tmp_path, [_placed_grasp("can", [0, 0, 0], "x")], object=missing_mesh)
    assert main(["demo", "--targets", str(bad), "--html", html]) == 2
    assert main(["demo", "--targets", str(tmp_path / "none.json"), "--html", html]) == 2
    errors = capsys.readouterr().err
    assert errors.count("sahgrasp: error:") == 2 and "Traceback" not in errors
