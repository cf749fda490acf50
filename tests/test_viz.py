"""Scenes of sahgrasp.viz: what they hold, their HTML export, and no server left behind."""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import psutil
import pytest
from polling import gone, until

from sahgrasp.cli import main
from sahgrasp.core.errors import VizError
from sahgrasp.experiments.ik_examples import (
    EXAMPLE_NAMES,
    format_report,
    show_examples,
    solve_example,
)
from sahgrasp.ik import random_problem, solve_ik
from sahgrasp.model.contacts import ContactTarget, GraspTarget
from sahgrasp.model.hand import Hand
from sahgrasp.objects import load_object, paper_grasp, transform_points
from sahgrasp.viz import (
    CAMERA_FOV_DEG,
    ChartGrasp,
    HandView,
    RecordingWindow,
    Viewer,
    display_points,
    frame_grasp,
    grasp_points,
    hex_color,
    present,
    quality_colors,
    scene_commands,
    show_atlas,
    show_atlas_grasps,
    show_contacts,
    show_grasp,
    visual_model,
)
from sahgrasp.viz.hand_view import visual_corners
from sahgrasp.viz.screenshot import ScreenshotError, screenshot
from sahgrasp.viz.viewer import ViewerError

LIVE_TIMEOUT_S = 20.0
"""How long a live viewer's processes may take to start or end [s]."""


def by_path(html: str, kind: str) -> dict[str, dict[str, Any]]:
    return {c["path"]: c for c in scene_commands(html) if c["type"] == kind}


def transform(command: dict[str, Any]) -> np.ndarray:
    return np.array(command["matrix"]).reshape(4, 4).T


# ----- recording window and viewer ------------------------------------------------------------
def test_recording_window_keeps_the_latest_state_like_meshcats_server() -> None:
    with Viewer() as viewer:
        assert viewer.server_pid is None and viewer.url is None
        node = viewer.meshcat["a/b"]
        node.set_transform(np.eye(4))
        node.set_transform(np.diag([1.0, 1.0, 1.0, 1.0]) + np.eye(4, k=3) * 0.5)
        viewer.meshcat["a/c"].set_property("visible", False)
        viewer.meshcat["gone"].set_transform(np.eye(4))
        viewer.meshcat["gone"].delete()
        html = viewer.html()
    transforms = by_path(html, "set_transform")
    assert transform(transforms["/meshcat/a/b"])[0, 3] == pytest.approx(0.5)
    assert "/meshcat/gone" not in transforms
    assert by_path(html, "set_property")["/meshcat/a/c"]["value"] is False
    assert "MeshCat.Viewer" in html and "<title>sahgrasp</title>" in html


def test_recording_window_refuses_unknown_commands() -> None:
    class Odd:
        def lower(self) -> dict[str, str]:
            return {"type": "capture_image", "path": ""}

    with pytest.raises(ValueError, match="capture_image"):
        RecordingWindow().send(Odd())


def test_live_viewer_server_is_gone_after_close() -> None:
    with Viewer(live=True) as viewer:
        pid = viewer.server_pid
        assert pid is not None and psutil.pid_exists(pid)
        assert viewer.url is not None and viewer.url.startswith("http")
        viewer.meshcat["box"].set_transform(np.eye(4))
        assert "MeshCat.Viewer" in viewer.html()  # static_html() from the live server
    assert not psutil.pid_exists(pid)
    viewer.close()  # idempotent


def test_live_viewer_server_is_gone_after_an_error() -> None:
    with pytest.raises(RuntimeError, match="boom"), Viewer(live=True) as viewer:
        pid = viewer.server_pid
        raise RuntimeError("boom")
    assert pid is not None and not psutil.pid_exists(pid)


ROOT = Path(__file__).resolve().parent.parent
LIVE_SCRIPT = """
import signal, sys, time
from sahgrasp.viz.viewer import Viewer
if sys.argv[1] == "own-handler":
    signal.signal(signal.SIGTERM, lambda *_: (print("own handler", flush=True), sys.exit(3)))
viewer = Viewer(live=True)
print(viewer.server_pid, flush=True)
time.sleep(120)
"""


