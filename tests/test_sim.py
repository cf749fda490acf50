"""The physics hold test: paper grasps hold; broken ones (moved, opened, frictionless) do not."""

from __future__ import annotations

import dataclasses
from functools import cache

import numpy as np
import pinocchio as pin
import pytest

pytest.importorskip("mujoco")

from sahgrasp.core.errors import InvalidSettingsError
from sahgrasp.ik import IKResult, solve_ik
from sahgrasp.model.hand import Hand, load_hand
from sahgrasp.objects import BoxSolid, GraspObject, load_object, paper_grasp
from sahgrasp.sim import (
    LIGHT_SQUEEZE_N,
    HoldSettings,
    HoldTester,
    dexgraspbench_solver,
    hold_test,
    soft_friction,
)


@cache
def _sah() -> Hand:
    return load_hand("sah")


@cache
def _solved(name: str) -> IKResult:
    result = solve_ik(_sah(), paper_grasp(name))
    assert result.success
    return result


@cache
def _tester(name: str, **settings: float) -> HoldTester:
    return HoldTester(_sah(), load_object(name), HoldSettings(**settings))


def test_can_grasp_holds() -> None:
    result = _tester("can").test(_solved("can"))
    assert result.holds, result.detail
    assert result.holds_bodex
    assert result.reason == "holds"
    assert [d.direction for d in result.directions] == ["+x", "-x", "+y", "-y", "+z", "-z"]
    assert all(d.displacement_m < 0.02 and d.rotation_deg < 15 for d in result.directions)
    assert result.contact_fingers == ("thumb", "index", "middle", "ring")
    assert result.initial_penetration_m < 1e-3
    assert result.squeeze_imbalance_n < 0.05 * sum(result.squeeze_normal_n)
    assert np.mean(result.squeeze_normal_n) == pytest.approx(HoldSettings().squeeze_n, rel=0.05)
    assert result.mass_kg == pytest.approx(0.379, rel=0.01)


def test_only_the_named_contact_fingers_squeeze() -> None:
    # A planned grasp names its contact fingers: the others are free and do not squeeze, even
    # with their fingertips on the object.
    squeeze, *_ = _tester("can").squeeze(_solved("can").q, ("thumb", "index", "middle"))
    assert squeeze.fingers == ("thumb", "index", "middle")
    assert np.mean(squeeze.normal_forces_n) == pytest.approx(HoldSettings().squeeze_n, rel=0.05)
    result = _tester("can").test(_solved("can"), fingers=("thumb", "index", "middle"))
    assert result.contact_fingers == ("thumb", "index", "middle")


def test_can_moved_away_does_not_hold() -> None:
    obj = load_object("can")
    T = obj.T_world_object.copy()
    T[:3, 3] += [0.0, 0.0, 0.15]  # 15 cm along the can axis: the fingertips touch nothing
    result = hold_test(_sah(), _solved("can"), obj.placed(T))
    assert not result.holds and not result.holds_bodex
    assert result.reason == "no contact"


def test_can_with_thumb_opened_does_not_hold() -> None:
    hand, q = _sah(), _solved("can").q.copy()
    q[7 + hand.coordinate_index("thumb_j2")] = hand.upper[hand.coordinate_index("thumb_j2")]
    q[7 + hand.coordinate_index("thumb_j3")] = hand.upper[hand.coordinate_index("thumb_j3")]
    result = _tester("can").test(q)
    assert "thumb" not in result.contact_fingers
    assert not result.holds and not result.holds_bodex


def test_can_without_friction_does_not_hold() -> None:
    result = _tester("can", friction=0.0).test(_solved("can"))
    assert not result.holds
    assert result.reason in {"slips", "turns", "moved while settling"}


def test_result_json_has_every_direction() -> None:
    entry = _tester("can").test(_solved("can"), name="can").to_dict()
    assert entry["name"] == "can"
    assert {d["direction"] for d in entry["directions"]} == {"+x", "-x", "+y", "-y", "+z", "-z"}
    assert set(entry["directions"][0]) >= {"displacement_m", "rotation_deg", "holds"}


