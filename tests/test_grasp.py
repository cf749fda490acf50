"""Tests of the SAH feasible-grasp system F (Eqs. (1)-(9)), R (Eqs. (10)-(13)) and the PCA."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pinocchio as pin
import pytest

from sahgrasp.core.errors import (
    GraspSystemError,
    InvalidSettingsError,
    OptimizationError,
    PrincipalMotionsError,
)
from sahgrasp.ik import IKSettings
from sahgrasp.model.hand import Hand
from sahgrasp.objects import bottle_patches, can_patches, load_object
from sahgrasp.optimization import optimizer as optimization_module
from sahgrasp.optimization.grasp import (
    GraspSystem,
    coordinate_scales,
    first_grasp_system,
    hand_motions,
    make_sah_manifold,
    reduced_system,
)
from sahgrasp.optimization.motions import principal_motions
from sahgrasp.optimization.optimizer import OptimizationSettings, optimize

EXPECTED_T = {"can": 11, "bottle": 12, "bottle-spinless": 11}  # 16 + params + pose - 15
PATCHES = {"can": can_patches, "bottle": bottle_patches, "bottle-spinless": bottle_patches}
AXIS = (0.0, 0.0, 1.0)  # the bottle's axis: every contact region is revolved about it


@pytest.fixture(scope="module", params=list(EXPECTED_T))
def case(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.fixture(scope="module")
def system(case: str, sah: Hand) -> GraspSystem:
    axis = AXIS if case.endswith("spinless") else None
    return first_grasp_system(sah, PATCHES[case](), symmetry_axis=axis)


def central_differences(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> np.ndarray:
    h = 1e-6
    return np.stack([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(x.size)], axis=-1)


def perturbed(system: GraspSystem, seed: int, size: float = 0.05) -> np.ndarray:
    return system.x_first + size * np.random.default_rng(seed).normal(size=system.n)


def test_dimensions(case: str, system: GraspSystem, sah: Hand) -> None:
    assert system.t == EXPECTED_T[case]
    assert system.m == 15  # three contacts of 5 equations
    assert system.F(system.x_first).shape == (system.m,)
    fixed = GraspSystem(sah, system.patches, system.q_first, free_object=False)
    assert fixed.t == EXPECTED_T[system.patches.name] - 6


def test_spinning_the_bottle_moves_nothing(sah: Hand) -> None:
    """Spin about the axis while every contact angle slides back: a direction of F, hand still."""
    system = first_grasp_system(sah, bottle_patches())
    dx = np.zeros(system.n)
    dx[system.pose_slice.start + 3 :] = system.T_palm_object0.rotation @ AXIS
    for contact in system.contacts:
        dx[contact.params.start] = -1.0  # u: the angle about the axis
    assert np.allclose(system.J(system.x_first) @ dx, 0.0, atol=1e-12)
    with pytest.raises(GraspSystemError, match="symmetry_axis"):
        GraspSystem(sah, system.patches, system.q_first, True, symmetry_axis=(0.0, 0.0))


def test_first_grasp_is_a_regular_point_inside_the_bounds(system: GraspSystem) -> None:
    x = system.x_first
    residual = system.F(x).reshape(-1, 5)  # within the IK's tolerance on points and centres
    d_min = IKSettings().d_min_m
    assert np.abs(residual[:, :3]).max() <= d_min
    assert np.abs(residual[:, 3:]).max() <= 2 * d_min / system.hand.radius_m
    assert np.linalg.matrix_rank(system.J(x)) == system.m
    assert (x >= system.lower).all() and (x <= system.upper).all()
    assert system.object_pose(x).isApprox(system.T_palm_object0)


@pytest.mark.parametrize("seed", [None, 1, 2])
def test_jacobian_matches_central_differences(system: GraspSystem, seed: int | None) -> None:
    x = system.x_first if seed is None else perturbed(system, seed)
    assert np.allclose(system.J(x), central_differences(system.F, x), rtol=0, atol=1e-7)


def test_jacobian_with_the_object_fixed(system: GraspSystem, sah: Hand) -> None:
    fixed = GraspSystem(sah, system.patches, system.q_first, free_object=False)
    x = perturbed(fixed, 3)
    assert np.allclose(fixed.J(x), central_differences(fixed.F, x), rtol=0, atol=1e-7)


def test_evaluations_do_not_depend_on_the_call_order(system: GraspSystem) -> None:
    x, y = perturbed(system, 4), perturbed(system, 5)
    f, jac = system.F(x).copy(), system.J(x).copy()
    system.J(y), system.hard_finger_constraints(y)
    assert np.array_equal(system.J(x), jac) and np.array_equal(system.F(x), f)
    z = x.copy()
    system.F(z)
    z[0] += 0.1  # a caller changing its array in place gets the new value
    assert not np.array_equal(system.F(z), f)


def test_evaluations_leave_the_hands_data_alone(system: GraspSystem, sah: Hand) -> None:
    """F and J compute in the system's own Pinocchio Data, not in the hand's shared one."""
    sah.contact_jacobians(sah.random_configuration(np.random.default_rng(6)))
    placements = np.array([M.homogeneous for M in sah.data.oMi])
    joint_jacobians = np.array(sah.data.J)
    x = perturbed(system, 7)
    system.F(x), system.J(x)
    assert np.array_equal(np.array([M.homogeneous for M in sah.data.oMi]), placements)
    assert np.array_equal(np.array(sah.data.J), joint_jacobians)


def test_object_velocity_is_the_twist_of_the_pose(system: GraspSystem) -> None:
    x = perturbed(system, 6)
    dx = np.random.default_rng(7).normal(size=system.n)
    h = 1e-6
    T0, T1 = system.object_pose(x - h * dx), system.object_pose(x + h * dx)
    linear = (T1.translation - T0.translation) / (2 * h)
    angular = pin.log3(T1.rotation @ T0.rotation.T) / (2 * h)
    assert np.allclose(system.object_velocity(x) @ dx, np.concatenate((linear, angular)), atol=1e-7)


def test_hard_finger_constraints_match_the_contact_point_velocities(system: GraspSystem) -> None:
    """C (qdot, nu) = d/dt (fingertip material point - object material point), per contact.

    The actuated joints move by ``qdot`` with the virtual contact joints held (the touching point
    stays the same point of the fingertip); the object moves by the twist ``nu``, world-aligned at
    its origin (the touching point stays the same point of the object).
    """
    x = perturbed(system, 8, size=0.02)
    C = system.hard_finger_constraints(x)
    a = len(system.actuated_rows)
    assert C.shape == (3 * len(system.contacts), a + 6)
    T = system.object_pose(x)
    frames = [c.frame for c in system.contacts]
    model = system.hand.model
    data = model.createData()  # the test's own: the hand's Data is not shared state
    pin.forwardKinematics(model, data, system.configuration(x))
    local = [T.actInv(pin.updateFramePlacement(model, data, f).translation) for f in frames]

    def gap(h: float, z: np.ndarray) -> np.ndarray:
        y = x.copy()
        y[system.hand_rows[system.actuated_rows]] += h * z[:a]
        pin.forwardKinematics(model, data, system.configuration(y))
        moved = pin.SE3(pin.exp3(h * z[a + 3 :]) @ T.rotation, T.translation + h * z[a : a + 3])
        tips = [pin.updateFramePlacement(model, data, f).translation for f in frames]
        return np.concatenate([tip - moved.act(p) for tip, p in zip(tips, local, strict=True)])

    rng = np.random.default_rng(9)
    for z in rng.normal(size=(3, a + 6)):
        h = 1e-6
        velocity = (gap(h, z) - gap(-h, z)) / (2 * h)
        assert np.allclose(C @ z, velocity, rtol=0, atol=1e-7)


def test_reduced_system(system: GraspSystem, sah: Hand) -> None:
    rng = np.random.default_rng(10)
    h = len(system.coordinates)
    motions = principal_motions(rng.normal(size=(200, h)) * np.linspace(2.0, 0.1, h))
    for k in (1, 2, system.t):
        R, JR = reduced_system(system, motions, k)
        x = perturbed(system, k)
        s = system.t - k
        assert R(x).shape == (system.m + s,)
        assert np.allclose(JR(x), central_differences(R, x), rtol=0, atol=1e-7)
        assert np.allclose(R(system.x_first)[system.m :], 0.0)
        assert np.linalg.matrix_rank(JR(system.x_first)) == system.m + s  # R has dimension k
    for k in (0, system.t + 1):
        with pytest.raises(GraspSystemError, match="k must"):
            reduced_system(system, motions, k)
    few = principal_motions(rng.normal(size=(50, 2)))  # h = 2 <= s = t - 1
    with pytest.raises(PrincipalMotionsError, match="s = t - k"):
        reduced_system(system, few, 1)


def test_principal_motions_ordering_and_orthonormality() -> None:
    rng = np.random.default_rng(11)
    mixing = np.linalg.qr(rng.normal(size=(4, 4)))[0]
    samples = 3.0 + (rng.normal(size=(5000, 4)) * [3.0, 1.0, 0.3, 0.1]) @ mixing.T
    motions = principal_motions(samples)
    E, variances = motions.directions, motions.variances
    assert np.all(np.diff(variances) <= 0)
    assert np.allclose(E.T @ E, np.eye(4))
    assert np.allclose(np.abs(E.T @ mixing), np.eye(4), atol=0.05)  # recovers the mixing axes
    assert np.allclose(variances, np.var(samples @ E, axis=0, ddof=1))
    assert np.allclose(motions.mean, samples.mean(axis=0))
    assert np.array_equal(motions.constraints(2), E[:, 2:].T)
    assert motions.constraints(0).shape == (0, 4)
    assert motions.retained_variance(0) == pytest.approx(1.0)
    assert motions.retained_variance(3) == pytest.approx(variances[0] / variances.sum())
    with pytest.raises(PrincipalMotionsError, match="s = t - k"):
        motions.constraints(4)


def test_the_free_finger_is_no_part_of_f(sah: Hand) -> None:
    """The can leaves the ring finger free: its joints are not in x and do not move F."""
    system = first_grasp_system(sah, can_patches())
    ring = {sah.coordinate_index(n) for n in sah.coordinate_names if n.startswith("ring_")}
    assert not ring & set(system.coordinates.tolist())
    assert "ring" not in [c.finger for c in system.contacts]
    folded = system.q_first.copy()
    sah.finger_part(folded)[sorted(ring)] = sah.lower[sorted(ring)]
    other = GraspSystem(sah, system.patches, folded, free_object=True)
    x = perturbed(system, seed=3)
    assert np.array_equal(other.x_first, system.x_first)
    assert np.array_equal(other.F(x), system.F(x)) and np.array_equal(other.J(x), system.J(x))


def test_principal_motions_from_grasp_postures(sah: Hand) -> None:
    """Solved grasps of the bottle's regions vary along fewer motions than random hand poses."""
    system = first_grasp_system(sah, bottle_patches(), symmetry_axis=AXIS)
    grasps = hand_motions(sah, system, 30, seed=1, source="grasps")
    random = hand_motions(sah, system, 300, seed=1, source="random")
    h = len(system.coordinates)
    assert grasps.directions.shape == (h, h)
    s = system.t - 2  # k = 2: the motions kept are h - s
    assert grasps.retained_variance(s) > random.retained_variance(s) + 0.1
    with pytest.raises(OptimizationError, match="unknown motion source 'human'"):
        hand_motions(sah, system, 10, seed=1, source="human")


