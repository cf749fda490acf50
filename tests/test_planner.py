"""The planner: 2-, 3- and 4-finger grasps of a box mesh, planned and verified independently."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from sahgrasp.cli import main
from sahgrasp.model.hand import load_hand
from sahgrasp.objects import load_mesh
from sahgrasp.planner import PlanningError, PlanSettings, plan_grasps
from sahgrasp.planner.verify import GraspVerifier


@pytest.fixture(scope="module")
def hand():  # type: ignore[no-untyped-def]
    return load_hand("sah")


@pytest.fixture(scope="module")
def box_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("meshes") / "box.stl"
    trimesh.creation.box(extents=(0.05, 0.07, 0.09)).export(path)
    return path


@pytest.mark.parametrize("count", [2, 3, 4])
def test_box_grasps_of_each_finger_count_are_verified(hand, box_file: Path, count: int) -> None:  # type: ignore[no-untyped-def]
    obj = load_mesh(box_file)
    plan = plan_grasps(hand, obj, PlanSettings(fingers=(count,), candidates=6, grasps=3, seed=1))
    assert plan.grasps, plan.summary
    mesh = obj.mesh().transformed(obj.T_world_object)
    verifier = GraspVerifier(hand.description, mesh.vertices_m, mesh.faces)
    for entry in plan.to_dict()["grasps"]:
        assert len(entry["fingers"]) == count
        assert entry["fingers"][0] == "thumb"
        verdict = verifier.check(entry["wrist"], entry["joints"], entry["contacts"])
        assert verdict.ok, verdict.problems
        assert max(verdict.contact_errors_m) <= 1.5e-3
        assert verdict.max_link_depth_m <= 5e-4
        assert entry["quality"]["force_closure"] == (entry["quality"]["epsilon_l1"] > 0.0)
    if count == 2:  # two hard-finger contacts never resist a torque about their line
        assert not any(g.force_closure for g in plan.grasps)
    else:
        assert any(g.force_closure for g in plan.grasps)


def test_verifier_refuses_a_grasp_moved_into_the_object(hand, box_file: Path) -> None:  # type: ignore[no-untyped-def]
    obj = load_mesh(box_file)
    plan = plan_grasps(hand, obj, PlanSettings(fingers=(3,), candidates=4, grasps=1, seed=2))
    entry = plan.to_dict()["grasps"][0]
    mesh = obj.mesh().transformed(obj.T_world_object)
    verifier = GraspVerifier(hand.description, mesh.vertices_m, mesh.faces)
    normal = np.array(entry["contacts"][0]["normal"])
    moved = {**entry["wrist"], "xyz": (np.array(entry["wrist"]["xyz"]) - 0.02 * normal).tolist()}
    verdict = verifier.check(moved, entry["joints"], entry["contacts"])
    assert not verdict.ok
    joints = dict(entry["joints"])
    joints["index_j1"] += 5.0
    assert any(
        "outside" in p for p in verifier.check(entry["wrist"], joints, entry["contacts"]).problems
    )
    uncoupled = {**entry["joints"], "ring_j4": entry["joints"]["ring_j3"] + 0.05}  # mimic of j3
    assert any("mimic" in p for p in verifier.check(entry["wrist"], uncoupled, []).problems)
    off = [{**c, "point": (np.array(c["point"]) + 0.003 * np.array(c["normal"])).tolist()}
           for c in entry["contacts"]]  # fmt: skip
    assert not verifier.check(entry["wrist"], entry["joints"], off).ok  # 3 mm off: d_min


def test_same_seed_same_plan(hand, box_file: Path) -> None:  # type: ignore[no-untyped-def]
    settings = PlanSettings(candidates=6, grasps=3, seed=5)
    a = plan_grasps(hand, load_mesh(box_file), settings).to_dict()
    b = plan_grasps(hand, load_mesh(box_file), settings).to_dict()
    assert a["grasps"] == b["grasps"]


def test_settings_are_checked() -> None:
    with pytest.raises(PlanningError, match="fingers"):
        PlanSettings(fingers=(5,))
    with pytest.raises(PlanningError, match="rank"):
        PlanSettings(rank="nope")


def test_cli_plans_a_mesh_and_writes_json(box_file: Path, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "plan.json"
    code = main(
        ["plan", str(box_file), "--candidates", "6", "--grasps", "2", "--json", str(out), "--quiet"]
    )
    assert code == 0
    doc = json.loads(out.read_text())
    assert doc["hand"] == "sah"
    assert doc["object"]["mesh"] == str(box_file.resolve())
    assert set(doc["summary"]) >= {
        "grasps",
        "force_closure",
        "candidates",
        "time_to_first_s",
        "time_s",
    }
    grasp = doc["grasps"][0]
    assert grasp["rank"] == 1
    assert set(grasp) >= {
        "fingers",
        "contacts",
        "wrist",
        "joints",
        "quality",
        "object_clearance_mm",
        "closest_link",
        "seed",
    }


def test_cli_broken_mesh_is_one_line_exit_2(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    broken = tmp_path / "broken.stl"
    broken.write_text("solid nothing\nendsolid nothing\n")
    assert main(["plan", str(broken), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("sahgrasp: error:")


def test_manipulability_indices_equal_the_atlas_ones_at_its_optimum() -> None:
    from sahgrasp.experiments.setups import run_experiment
    from sahgrasp.planner.plan import manipulability_indices

    result = run_experiment("bottle", index="volume")
    problem = result.problem
    y = result.atlas.centres[result.best]
    x = problem.x_of(y)
    system = problem.system
    reference = np.asarray(system.object_pose(x).translation)
    fingers = tuple(c.finger for c in system.contacts)
    mine = manipulability_indices(system.hand, system.configuration(x), fingers, reference)
    atlas = problem.manipulability(y)
    for name, value in mine.items():
        assert value == pytest.approx(float(atlas.index(name)), rel=1e-9)


@pytest.mark.slow
def test_plan_mug_example_writes_a_scene_of_the_ranked_grasps(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    import importlib.util

    from sahgrasp.viz.recording import scene_commands

    path = Path(__file__).resolve().parent.parent / "examples" / "plan_mug.py"
    spec = importlib.util.spec_from_file_location("example_plan_mug", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out = tmp_path / "plan.html"
    assert module.main(["--candidates", "8", "--grasps", "2", "--html", str(out)]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith("mug: ") and "#1: thumb+" in printed
    drawn = {c["path"] for c in scene_commands(out.read_text()) if c["type"] == "set_object"}
    assert {"/meshcat/plan/1/object", "/meshcat/labels/1"} <= drawn


def test_verifier_self_collision_agrees_with_the_hand_model(hand, box_file: Path) -> None:  # type: ignore[no-untyped-def]
    import pinocchio as pin

    obj = load_mesh(box_file)
    mesh = obj.mesh().transformed(obj.T_world_object)
    verifier = GraspVerifier(hand.description, mesh.vertices_m, mesh.faces)
    rng = np.random.default_rng(3)
    far = pin.SE3(np.eye(3), np.array([1.0, 1.0, 1.0]))  # away from the object
    seen = {True: 0, False: 0}
    for _ in range(200):
        q = hand.random_configuration(rng, far)
        wrist = {"xyz": q[:3].tolist(), "quat": q[3:7].tolist()}
        verdict = verifier.check(wrist, hand.joint_values(q), [])
        colliding = any(p.startswith("self-collision") for p in verdict.problems)
        assert colliding == hand.in_collision(q)
        seen[colliding] += 1
    assert seen[True] and seen[False]


def test_cli_json_on_stdout_with_scale_and_placement(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    mm = tmp_path / "box_mm.stl"
    trimesh.creation.box(extents=(50.0, 60.0, 80.0)).export(mm)
    argv = ["plan", str(mm), "--scale", "1e-3", "--xyz", "0.5", "0", "0", "--candidates", "4",
            "--grasps", "1", "--json", "-", "--quiet"]  # fmt: skip
    assert main(argv) == 0
    doc = json.loads(capsys.readouterr().out)  # stdout holds the JSON alone
    assert doc["object"]["scale"] == 1e-3 and doc["object"]["xyz"] == [0.5, 0.0, 0.0]
    for contact in doc["grasps"][0]["contacts"]:
        assert 0.5 - 0.026 < contact["point"][0] < 0.5 + 0.026  # world frame, object placed


def test_cli_unknown_object_and_bad_fingers_are_usage_errors(capsys) -> None:  # type: ignore[no-untyped-def]
    assert main(["plan", "no_such_thing"]) == 2
    assert main(["plan", "can", "--fingers", "5"]) == 2
    err = capsys.readouterr().err
    assert "neither a mesh file" in err and "finger counts" in err


def test_verifier_finds_links_wholly_inside_the_object(hand) -> None:  # type: ignore[no-untyped-def]
    big = trimesh.creation.box(extents=(0.6, 0.6, 0.6))  # the hand fits inside: no triangle met
    verifier = GraspVerifier(hand.description, np.asarray(big.vertices), np.asarray(big.faces))
    q = hand.configuration()
    wrist = {"xyz": q[:3].tolist(), "quat": q[3:7].tolist()}
    verdict = verifier.check(wrist, hand.joint_values(q), [])
    assert not verdict.ok
    assert verdict.max_link_depth_m > 0.1 and verdict.clearance_m < -0.1
    inside = {p.split()[1] for p in verdict.problems if p.endswith("inside the object")}
    assert inside == set(verifier.links)  # every link (no contact: none exempt)


def test_allegro_plans_with_its_own_reach(allegro, box_file: Path) -> None:  # type: ignore[no-untyped-def]
    from sahgrasp.planner.candidates import hand_reach

    reach = hand_reach(allegro)
    assert reach.fingertip_radius_m == allegro.description.fingertip_radius_m
    plan = plan_grasps(allegro, load_mesh(box_file), PlanSettings(fingers=(3,), candidates=4))
    assert plan.hand == "allegro" and plan.grasps
    assert all(g.fingers[0] == "thumb" for g in plan.grasps)


def test_time_limit_caps_the_plan(hand, box_file: Path) -> None:  # type: ignore[no-untyped-def]
    plan = plan_grasps(hand, load_mesh(box_file), PlanSettings(candidates=50, time_limit_s=1e-6))
    assert plan.summary.time_limited and plan.summary.candidates == 0 and not plan.grasps


def test_an_extra_check_drops_and_reranks(hand, box_file: Path) -> None:  # type: ignore[no-untyped-def]
    settings = PlanSettings(candidates=8, grasps=4, seed=4, rank="epsilon")
    plain = plan_grasps(hand, load_mesh(box_file), settings)

    def prefer_low_epsilon(grasp):  # type: ignore[no-untyped-def]
        return None if len(grasp.fingers) == 2 else -grasp.quality["epsilon_l1"]

    checked = plan_grasps(hand, load_mesh(box_file), settings, check=prefer_low_epsilon)
    assert checked.grasps and all(len(g.fingers) > 2 for g in checked.grasps)
    scores = [g.quality["check"] for g in checked.grasps]
    assert scores == sorted(scores, reverse=True)
    assert len(plain.grasps) >= len(checked.grasps)


def test_epsilon_bound_is_never_below_the_epsilon(hand, box_file: Path) -> None:  # type: ignore[no-untyped-def]
    from sahgrasp.planner.candidates import ObjectFrame
    from sahgrasp.planner.plan import _epsilon_bound, _wrenches
    from sahgrasp.quality.wrench import epsilon

    obj = load_mesh(box_file)
    mesh = obj.mesh()
    frame = ObjectFrame.of(mesh.vertices_m, mesh.faces)
    settings = PlanSettings(grasps=10, candidates=20, fingers=(3, 4), seed=3, rank="epsilon")
    plan = plan_grasps(hand, obj, settings)
    assert plan.grasps
    previous = np.inf
    for grasp in plan.grasps:
        value = epsilon(_wrenches(grasp, frame, settings))
        assert grasp.quality["epsilon_l1"] == pytest.approx(value, abs=1e-12)
        assert _epsilon_bound(grasp, frame, settings) >= value - 1e-12
        # Force-closure grasps come ranked by their exact epsilon (ties aside).
        assert value <= previous + 1e-9
        previous = value


def test_a_check_draws_further_batches_until_enough_pass(hand, box_file: Path) -> None:  # type: ignore[no-untyped-def]
    settings = PlanSettings(candidates=8, grasps=3, seed=2)

    def rare(grasp):  # type: ignore[no-untyped-def]
        return 1.0 if grasp.seed % 4 == 0 else None  # about one verified grasp in four

    one = plan_grasps(hand, load_mesh(box_file), settings, check=rare)
    assert one.summary.candidates == 8  # without max_candidates: one batch
    more = plan_grasps(hand, load_mesh(box_file), settings, check=rare, max_candidates=40)
    s = more.summary
    assert s.candidates % 8 == 0 and 8 <= s.candidates <= 40
    # Stopped because enough pass, or at the cap; a batch more than needed is never drawn.
    assert len(more.grasps) == 3 or s.candidates == 40
    assert len(more.grasps) >= len(one.grasps)
    assert all(g.seed % 4 == 0 for g in more.grasps)
    if s.candidates > 8:
        assert len(one.grasps) < 3
    again = plan_grasps(hand, load_mesh(box_file), settings, check=rare, max_candidates=40)
    assert [g.seed for g in again.grasps] == [g.seed for g in more.grasps]
    # Without a check the cap changes nothing: one batch, the same plan.
    plain = plan_grasps(hand, load_mesh(box_file), settings, max_candidates=40)
    assert plain.summary.candidates == 8
    with pytest.raises(PlanningError, match="max_candidates"):
        plan_grasps(hand, load_mesh(box_file), settings, check=rare, max_candidates=0)