def listening(pid: int) -> set[str]:
    return {c.laddr.ip for c in psutil.Process(pid).net_connections() if c.status == "LISTEN"}


@pytest.mark.slow
@pytest.mark.parametrize(
    ("signum", "mode", "code"),
    [
        (signal.SIGTERM, "plain", -signal.SIGTERM),
        (signal.SIGHUP, "plain", -signal.SIGHUP),
        (signal.SIGKILL, "plain", -signal.SIGKILL),
        (signal.SIGTERM, "own-handler", 3),
    ],
)
def test_a_signalled_script_leaves_no_meshcat_server(signum: int, mode: str, code: int) -> None:
    script = subprocess.Popen(
        [sys.executable, "-c", LIVE_SCRIPT, mode], stdout=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip
    try:
        assert script.stdout is not None
        lines = iter(script.stdout.readline, "")
        server = int(next(line for line in lines if line.strip().isdigit()))
        assert listening(server) == {"127.0.0.1"}  # zmq and web ports, this machine only
        script.send_signal(signum)
        assert until(lambda: script.poll() is not None, LIVE_TIMEOUT_S), "the script did not end"
        assert until(lambda: gone(server), LIVE_TIMEOUT_S), "the meshcat server outlived the script"
        assert script.returncode == code
        if mode == "own-handler":
            assert "own handler" in script.stdout.read()
    finally:
        script.kill()
        script.communicate(timeout=10)


def test_live_viewer_puts_back_the_signal_handlers() -> None:
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGHUP)}
    with Viewer(live=True) as viewer:
        assert signal.getsignal(signal.SIGTERM) == viewer._on_signal
    assert {sig: signal.getsignal(sig) for sig in before} == before


def test_an_ignored_signal_stays_ignored() -> None:
    previous = signal.signal(signal.SIGHUP, signal.SIG_IGN)  # as under nohup
    try:
        with Viewer(live=True) as viewer:
            assert signal.getsignal(signal.SIGHUP) == signal.SIG_IGN
            assert signal.getsignal(signal.SIGTERM) == viewer._on_signal
        assert signal.getsignal(signal.SIGHUP) == signal.SIG_IGN
    finally:
        signal.signal(signal.SIGHUP, previous)


def test_live_viewer_on_a_bad_host_is_a_typed_error() -> None:
    with pytest.raises(ViewerError, match=r"did not start on host '256\.1\.1\.1'"):
        Viewer(live=True, host="256.1.1.1")


def test_offline_viewer_cannot_open_a_browser() -> None:
    with Viewer() as viewer, pytest.raises(RuntimeError, match="save_html"):
        viewer.open()


def test_save_html_writes_a_standalone_page(tmp_path: Path) -> None:
    with Viewer(title="my scene") as viewer:
        out = viewer.save_html(tmp_path / "sub" / "scene.html")
    text = out.read_text(encoding="utf-8")
    assert "<title>my scene</title>" in text and "http://" not in text.split("<script>")[0]


def test_look_at_shifts_the_scene_and_places_the_camera() -> None:
    with Viewer() as viewer:
        viewer.look_at([0.1, 0.2, 0.3], [0.1, -0.3, 0.5])
        html = viewer.html()
    assert np.allclose(transform(by_path(html, "set_transform")["/meshcat"])[:3, 3],
                       [-0.1, -0.2, -0.3])  # fmt: skip
    camera = [
        c
        for c in scene_commands(html)
        if c["type"] == "set_property" and c["property"] == "position"
    ]
    assert np.allclose(camera[-1]["value"], [0.0, 0.2, 0.5])  # world (x, y, z) -> (x, z, -y)