@pytest.mark.parametrize(
    "change",
    [
        {"friction": -0.1},
        {"friction": float("nan")},
        {"squeeze_n": 0.0},
        {"mass_kg": 0.0},
        {"timestep_s": 0.05},
        {"solver_iterations": 0},
        {"ls_iterations": 0},
        {"ls_iterations": 2.5},
        {"balance_friction": 2.0},
        {"pull_s": "1"},
        {"stop_at_rest": "yes"},
        {"stop_at_first_failure": 1},
    ],
)
def test_bad_settings_are_refused(change: dict[str, object]) -> None:
    with pytest.raises(InvalidSettingsError):
        dataclasses.replace(HoldSettings(), **change)  # type: ignore[arg-type]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["cup", "buddha", "can"])
def test_paper_grasps_hold(name: str) -> None:
    result = _tester(name).test(_solved(name))
    assert result.holds, result.detail
    assert result.holds_bodex


def test_dexgraspbench_solver_changes_the_solver_only() -> None:
    base = HoldSettings(squeeze_n=LIGHT_SQUEEZE_N, mass_kg=0.1)
    solver = dexgraspbench_solver(base)
    assert (solver.timestep_s, solver.impratio, solver.noslip_iterations) == (0.004, 10.0, 2)
    # DexGraspBench's 5 ms contact time constant is below MuJoCo's floor of two steps.
    assert solver.contact_timeconst_s == 2 * solver.timestep_s
    assert (solver.solver_iterations, solver.ls_iterations) == (100, 50)
    kept = ("squeeze_n", "mass_kg", "friction", "patch_radius_m", "pull_s",
            "max_displacement_m", "max_rotation_deg", "directions")  # fmt: skip
    assert all(getattr(solver, k) == getattr(base, k) for k in kept)
    assert dexgraspbench_solver().squeeze_n == HoldSettings().squeeze_n


@pytest.mark.slow
@pytest.mark.parametrize("name", ["cup", "buddha", "can"])
def test_paper_grasps_hold_in_dexgraspbenchs_solver_settings(name: str) -> None:
    # The cross-check: stiff friction (impratio 10) and the no-slip post-solver converge with
    # MuJoCo's 50 line-search iterations; the squeeze settles without dragging the object.
    tester = HoldTester(_sah(), load_object(name), dexgraspbench_solver())
    result = tester.test(_solved(name))
    assert result.holds, result.detail
    assert result.settle_displacement_m < 0.002 and result.settle_rotation_deg < 2.0


@pytest.mark.slow
def test_can_without_friction_does_not_hold_in_dexgraspbenchs_solver_settings() -> None:
    settings = dexgraspbench_solver(HoldSettings(friction=0.0))
    result = HoldTester(_sah(), load_object("can"), settings).test(_solved("can"))
    assert not result.holds


@pytest.mark.slow
def test_coffee_cup_paper_grasp_holds_unless_the_friction_creeps() -> None:
    # The default model's friction sticks inside its cone (no-slip post-solver, impratio 10):
    # the grasp holds. MuJoCo's soft friction lets the contacts creep and the cup turns by
    # about the 15 degree limit over a 1 s pull (docs/methods/physics.md, "Which MuJoCo
    # settings").
    result = _tester("coffee_cup").test(_solved("coffee_cup"))
    assert result.holds, result.detail
    creeping = HoldTester(_sah(), load_object("coffee_cup"), soft_friction())
    assert not creeping.test(_solved("coffee_cup")).holds


