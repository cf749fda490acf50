"""The atlas on a mesh: F and J on the smooth local models, components, verification on the mesh."""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from sahgrasp.experiments.mesh_atlas import (
    MeshStart,
    optimize_mesh_grasps,
    read_starts,
    verify_grasp,
)
from sahgrasp.ik import solve_ik
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import Hand, load_hand
from sahgrasp.objects import GraspObject, load_mesh
from sahgrasp.objects.grasp_sampler import sample_object_grasps
from sahgrasp.optimization.grasp import GraspSystem, mesh_patches
from sahgrasp.optimization.optimizer import OptimizationSettings

ROOT = Path(__file__).resolve().parent.parent
FINGERS = ("thumb", "index", "middle")


@pytest.fixture(scope="module")
def cylinder(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, GraspObject]:
    """A can-sized cylinder mesh (radius 33 mm, 64 sections), placed off the origin."""
    path = tmp_path_factory.mktemp("mesh") / "cylinder.stl"
    trimesh.creation.cylinder(0.033, 0.12, sections=64).export(path)
    T = np.eye(4)
    T[:3, 3] = [0.05, -0.02, 0.1]
    return path, load_mesh(path).placed(T)


@pytest.fixture(scope="module")
def hand() -> Hand:
    return load_hand("sah")


@pytest.fixture(scope="module")
def starts(cylinder: tuple[Path, GraspObject], hand: Hand) -> list[MeshStart]:
    """Two 3-finger grasps of the cylinder solved by the IK (object as obstacle), world frame."""
    obj = cylinder[1]
    found = []
    for target in sample_object_grasps(obj, 20, 0):
        three = GraspTarget(target.name, [c for c in target.contacts if c.finger in FINGERS])
        result = solve_ik(hand, three, free_fingers=("ring",), obstacle=obj)
        if result.success:
            found.append(MeshStart(three, result.q, f"start {len(found)}"))
        if len(found) == 2:
            return found
    raise AssertionError("the IK solved fewer than two sampled grasps of the cylinder")


def test_f_and_j_on_a_mesh_match_finite_differences(
    cylinder: tuple[Path, GraspObject], hand: Hand, starts: list[MeshStart]
) -> None:
    obj = cylinder[1]
    start = starts[0]
    patches = mesh_patches(obj, start.target)
    q = start.q.copy()
    # The system's world is the object frame.
    import pinocchio as pin

    T = pin.SE3(np.linalg.inv(obj.T_world_object)) * hand.wrist_pose(q)
    hand.wrist_part(q)[:] = pin.SE3ToXYZQUAT(T)
    system = GraspSystem(hand, patches, q, free_object=True)
    rng = np.random.default_rng(1)
    step = 1e-7
    for _ in range(3):
        x = system.x_first + 1e-3 * rng.normal(size=system.n)
        J = np.array(system.J(x))
        numeric = np.empty_like(J)
        for col in range(system.n):
            e = np.zeros(system.n)
            e[col] = step
            numeric[:, col] = (system.F(x + e) - system.F(x - e)) / (2 * step)
        assert np.allclose(J, numeric, atol=1e-6), np.abs(J - numeric).max()
    # The start's point residuals are the distances of its contacts to the models: under d_min.
    points = np.asarray(system.F(system.x_first)).reshape(len(FINGERS), 5)[:, :3]
    assert np.linalg.norm(points, axis=1).max() < 1.5e-3


@pytest.mark.slow
def test_every_component_once_and_its_best_grasp_verified_on_the_mesh(
    cylinder: tuple[Path, GraspObject], hand: Hand, starts: list[MeshStart]
) -> None:
    obj = cylinder[1]
    settings = OptimizationSettings(radius=2.0, epsilon=0.5, max_charts=2000)
    search = optimize_mesh_grasps(hand, obj, [starts[0], starts[1], starts[0]], settings,
                                  motion_samples=300)  # fmt: skip
    assert search.start_errors == (None, None, None)
    # The third start is the first again: its component is not built twice.
    assert search.start_components[2] == search.start_components[0]
    assert len(search.components) == len(set(search.start_components))
    for component in search.components:
        assert component.result.atlas.complete
        assert component.best_chart is not None and component.verification is not None
        assert component.verification.ok
        # The planner's independent verifier passed it too, its contacts on the true mesh.
        assert component.verdict is not None and component.verdict.ok
        assert max(component.verdict.contact_errors_m) <= 1.5e-3
        assert component.best_value >= component.start_value
        # Independent of the search's own bookkeeping: the returned hand, checked again.
        assert component.q_world is not None
        again = verify_grasp(hand, obj, component.q_world, FINGERS)
        assert again.ok and max(again.contact_distances_m.values()) <= 3e-4