def test_frame_holds_every_point_in_the_field_of_view() -> None:
    points = np.random.default_rng(0).uniform(-0.2, 0.2, (50, 3)) + np.array([1.0, 2.0, 0.0])
    with Viewer() as viewer:
        viewer.frame(points, (0.0, -1.0, 0.0))
        html = viewer.html()
    centre = -transform(by_path(html, "set_transform")["/meshcat"])[:3, 3]
    (position,) = [c for c in scene_commands(html) if c.get("property") == "position"]
    x, z, minus_y = position["value"]
    eye = centre + np.array([x, -minus_y, z])
    rel = points - eye
    depth = rel[:, 1]  # looking along +y
    half = np.tan(np.radians(0.5 * CAMERA_FOV_DEG))
    assert np.all(np.abs(rel[:, 0]) <= depth * half) and np.all(np.abs(rel[:, 2]) <= depth * half)


def camera_eye(html: str) -> np.ndarray:
    """The camera position (world frame) of an exported scene framed by ``look_at``."""
    centre = -transform(by_path(html, "set_transform")["/meshcat"])[:3, 3]
    (position,) = [c for c in scene_commands(html) if c.get("property") == "position"]
    x, z, minus_y = position["value"]
    return centre + np.array([x, -minus_y, z])


def in_view(points: np.ndarray, eye: np.ndarray, centre: np.ndarray, aspect: float) -> bool:
    """Every point inside the field of view of a camera at ``eye`` looking at ``centre``."""
    forward = (centre - eye) / np.linalg.norm(centre - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    rel = points - eye
    depth = rel @ forward
    tan_v = np.tan(np.radians(0.5 * CAMERA_FOV_DEG))
    return bool(np.all(np.abs(rel @ up) <= depth * tan_v)
                and np.all(np.abs(rel @ right) <= depth * tan_v * aspect))  # fmt: skip


def test_visual_corners_bound_every_visual_geometry(sah: Hand) -> None:
    q = sah.configuration()
    corners = visual_corners(sah, q)
    assert corners.shape == (8 * visual_model(sah).ngeoms, 3)
    with Viewer() as viewer:
        placements = HandView(viewer, sah, "h", q).placements(q)
    palm = corners[:8]  # a box: its corners lie at its half-diagonal from its placement
    assert np.allclose(palm.mean(axis=0), placements[0][:3, 3])
    assert np.allclose(np.linalg.norm(palm - placements[0][:3, 3], axis=1),
                       np.linalg.norm([0.03285, 0.06, 0.065]))  # fmt: skip


def test_frame_grasp_looks_at_the_inside_of_the_hand_with_all_in_view(sah: Hand) -> None:
    can, target = load_object("can"), paper_grasp("can")
    result = solve_ik(sah, target)
    with Viewer() as viewer:
        show_grasp(viewer, "g", sah, result.q, can, target)
        frame_grasp(viewer, sah, result.q, target, can)
        html = viewer.html()
    eye = camera_eye(html)
    centre = -transform(by_path(html, "set_transform")["/meshcat"])[:3, 3]
    contacts = np.mean([c.point for c in target.contacts], axis=0)
    outward = contacts - result.q[:3]
    assert (eye - contacts)[:2] @ outward[:2] > 0  # beyond the contacts, seen from the wrist
    assert eye[2] > centre[2]  # from above
    assert in_view(grasp_points(sah, result.q, can), eye, centre, aspect=1.0)


def test_a_row_of_examples_fits_a_1280x800_window(sah: Hand) -> None:
    examples = [solve_example(sah, name) for name in EXAMPLE_NAMES]
    with Viewer() as viewer:
        show_examples(viewer, sah, examples)
        html = viewer.html()
    eye = camera_eye(html)
    centre = -transform(by_path(html, "set_transform")["/meshcat"])[:3, 3]
    placed = [
        transform_points(transform(by_path(html, "set_transform")[f"/meshcat/grasps/{ex.name}"]),
                         grasp_points(sah, ex.result.q, ex.obj))
        for ex in examples
    ]  # fmt: skip
    assert in_view(np.concatenate(placed), eye, centre, aspect=1280 / 800)


def test_a_targets_files_grasps_show_their_palm_side_and_stay_upright(sah: Hand) -> None:
    # facing=False is how demo --targets draws: each grasp as the world has it, turned about z.
    examples = [solve_example(sah, name) for name in EXAMPLE_NAMES]
    with Viewer() as viewer:
        show_examples(viewer, sah, examples, facing=False)
        html = viewer.html()
    eye = camera_eye(html)
    for ex in examples:
        T = transform(by_path(html, "set_transform")[f"/meshcat/grasps/{ex.name}"])
        np.testing.assert_allclose(T[2, :3], [0.0, 0.0, 1.0], atol=1e-12)  # upright
        contacts = transform_points(T, ex.contact_centre_m[None])[0]
        wrist = transform_points(T, ex.result.q[None, :3])[0]
        outward = contacts - wrist
        if np.hypot(*outward[:2]) > 1e-3:
            assert (eye - contacts)[:2] @ outward[:2] > 0, ex.name  # beyond the contacts


# ----- colours --------------------------------------------------------------------------------
def test_hex_color() -> None:
    assert hex_color((1.0, 0.0, 0.0, 1.0)) == 0xFF0000
    assert hex_color((0.0, 0.5, 1.0)) == 0x0080FF
    assert hex_color((2.0, -1.0, 0.0)) == 0xFF0000


def test_quality_colors_red_to_green_black_if_singular() -> None:
    colors = quality_colors([1e-6, 0.1, 0.5, 1.0], singular_below=1e-3)
    assert np.allclose(colors[0], 0.0)
    assert colors[1, 0] > colors[1, 1] and colors[3, 1] > colors[3, 0]  # red low, green high
    with pytest.raises(ValueError, match="finite"):
        quality_colors([np.nan], 1e-3)


# ----- hands, contacts, grasps ----------------------------------------------------------------
def test_hand_view_draws_every_visual_geometry(any_hand: Hand) -> None:
    with Viewer() as viewer:
        view = HandView(viewer, any_hand, "h")
        html = viewer.html()
    objects = by_path(html, "set_object")
    assert len(view.node_names) == visual_model(any_hand).ngeoms > 0
    for name in view.node_names:
        assert f"/meshcat/{name}" in objects
    if any_hand.description.name == "allegro":  # STL meshes are embedded, not linked
        assert any(o["object"]["geometries"][0].get("format") == "stl" for o in objects.values()
                   if o["object"].get("geometries"))  # fmt: skip


def test_hand_view_shows_the_configuration(sah: Hand) -> None:
    q = sah.configuration()
    q[:3] = [0.1, 0.2, 0.3]
    with Viewer() as viewer:
        view = HandView(viewer, sah, "h", q)
        html = viewer.html()
    palm = next(n for n in view.node_names if n.endswith("palm_0"))
    placed = transform(by_path(html, "set_transform")[f"/meshcat/{palm}"])
    assert np.allclose(placed, view.placements(q)[view.node_names.index(palm)])
    assert np.allclose(placed[:3, 3], q[:3] + sah.wrist_pose(q).rotation
                       @ visual_model(sah).geometryObjects[0].placement.translation)  # fmt: skip


def test_animation_has_one_keyframe_per_iterate(sah: Hand) -> None:
    result = solve_ik(sah, random_problem(sah, 0, 1), record_history=True)
    assert result.history is not None and len(result.history) >= 2
    with Viewer() as viewer:
        view = HandView(viewer, sah, "h", result.q)
        view.animate(result.history)
        html = viewer.html()
    (animation,) = [c for c in scene_commands(html) if c["type"] == "set_animation"]
    clips = {a["path"]: a["clip"] for a in animation["animations"]}
    assert set(clips) == {f"/meshcat/{n}" for n in view.node_names}
    track = clips[f"/meshcat/{view.node_names[0]}"]["tracks"][0]
    assert [k["time"] for k in track["keys"]] == list(range(len(result.history)))
    first = view.placements(result.history[0])[0][:3, 3]
    assert np.allclose(track["keys"][0]["value"], first)
    with pytest.raises(ValueError, match="nothing to animate"):
        view.animate([])


def test_contacts_are_disks_at_the_points_with_cylinders_along_the_normals() -> None:
    n = np.array([0.0, 0.6, 0.8])
    thumb = ContactTarget("thumb", [0.1, 0.0, 0.0], n)
    target = GraspTarget("t", [thumb, ContactTarget("index", [0.0, 0.1, 0.0], [0.0, -1.0, 0.0])])
    with Viewer() as viewer:
        show_contacts(viewer, "c", target, disk_radius_m=0.005, normal_length_m=0.02)
        html = viewer.html()
    transforms = by_path(html, "set_transform")
    disk = transform(transforms["/meshcat/c/thumb/disk"])
    stick = transform(transforms["/meshcat/c/thumb/normal"])
    assert np.allclose(disk[:3, 3], [0.1, 0.0, 0.0]) and np.allclose(disk[:3, 1], n)
    assert np.allclose(stick[:3, 3], [0.1, 0.0, 0.0] + 0.01 * n)
    assert np.allclose(transform(transforms["/meshcat/c/index/disk"])[:3, 1], [0, -1, 0])
    geometry = by_path(html, "set_object")["/meshcat/c/thumb/disk"]["object"]["geometries"][0]
    assert geometry["type"] == "CylinderGeometry" and geometry["radiusTop"] == 0.005


def test_grasp_scene_holds_object_contacts_and_hand(sah: Hand) -> None:
    obj = load_object("can")
    target = paper_grasp("can")
    T = np.eye(4)
    T[:3, 3] = [0.5, 0.0, 0.0]
    with Viewer() as viewer:
        show_grasp(viewer, "g", sah, sah.configuration(), obj, target, T_scene=T)
        html = viewer.html()
    objects = by_path(html, "set_object")
    mesh = objects["/meshcat/g/object"]["object"]
    assert mesh["materials"][0]["color"] == hex_color(obj.rgba)
    assert {f"/meshcat/g/contacts/{f}/disk" for f in target.fingers} <= set(objects)
    assert any(p.startswith("/meshcat/g/hand/visuals/") for p in objects)
    assert np.allclose(transform(by_path(html, "set_transform")["/meshcat/g"]), T)


# ----- atlas ----------------------------------------------------------------------------------
@pytest.mark.parametrize("dim", [2, 3, 12])
def test_display_points_fit_the_atlas_size(dim: int) -> None:
    points = np.random.default_rng(dim).normal(size=(40, dim))
    shown = display_points(points, size_m=0.3)
    assert shown.shape == (40, 3)
    assert np.ptp(shown, axis=0).max() == pytest.approx(0.3)
    assert np.allclose(shown.mean(axis=0), 0.0, atol=1e-12)
    if dim == 2:
        assert np.allclose(shown[:, 2], 0.0)
    with pytest.raises(VizError, match="finite"):
        display_points(np.zeros((0, 3)))


def test_atlas_points_coloured_by_quality_best_and_worst_marked() -> None:
    points = np.random.default_rng(1).normal(size=(30, 5))
    values = np.linspace(0.0, 1.0, 30)
    values[7] = np.nan  # no candidate: grey
    with Viewer() as viewer:
        plot = show_atlas(viewer, "atlas", points, values, singular_below=0.05)
        html = viewer.html()
    assert (plot.best, plot.worst) == (29, 0)
    cloud = by_path(html, "set_object")["/meshcat/atlas/charts"]["object"]
    assert cloud["object"]["type"] == "Points"
    best = transform(by_path(html, "set_transform")["/meshcat/atlas/best"])
    assert np.allclose(best[:3, 3], plot.positions_m[29])
    with Viewer() as viewer, pytest.raises(VizError, match="values of shape"):
        show_atlas(viewer, "atlas", points, values[:5], 0.05)


def test_atlas_with_the_best_and_worst_hand_grasps(sah: Hand) -> None:
    rng = np.random.default_rng(2)
    best = ChartGrasp(3, sah.random_configuration(rng), load_object("can"))
    worst = ChartGrasp(5, sah.random_configuration(rng))
    with Viewer() as viewer:
        plot = show_atlas_grasps(viewer, sah, rng.normal(size=(10, 20)), rng.uniform(size=10),
                                 1e-4, best, worst)  # fmt: skip
        html = viewer.html()
    assert (plot.best, plot.worst) == (3, 5)
    objects = by_path(html, "set_object")
    assert "/meshcat/best/object" in objects and "/meshcat/worst/object" not in objects
    assert {"/meshcat/links/best", "/meshcat/links/worst"} <= set(objects)
    assert any(p.startswith("/meshcat/worst/hand/") for p in objects)
    # Both hands and the can whole in a 1200x800 window: every drawn box corner and vertex.
    eye = camera_eye(html)
    centre = -transform(by_path(html, "set_transform")["/meshcat"])[:3, 3]
    drawn = [
        transform_points(transform(by_path(html, "set_transform")[f"/meshcat/{name}"]),
                         grasp_points(sah, grasp.q, grasp.obj))
        for name, grasp in (("best", best), ("worst", worst))
    ]  # fmt: skip
    assert in_view(np.concatenate(drawn), eye, centre, aspect=1200 / 800)


# ----- paper examples -------------------------------------------------------------------------
def test_example_report_beside_the_paper(sah: Hand) -> None:
    example = solve_example(sah, "fork")
    report = format_report([example])
    assert report.splitlines()[0].split()[:2] == ["object", "solved"]
    row = report.splitlines()[1]
    assert row.split()[0] == "fork" and "(1)" in row and "(6)" in row
    assert example.result.history is not None


def test_example_report_columns_stay_aligned_on_a_long_reason(sah: Hand) -> None:
    solved = solve_example(sah, "fork")
    failed = dataclasses.replace(
        solved, name="can", result=dataclasses.replace(solved.result, success=False,
                                                        reason="no_progress"),
    )  # fmt: skip
    header, *rows = format_report([solved, failed]).splitlines()
    assert rows[1].split()[1:3] == ["no", "(no_progress)"]
    for title in ("inits (paper)", "iterations (paper)"):  # text: left-aligned
        start = header.index(title)
        for row in rows:
            assert row[start - 2 : start] == "  " and row[start] != " ", (title, row)
    end = header.index("time [ms]") + len("time [ms]")  # numbers: right-aligned
    assert all(row[end - 1] != " " and row[end : end + 2] == "  " for row in rows)
    assert len({len(line) for line in (header, *rows)}) == 1


def test_present_writes_html_without_a_server(tmp_path: Path) -> None:
    before = {p.pid for p in psutil.Process().children(recursive=True)}
    present(lambda v: v.meshcat["x"].set_transform(np.eye(4)), str(tmp_path / "x.html"))
    assert (tmp_path / "x.html").stat().st_size > 100_000  # meshcat's viewer is inlined
    assert {p.pid for p in psutil.Process().children(recursive=True)} == before


# ----- screenshots ----------------------------------------------------------------------------
def fake_chromium(folder: Path, body: str) -> str:
    """An executable standing in for Chromium: a shell script running ``body``."""
    path = folder / "fake-chromium"
    path.write_text(f"#!/bin/sh\n{body}\n")
    path.chmod(0o755)
    return str(path)


WRITE_SHOT = 'for a in "$@"; do case "$a" in --screenshot=*) printf PNG > "${a#*=}";; esac; done'


def processes_running(executable: str) -> list[psutil.Process]:
    found = []
    for proc in psutil.process_iter(["cmdline", "status"]):
        cmdline = proc.info["cmdline"] or []
        if any(executable in part for part in cmdline) and proc.info["status"] != "zombie":
            found.append(proc)
    return found


@pytest.fixture
def page(tmp_path: Path) -> Path:
    html = tmp_path / "scene.html"
    html.write_text("<html></html>")
    return html


@pytest.mark.slow
def test_a_hanging_chromium_is_killed_whole_retried_then_one_error(
    tmp_path: Path, page: Path
) -> None:
    chromium = fake_chromium(tmp_path, "sleep 300 &\nsleep 300")  # a child in its group too
    with pytest.raises(ScreenshotError, match=r"failed 2 times.*hung.*install Chromium"):
        screenshot(page, tmp_path / "out.png", timeout_s=0.5, attempts=2, chromium=chromium)
    assert processes_running(chromium) == []
    assert not (tmp_path / "out.png").exists()


def test_a_failing_chromium_reports_its_exit_code_and_last_line(tmp_path: Path, page: Path) -> None:
    chromium = fake_chromium(tmp_path, "echo 'first' >&2\necho 'GPU process died' >&2\nexit 3")
    with pytest.raises(ScreenshotError, match=r"exit code 3 \(GPU process died\)"):
        screenshot(page, tmp_path / "out.png", attempts=1, chromium=chromium)


@pytest.mark.slow
def test_an_image_written_before_chromium_hangs_on_exit_is_kept(tmp_path: Path, page: Path) -> None:
    chromium = fake_chromium(tmp_path, f"{WRITE_SHOT}\nsleep 300")
    out = screenshot(page, tmp_path / "sub" / "out.png", timeout_s=30, chromium=chromium)
    assert out.read_bytes() == b"PNG"
    assert processes_running(chromium) == []


def test_no_chromium_is_one_typed_error_and_one_line(
    tmp_path: Path, page: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(ScreenshotError, match=r"no Chromium found.*apt-get install -y chromium"):
        screenshot(page, tmp_path / "out.png")
    assert main(["screenshot", str(page), str(tmp_path / "out.png")]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("sahgrasp: error: no Chromium found")


def test_bad_screenshot_requests_are_refused(tmp_path: Path, page: Path) -> None:
    with pytest.raises(ScreenshotError, match="not a file"):
        screenshot(tmp_path / "missing.html", tmp_path / "out.png")
    with pytest.raises(ScreenshotError, match="attempts >= 1"):
        screenshot(page, tmp_path / "out.png", attempts=0)
    assert main(["screenshot", str(page), str(tmp_path / "out.png"), "--size", "12x"]) == 2


ARGS_SEEN = 'printf "%s\\n" "$@" > "$(dirname "$0")/args.txt"\n' + WRITE_SHOT


@pytest.mark.parametrize("root", [False, True], ids=["user", "root"])
def test_the_sandbox_is_off_only_for_root(
    tmp_path: Path, page: Path, monkeypatch: pytest.MonkeyPatch, root: bool
) -> None:
    monkeypatch.setattr(os, "geteuid", lambda: 0 if root else 1000)
    chromium = fake_chromium(tmp_path, ARGS_SEEN)
    screenshot(page, tmp_path / "out.png", timeout_s=30, chromium=chromium)
    args = (tmp_path / "args.txt").read_text().splitlines()
    assert ("--no-sandbox" in args) == root
    assert "--headless" in args and "--window-size=1200,800" in args


@pytest.mark.parametrize("size", [(0, 800), (15, 800), (1200, 8193), (10**6, 10**6), (1200,)])
def test_window_sizes_are_bounded(tmp_path: Path, page: Path, size: tuple[int, ...]) -> None:
    with pytest.raises(ScreenshotError, match=r"size must be \(width, height\) in 16\.\.8192 px"):
        screenshot(page, tmp_path / "out.png", size)  # type: ignore[arg-type]


@pytest.mark.parametrize("text", ["8193x800", "1200x100000", "15x15", "0x0", "5x800"])
def test_the_size_option_is_bounded_and_shows_its_default(
    tmp_path: Path, page: Path, text: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["screenshot", str(page), str(tmp_path / "out.png"), "--size", text]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert "--size: width and height must be in 16..8192 px" in line
    assert main(["screenshot", "--help"]) == 0
    shown = " ".join(capsys.readouterr().out.split())
    assert "(default: 1200x800)" in shown and "16..8192" in shown