def test_soft_friction_changes_the_solver_only() -> None:
    base = HoldSettings(squeeze_n=LIGHT_SQUEEZE_N, mass_kg=0.1)
    soft = soft_friction(base)
    assert (soft.impratio, soft.noslip_iterations, soft.timestep_s) == (1.0, 0, 0.01)
    assert soft.contact_timeconst_s == 2 * soft.timestep_s
    assert dataclasses.replace(soft, impratio=base.impratio, noslip_iterations=2,
                               timestep_s=base.timestep_s,
                               contact_timeconst_s=base.contact_timeconst_s) == base  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize("name", ["cup", "can", "coffee_cup"])
def test_ending_pulls_at_rest_keeps_the_verdicts(name: str) -> None:
    # A pull that has come to rest under its constant force stays at rest: ending it early
    # gives the verdict and nearly the motion of the full second.
    full = HoldTester(_sah(), load_object(name), HoldSettings(stop_at_rest=False))
    early, whole = _tester(name).test(_solved(name)), full.test(_solved(name))
    assert (early.holds, early.reason) == (whole.holds, whole.reason)
    assert early.simulated_s < whole.simulated_s
    for a, b in zip(early.directions, whole.directions, strict=True):
        assert a.displacement_m == pytest.approx(b.displacement_m, abs=5e-4)
        assert a.rotation_deg == pytest.approx(b.rotation_deg, abs=0.5)


@pytest.mark.slow
def test_fork_edge_pinch_holds_with_a_light_squeeze_only() -> None:
    # The fork is pinched on the rounded edge (radius 0.6 mm) of a 5 mm plate: rigid fingertips
    # pressing hard roll it over, a light squeeze holds it (docs/methods/physics.md).
    light = _tester("fork", squeeze_n=LIGHT_SQUEEZE_N)
    assert light.test(_solved("fork")).holds
    assert not _tester("fork").test(_solved("fork")).holds


@pytest.mark.slow
@pytest.mark.parametrize("name", ["cup", "buddha", "coffee_cup", "can"])
def test_paper_grasps_without_friction_do_not_hold(name: str) -> None:
    assert not _tester(name, friction=0.0).test(_solved(name)).holds


def _pinch() -> tuple[np.ndarray, GraspObject]:
    """Thumb and index of the can grasp pinching a box, the pinch along world x; others open."""
    hand = _sah()
    q = _solved("can").q.copy()
    for joint in ("middle_j2", "middle_j3", "ring_j2", "ring_j3"):
        k = hand.coordinate_index(joint)
        q[7 + k] = hand.upper[k]
    state = hand.contact_state(q)
    thumb, index = state.centres[0], state.centres[1]
    turn = pin.SE3(pin.Quaternion.FromTwoVectors(index - thumb, np.array([1.0, 0, 0])).matrix(),
                   np.zeros(3))  # fmt: skip
    q[:7] = pin.SE3ToXYZQUAT(turn * hand.wrist_pose(q))
    T = np.eye(4)
    T[:3, 3] = turn.act(0.5 * (thumb + index))
    width_m = np.linalg.norm(index - thumb) - 2 * hand.radius_m
    box = BoxSolid("box", (width_m, 0.03, 0.03))
    return q, GraspObject("pinched box", (box,), (0.5, 0.5, 0.5, 1.0), T)


def _slip_mass(q: np.ndarray, obj: GraspObject, direction: str, predicted_kg: float,
               squeeze_n: float, friction: float) -> float:  # fmt: skip
    """The mass [kg] at which a pull along ``direction`` starts to slip (bisection)."""
    low, high = 0.5 * predicted_kg, 1.5 * predicted_kg
    for _ in range(5):
        mass = 0.5 * (low + high)
        settings = HoldSettings(mass_kg=mass, squeeze_n=squeeze_n, friction=friction,
                                directions=(direction,))  # fmt: skip
        pull = HoldTester(_sah(), obj, settings).test(q).directions[0]
        low, high = (mass, high) if pull.displacement_m < 0.02 else (low, mass)
    return 0.5 * (low + high)