def test_starts_are_read_from_a_plan_or_a_targets_file(
    tmp_path: Path, hand: Hand, starts: list[MeshStart]
) -> None:
    q = starts[0].q
    grasp = {
        "contacts": [c.to_dict() for c in starts[0].target.contacts],
        "wrist": {"xyz": q[:3].tolist(), "quat": q[3:7].tolist()},
        "joints": hand.joint_values(q),
        "contact_params": {f: list(p) for f, p in hand.contact_parameters(q).items()},
    }
    (tmp_path / "plan.json").write_text(json.dumps({"grasps": [grasp]}))
    (read,) = read_starts(tmp_path / "plan.json", hand)
    assert read.q is not None and np.allclose(read.q, q, atol=1e-12)
    (tmp_path / "targets.json").write_text(
        json.dumps({"problems": [{"contacts": grasp["contacts"]}]})
    )
    (targets,) = read_starts(tmp_path / "targets.json", hand)
    assert targets.q is None and targets.target.fingers == FINGERS
    (tmp_path / "bad.json").write_text(
        json.dumps({"grasps": [{"contacts": grasp["contacts"][:1]}]})
    )
    from sahgrasp.core.errors import InvalidTargetError

    with pytest.raises(InvalidTargetError, match="two or more contacts"):
        read_starts(tmp_path / "bad.json", hand)


def test_the_command_refuses_a_mesh_without_starts(cylinder: tuple[Path, GraspObject]) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "sahgrasp", "atlas", "--mesh", str(cylinder[0])],
        capture_output=True, text=True, cwd=ROOT, env={"PYTHONPATH": str(ROOT)}, check=False,
    )  # fmt: skip
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.startswith("sahgrasp atlas: error: give an experiment")


@pytest.mark.slow
def test_the_first_chart_is_the_start_and_the_optimum_is_no_worse(
    cylinder: tuple[Path, GraspObject], hand: Hand, starts: list[MeshStart]
) -> None:
    from sahgrasp.experiments.mesh_atlas import _world_grasp
    from sahgrasp.planner.plan import manipulability_indices

    obj = cylinder[1]
    start = starts[0]
    settings = OptimizationSettings(radius=2.0, epsilon=0.5, max_charts=2000)
    search = optimize_mesh_grasps(hand, obj, [start], settings, motion_samples=300)
    (component,) = search.components
    # The models pass through the start's contacts: chart 0 is the start (up to the 1e-4 the
    # start is moved inside the bounds), its index the start's.
    q0, _ = _world_grasp(component.problem, component.result, 0, obj)
    assert start.q is not None
    assert np.abs(q0[:7] - start.q[:7]).max() < 1e-3
    centre = obj.T_world_object[:3, 3]
    at_start = manipulability_indices(hand, start.q, FINGERS, centre)["volume"]
    assert component.start_value == pytest.approx(at_start, rel=1e-2)
    assert component.best_value >= component.start_value