def test_coordinate_scales_make_every_direction_move_alike(sah: Hand) -> None:
    system = first_grasp_system(sah, can_patches())
    scales = coordinate_scales(system, 0.1)
    assert np.all(scales[system.hand_rows] == 1.0)  # joint angles [rad]
    pose = system.pose_slice.start
    assert np.all(scales[pose : pose + 3] == 0.1) and np.all(scales[pose + 3 :] == 1.0)
    for contact in system.contacts:  # a unit of y moves the contact by 0.1 m
        jet = contact.region.evaluate(contact.region.nominal)
        moved = np.linalg.norm(jet.point_jacobian * scales[contact.params], axis=0)
        assert np.allclose(moved[moved > 0], 0.1)
    with pytest.raises(GraspSystemError, match="length_m"):
        coordinate_scales(system, 0.0)


@pytest.mark.slow
def test_chart_checks_on_worker_processes_are_those_of_this_process(
    sah: Hand, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The can leaves the ring free: workers place it and check both collisions as here."""
    monkeypatch.setattr(optimization_module, "_CHECK_BATCH", 8)  # several batches during the build
    problem = make_sah_manifold(sah, can_patches(), k=2, obj=load_object("can"))
    here = optimize(problem, OptimizationSettings(radius=0.15, epsilon=0.5))
    spread = optimize(problem, OptimizationSettings(radius=0.15, epsilon=0.5, workers=2))
    assert here.atlas.n_charts > 16  # more centres than runs: several runs per worker
    assert np.array_equal(spread.atlas.centres, here.atlas.centres)
    for name in ("configurations", "self_collision", "object_collision"):
        assert np.array_equal(getattr(spread.checks, name), getattr(here.checks, name))
    free = problem.system.hand.finger_coordinates["ring"]
    assert not np.array_equal(
        here.configurations[:, free],
        problem.system.configuration(problem.x_of(here.atlas.centres[0]))[None, free].repeat(
            here.atlas.n_charts, 0
        ),
    )
    assert (spread.best, spread.worst) == (here.best, here.worst)


@pytest.mark.parametrize("workers", [-1, 1.5, True])
def test_optimization_workers_must_be_a_count(workers: object) -> None:
    with pytest.raises(InvalidSettingsError, match="workers must be an integer"):
        OptimizationSettings(radius=0.15, epsilon=0.5, workers=workers)  # type: ignore[arg-type]