@pytest.mark.slow
@pytest.mark.parametrize(("squeeze_n", "friction"), [(5.0, 0.6), (2.0, 0.3)])
def test_pinch_slips_at_coulombs_limit(squeeze_n: float, friction: float) -> None:
    q, obj = _pinch()
    result = HoldTester(_sah(), obj, HoldSettings(squeeze_n=squeeze_n)).test(q)
    assert result.contact_fingers == ("thumb", "index")
    # Two contacts, each pressing squeeze_n: friction holds up to friction * 2 * squeeze_n.
    predicted_kg = friction * 2 * squeeze_n / 9.81
    slips = [
        _slip_mass(q, obj, d, predicted_kg, squeeze_n, friction) for d in ("+y", "-y", "+z", "-z")
    ]
    # A position-servoed finger presses harder when pulled one way along the surface and less
    # the other way; over the four tangential pulls that evens out.
    assert np.mean(slips) == pytest.approx(predicted_kg, rel=0.15)
    assert all(abs(m / predicted_kg - 1) < 0.3 for m in slips), slips


@pytest.mark.slow
def test_allegro_can_grasp_is_simulated() -> None:
    allegro = load_hand("allegro")
    result = solve_ik(allegro, paper_grasp("can"), obstacle=load_object("can"))
    assert result.success
    held = hold_test(allegro, result, load_object("can"))
    assert held.contact_fingers == ("thumb", "index", "middle", "ring")
    assert held.holds, held.detail


def test_contact_jacobian_matches_finite_differences() -> None:
    import mujoco

    tester = _tester("can")
    squeeze, _, _, _ = tester.squeeze(_solved("can").q)
    sim, m, d = tester.sim, tester.sim.model, tester.sim.data
    J = tester.contact_jacobian(squeeze.fingers, squeeze.points_m)
    # The points fixed to their fingertip bodies, in each body's frame.
    bodies = [sim.fingertip_bodies[f] for f in squeeze.fingers]
    pairs = zip(bodies, squeeze.points_m, strict=True)
    local = [d.xmat[b].reshape(3, 3).T @ (p - d.xpos[b]) for b, p in pairs]
    qpos0 = d.qpos.copy()
    followers = {leader: (dof, k) for dof, leader, k in sim.mimic}

    def points(column: int, step: float) -> np.ndarray:
        d.qpos[:] = qpos0
        d.qpos[m.jnt_qposadr[m.dof_jntid[sim.actuated_dofs[column]]]] += step
        if column in followers:  # a coupled joint turns with its leader
            dof, k = followers[column]
            d.qpos[m.jnt_qposadr[m.dof_jntid[dof]]] += k * step
        mujoco.mj_kinematics(m, d)
        return np.concatenate(
            [d.xpos[b] + d.xmat[b].reshape(3, 3) @ x for b, x in zip(bodies, local, strict=True)]
        )

    h = 1e-6
    numeric = np.column_stack([(points(c, h) - points(c, -h)) / (2 * h) for c in range(m.nu)])
    d.qpos[:] = qpos0
    mujoco.mj_kinematics(m, d)
    assert np.abs(numeric).max() > 0.01  # the fingers do move their contacts
    np.testing.assert_allclose(J, numeric, atol=1e-7)


def test_balanced_forces_of_a_pinch_and_of_one_side() -> None:
    from sahgrasp.sim.hold import balanced_forces

    points = np.array([[-0.02, 0.0, 0.0], [0.02, 0.0, 0.0]])
    normals = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    forces = balanced_forces(points, normals, np.zeros(3), 0.05, 4.0, 0.3)
    np.testing.assert_allclose(forces, [[4.0, 0, 0], [-4.0, 0, 0]], atol=1e-6)
    # Three fingers pressing from one side cannot balance: the residual says so.
    side = np.array([[0.02, y, 0.0] for y in (-0.02, 0.0, 0.02)])
    pushed = balanced_forces(side, np.tile([-1.0, 0, 0], (3, 1)), np.zeros(3), 0.05, 4.0, 0.3)
    assert np.linalg.norm(pushed.sum(axis=0)) > 1.0