@pytest.mark.slow
def test_the_refine_example_plans_then_refines_the_mug(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import importlib.util

    path = ROOT / "examples" / "refine_mug.py"
    spec = importlib.util.spec_from_file_location("example_refine_mug", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out = tmp_path / "refined.json"
    assert module.main(["--starts", "1", "--candidates", "20", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "verified on the mesh" in printed and "1 of 1 planned grasps refined" in printed
    document = json.loads(out.read_text())
    (grasp,) = document["grasps"]
    # The refined grasp reads back as a start (the atlas's --start), hand and all.
    (again,) = read_starts(out, hand=load_hand("sah"))
    assert again.q is not None and len(grasp["contacts"]) >= 3


def test_refine_refuses_a_bad_number_of_rounds(
    cylinder: tuple[Path, GraspObject], hand: Hand, starts: list[MeshStart]
) -> None:
    from sahgrasp.core.errors import InvalidSettingsError
    from sahgrasp.experiments.mesh_atlas import refine_mesh_grasp

    for rounds in (0, -1, True, 1.5):
        with pytest.raises(InvalidSettingsError, match="rounds must be an integer >= 1"):
            refine_mesh_grasp(hand, cylinder[1], starts[0], rounds=rounds)  # type: ignore[arg-type]


@pytest.mark.slow
def test_rounds_start_from_the_last_optimum_and_never_lose(
    cylinder: tuple[Path, GraspObject], hand: Hand, starts: list[MeshStart]
) -> None:
    from sahgrasp.experiments.mesh_atlas import refine_mesh_grasp

    settings = OptimizationSettings(radius=2.0, epsilon=0.5, max_charts=2000)
    rounds = refine_mesh_grasp(hand, cylinder[1], starts[0], settings, rounds=3,
                               motion_samples=300)  # fmt: skip
    assert 1 <= len(rounds) <= 3
    for before, after in itertools.pairwise(rounds):
        # A round starts at the last one's best verified grasp as it is, and is kept only if
        # it ends better.
        assert before.best_chart not in (None, 0)
        assert after.start_value == pytest.approx(before.best_value, rel=1e-3)
        assert after.best_value > before.best_value
    for r in rounds:
        assert r.verdict is None or r.verdict.ok


def test_a_plan_without_contact_params_puts_the_contact_frames_on_the_contacts(
    tmp_path: Path, hand: Hand, starts: list[MeshStart]
) -> None:
    # sahgrasp plan writes the wrist and every URDF joint, not the virtual contact joints.
    q = starts[0].q
    assert q is not None
    grasp = {
        "contacts": [c.to_dict() for c in starts[0].target.contacts],
        "wrist": {"xyz": q[:3].tolist(), "quat": q[3:7].tolist()},
        "joints": hand.joint_values(q),
    }
    (tmp_path / "plan.json").write_text(json.dumps({"grasps": [grasp]}))
    (read,) = read_starts(tmp_path / "plan.json", hand)
    assert read.q is not None
    for c in starts[0].target.contacts:
        # As close to the contact as the IK's own virtual joints put it (the IK stops at d_min).
        placed = hand.contact_placement(read.q, c.finger).translation
        solved = hand.contact_placement(q, c.finger).translation
        assert np.linalg.norm(placed - c.point) <= np.linalg.norm(solved - c.point) + 1e-9
    # The wrist and the URDF joints stay as the plan gives them.
    assert np.allclose(read.q[:7], q[:7], atol=1e-12)
    assert hand.joint_values(read.q) == pytest.approx(hand.joint_values(q), abs=1e-12)


@pytest.mark.slow
def test_the_mesh_benchmark_row_starts_from_the_plan_and_verifies_the_optimum() -> None:
    from sahgrasp.bench.atlas import _mesh_object_row, mesh_objects

    assert mesh_objects()[:6] == ("fork", "cup", "buddha", "coffee_cup", "can", "bottle")
    assert {"mesh:mug.stl", "mesh:bottle.obj"} <= set(mesh_objects())
    row = _mesh_object_row("can", starts=1, rounds=2)
    assert row["start"]["fingers"][0] == "thumb" and len(row["start"]["fingers"]) >= 3
    (component,) = row["components"]
    assert component["starts"] == ["rank 1"] or row["skipped_starts"]
    # Verified by the planner's verifier, scored by the planner's index function as the start.
    assert row["verified"] and component["verified"]
    assert component["max_contact_error_mm"] <= 1.5 and component["max_link_depth_mm"] <= 0.5
    assert row["best_index"] >= component["best_index"]
    assert row["improved"] == (row["best_index"] > row["start_index"])
