import dataclasses
import math

import coal
import numpy as np
import pinocchio as pin
import pytest

from sahgrasp.collision.hand_self import SelfCollision
from sahgrasp.core.errors import InvalidSettingsError, InvalidTargetError, SequenceFileError
from sahgrasp.ik import (
    IKSettings,
    Sequence,
    default_sequence,
    hang_from_thumb,
    random_problems,
    solve_ik,
    solve_many,
)
from sahgrasp.ik.initial import expansion_matrix
from sahgrasp.ik.solver import (
    REPAIR_PATIENCE,
    Attempt,
    ContactProblem,
    _separate,
    run_algorithm1,
)
from sahgrasp.model.contacts import ContactTarget, GraspTarget
from sahgrasp.model.hand import Hand, load_hand
from sahgrasp.objects import BoxSolid, GraspObject, can_patches, load_object


def _plain_hand(hand: Hand, result_dict: dict) -> tuple[pin.Model, pin.Data, np.ndarray, pin.SE3]:
    """The plain URDF model (no virtual joints, no free flyer) at the returned joints and wrist."""
    model = pin.buildModelFromUrdf(str(hand.description.urdf_path), mimic=False)
    data = model.createData()
    q = pin.neutral(model)
    for name, value in result_dict["joints"].items():
        jid = model.getJointId(name)
        q[model.joints[jid].idx_q] = value
        assert model.lowerPositionLimit[model.joints[jid].idx_q] - 1e-9 <= value
        assert value <= model.upperPositionLimit[model.joints[jid].idx_q] + 1e-9
    for mimic, (leader, scale, offset) in hand.mimic_joints.items():
        assert result_dict["joints"][mimic] == pytest.approx(
            scale * result_dict["joints"][leader] + offset
        )
    wrist = result_dict["wrist"]
    pin.framesForwardKinematics(model, data, q)
    return model, data, q, pin.XYZQUATToSE3(np.array(wrist["xyz"] + wrist["quat"]))


def _independent_check(hand: Hand, target: GraspTarget, result_dict: dict, d_min: float) -> None:
    """Set the returned wrist and joints on the plain URDF and check the grasp there."""
    model, data, q, T_world_palm = _plain_hand(hand, result_dict)
    for finger in target.fingers:
        spec = hand.description.fingers[hand.fingers.index(finger)]
        centre = T_world_palm * data.oMf[model.getFrameId(spec.tip_link)].translation
        contact = target.contact(finger)
        assert np.linalg.norm(centre - contact.centre(hand.radius_m)) < d_min
        # The contact point is where the sphere touches the object: centre - R * normal.
        assert np.linalg.norm(centre - hand.radius_m * contact.normal - contact.point) < d_min
    urdf = str(hand.description.urdf_path)
    geometry = pin.buildGeomFromUrdf(model, urdf, pin.GeometryType.COLLISION)
    plain = SelfCollision(model, geometry, hand.description.excluded_collisions)
    assert not plain.in_collision(q)


def _object_distances(
    hand: Hand, result_dict: dict, pieces: list[tuple[coal.ShapeBase, coal.Transform3s]]
) -> dict[str, float]:
    """Signed distance [m] of every link of the plain URDF hand at the result to the object."""
    model, data, q, T_world_palm = _plain_hand(hand, result_dict)
    urdf = str(hand.description.urdf_path)
    geometry = pin.buildGeomFromUrdf(model, urdf, pin.GeometryType.COLLISION)
    geometry_data = pin.GeometryData(geometry)
    pin.updateGeometryPlacements(model, data, geometry, geometry_data, q)
    out: dict[str, float] = {}
    for obj, placement in zip(geometry.geometryObjects, geometry_data.oMg, strict=True):
        M = T_world_palm * placement
        at_link = coal.Transform3s(M.rotation, M.translation)
        link = model.frames[obj.parentFrame].name
        for shape, at_piece in pieces:
            d = coal.distance(shape, at_piece, obj.geometry, at_link,
                              coal.DistanceRequest(), coal.DistanceResult())  # fmt: skip
            out[link] = min(out.get(link, math.inf), d)
    return out


def _assert_outside(hand: Hand, distances: dict[str, float], contacts: tuple[str, ...]) -> None:
    """No link inside the object; the contact fingertip spheres not deeper than d_min."""
    tips = {f.tip_link for f in hand.description.fingers if f.name in contacts}
    for link, distance in distances.items():
        assert distance >= (-1.5e-3 if link in tips else -1e-9), (link, distance)


@pytest.mark.parametrize("method", ["auto", "paper"])
def test_known_solution_problems_are_solved_and_verified(sah: Hand, method: str) -> None:
    problems = random_problems(sah, 8, seed=11)
    results = [solve_ik(sah, p, method=method) for p in problems]
    solved = [(p, r) for p, r in zip(problems, results, strict=True) if r.success]
    assert len(solved) >= (7 if method == "auto" else 5)
    for problem, result in solved:
        assert result.reason == "converged"
        assert result.max_error_m < 1.5e-3
        _independent_check(sah, problem, result.to_dict(sah), 1.5e-3)


def test_allegro_problems_are_solved(allegro: Hand) -> None:
    results = [solve_ik(allegro, p) for p in random_problems(allegro, 5, seed=2)]
    assert sum(r.success for r in results) >= 4


def test_unreachable_targets_fail_with_reason(sah: Hand) -> None:
    far = GraspTarget(
        "far",
        [ContactTarget(f, [i * 1.0, 0.0, 0.0], [0.0, 0.0, 1.0]) for i, f in enumerate(sah.fingers)],
    )
    result = solve_ik(sah, far, max_inits=3)
    assert not result.success
    assert result.reason in ("max_inits", "no_progress")
    assert result.inits_used == 3
    # A contact behind the palm: the normal points into the hand.
    problem = random_problems(sah, 1, seed=5)[0]
    behind = GraspTarget(
        "behind",
        [ContactTarget(c.finger, c.point, -c.normal) if c.finger == "index" else c
         for c in problem.contacts],
    )  # fmt: skip
    assert not solve_ik(sah, behind, max_inits=3).success


def test_attempts_are_frozen_and_a_colliding_one_is_refused_by_a_new_record(sah: Hand) -> None:
    """The outer loop derives the checked attempt; the inner solver's record is never changed."""
    rng = np.random.default_rng(3)
    draws = (sah.random_configuration(rng) for _ in range(1000))
    colliding = next(q for q in draws if sah.in_collision(q))
    returned: list[Attempt] = []

    def claims_convergence(hand: Hand, problem, coords, s: IKSettings) -> Attempt:
        returned.append(Attempt(colliding.copy(), "converged", 4, 0.0, None))
        return returned[-1]

    target = random_problems(sah, 1, seed=8)[0]
    result = run_algorithm1(sah, target, claims_convergence, IKSettings(max_inits=2))
    assert not result.success and result.reason == "collision"
    assert result.attempts == ("collision", "collision") and result.iterations == 8
    assert [a.outcome for a in returned] == ["converged", "converged"]
    assert all(a.seconds == 0.0 for a in returned) and result.attempt_seconds[1] > 0.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        returned[0].outcome = "collision"  # type: ignore[misc]


def test_invalid_targets_raise(sah: Hand) -> None:
    problem = random_problems(sah, 1, seed=5)[0]
    with pytest.raises(InvalidTargetError, match="missing contact for the thumb"):
        solve_ik(sah, GraspTarget("x", problem.contacts[1:]))  # a finger may be free, not the thumb
    with pytest.raises(InvalidTargetError, match="given as free fingers too"):
        solve_ik(sah, problem, free_fingers=("ring",))
    pinky = [*problem.contacts[:3], ContactTarget("pinky", [0, 0, 0], [0, 0, 1])]
    with pytest.raises(InvalidTargetError, match="unknown finger"):
        solve_ik(sah, GraspTarget("x", pinky))
    with pytest.raises(InvalidSettingsError, match="method"):
        solve_ik(sah, problem, method="magic")


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("max_inits", 0, "max_inits must be an integer between 1 and 1000"),
        ("max_inits", 1001, "max_inits must be an integer between 1 and 1000"),
        ("max_inits", 10**9, "between 1 and 1000"),
        ("max_inits", 2.5, "max_inits must be an integer"),
        ("max_inits", "12", "max_inits must be an integer"),
        ("seed", -1, "seed must be an integer >= 0"),
        ("seed", True, "seed must be an integer"),
        ("max_iterations", 0, "max_iterations must be an integer between 1 and 1000000"),
        ("max_iterations", 10**12, "max_iterations must be an integer between 1 and 1000000"),
        ("init", "grid", r"init must be one of \['sequence', 'random', 'learned'\]"),
        ("method", "magic", r"method must be one of \['auto', 'paper'\]"),
        ("d_min_m", float("nan"), "d_min_m must be a finite number > 0"),
        ("alpha", float("inf"), "alpha must be a finite number > 0"),
        ("refine_m", "1e-5", "refine_m must be a finite number > 0"),
    ],
)
def test_bad_settings_raise_typed_errors(field: str, value: object, message: str) -> None:
    with pytest.raises(InvalidSettingsError, match=message):
        IKSettings(**{field: value})


def test_settings_bounds_are_inclusive() -> None:
    assert IKSettings(max_inits=1000, seed=0).max_inits == 1000
    assert IKSettings(max_inits=1, seed=2**63).max_inits == 1


def test_same_seed_same_result_any_workers(sah: Hand) -> None:
    # A solve first, so that workers=1 runs in a process that has solved before, the workers in
    # fresh ones: coal's broad phase once made these differ in the last bits of q.
    solve_ik(load_hand("sah"), random_problems(sah, 1, seed=4)[0])
    problems = random_problems(sah, 4, seed=8)
    settings = IKSettings(init="random", max_inits=4, seed=3)
    one = solve_many(sah, problems, settings, workers=1)
    two = solve_many(sah, problems, settings, workers=2)
    for a, b in zip(one, two, strict=True):
        assert (a.success, a.inits_used, a.iterations) == (b.success, b.inits_used, b.iterations)
        np.testing.assert_array_equal(a.q, b.q)


def test_thumb_hanging_satisfies_thumb_contact(sah: Hand) -> None:
    problem = random_problems(sah, 1, seed=4)[0]
    coords = default_sequence(sah).basis.coordinates(sah, (0.5, 0.5))
    q, _ = hang_from_thumb(sah, coords, problem)
    state = sah.contact_state(q)
    thumb = problem.contact("thumb")
    np.testing.assert_allclose(state.points[0], thumb.point, atol=1e-12)
    np.testing.assert_allclose(state.centres[0], thumb.centre(sah.radius_m), atol=1e-12)


def test_pose_basis_in_paper_q_space(sah: Hand) -> None:
    basis = default_sequence(sah).basis
    assert basis.mean.shape == (25,)  # Eq. (4): 25 joint values, coupled ones included
    np.testing.assert_allclose(np.linalg.norm(basis.directions, axis=1), 1.0)
    E = expansion_matrix(sah)
    # Principal directions move coupled joints together (they lie in the span of E).
    residual = basis.directions.T - E @ np.linalg.lstsq(E, basis.directions.T, rcond=None)[0]
    assert np.abs(residual).max() < 1e-9
    np.testing.assert_allclose(basis.pose((0.5, 0.5)), basis.mean)


def test_sequence_for_another_hand_is_refused(sah: Hand, allegro: Hand) -> None:
    problem = random_problems(sah, 1, seed=1)[0]
    with pytest.raises(SequenceFileError, match="cannot be used"):
        solve_ik(sah, problem, sequence=default_sequence(allegro))


def test_sequence_file_roundtrip_and_corruption(sah: Hand, tmp_path) -> None:
    path = tmp_path / "seq.json"
    default_sequence(sah).save(path)
    assert Sequence.load(path).lambdas == default_sequence(sah).lambdas
    path.write_text('{"format": "sahgrasp-sequence-1", "hand": "sah"}')
    with pytest.raises(SequenceFileError, match="not a valid"):
        Sequence.load(path)


def test_history_records_iterates(sah: Hand) -> None:
    problem = random_problems(sah, 1, seed=6)[0]
    result = solve_ik(sah, problem, record_history=True)
    assert result.history is not None
    assert len(result.history) >= 2
    np.testing.assert_array_equal(result.history[-1], result.q)


def test_paper_alpha_and_results_format(sah: Hand) -> None:
    problem = random_problems(sah, 1, seed=9)[0]
    entry = solve_ik(sah, problem, method="paper", alpha=0.8).to_dict(sah)
    assert set(entry["joints"]) == {*sah.joint_names, *sah.mimic_joints}
    assert len(entry["wrist"]["quat"]) == 4
    assert math.isfinite(entry["time_ms"])


def test_load_hand_fixture_is_the_sah() -> None:
    assert load_hand("sah").dof()["total"] == 27


# ----- the object as an obstacle --------------------------------------------------------------
def _pinch(width_m: float, spacing_m: float) -> GraspTarget:
    """Thumb on the +x face of a box ``width_m`` thick, the other fingers on the -x face."""
    contacts = [ContactTarget("thumb", [width_m / 2, 0, 0], [1, 0, 0])]
    for finger, y in zip(("index", "middle", "ring"), (-spacing_m, 0.0, spacing_m), strict=True):
        contacts.append(ContactTarget(finger, [-width_m / 2, y, 0.0], [-1, 0, 0]))
    return GraspTarget(f"pinch-{width_m}", contacts)


def _box(size_m: tuple[float, float, float]) -> tuple[GraspObject, list]:
    """A box centred at the world origin, and its coal shape for the independent check."""
    obj = GraspObject("box", (BoxSolid("box", size_m),), (1, 0, 0, 1))
    return obj, [(coal.Box(*size_m), coal.Transform3s(np.eye(3), np.zeros(3)))]


def test_box_grasp_with_the_object_leaves_it_alone(sah: Hand) -> None:
    target = _pinch(0.05, 0.03)
    box, pieces = _box((0.05, 0.12, 0.05))
    # From the sequence's starts (the learned start happens to miss the box here).
    plain = solve_ik(sah, target, init="sequence")
    assert plain.success and plain.object_clearance_m is None and plain.closest_link is None
    assert "object_clearance_mm" not in plain.to_dict(sah)
    # Without the object the thumb's distal phalanx goes into the box: the constraint matters.
    assert min(_object_distances(sah, plain.to_dict(sah), pieces).values()) < -0.5e-3
    result = solve_ik(sah, target, obstacle=box, init="sequence")
    assert result.success and result.reason == "converged"
    entry = result.to_dict(sah)
    _independent_check(sah, target, entry, 1.5e-3)
    distances = _object_distances(sah, entry, pieces)
    _assert_outside(sah, distances, sah.fingers)
    assert result.object_clearance_m is not None and result.object_clearance_m >= 0.0
    others = {k: v for k, v in distances.items() if k not in {f"{f}_tip" for f in sah.fingers}}
    assert result.object_clearance_m == pytest.approx(min(others.values()), abs=1e-6)
    assert result.closest_link == min(others, key=others.__getitem__)
    assert entry["object_clearance_mm"] == pytest.approx(result.object_clearance_m * 1e3)


def test_three_finger_can_grasp_keeps_the_free_finger_out(sah: Hand) -> None:
    can, target = load_object("can"), can_patches().target()
    pieces = [(s.geometry, s.transform(can.T_world_object)) for s in can.collision_shapes()]
    plain = solve_ik(sah, target, free_fingers=("ring",))
    assert plain.success
    assert _object_distances(sah, plain.to_dict(sah), pieces)["ring_distal"] < -0.01
    result = solve_ik(sah, target, free_fingers=("ring",), obstacle=can)
    assert result.success
    entry = result.to_dict(sah)
    _independent_check(sah, target, entry, 1.5e-3)
    # The free ring finger has no contact: its fingertip may not enter the can either.
    _assert_outside(sah, _object_distances(sah, entry, pieces), ("thumb", "index", "middle"))


def test_free_finger_is_returned_placed_clear_of_the_other_links(sah: Hand) -> None:
    from sahgrasp.collision.hand_object import HandObjectClearance

    for problem in random_problems(sah, 10, seed=7):
        target = GraspTarget(problem.name, [c for c in problem.contacts if c.finger != "ring"])
        result = solve_ik(sah, target, free_fingers=("ring",))
        assert result.success
        # Already placed: placing again leaves it where it is, and it is clear.
        again = HandObjectClearance(sah, None).place_free_fingers(result.q, ("ring",))
        assert again.clear
        np.testing.assert_array_equal(again.q, result.q)


@pytest.mark.parametrize("method", ["auto", "paper"])
def test_only_solutions_through_the_object_fail_with_object_collision(
    sah: Hand, method: str
) -> None:
    """A pinch across the middle of a 40 cm plate: the hand cannot reach around its edges."""
    target = _pinch(0.03, 0.03)
    plate, pieces = _box((0.03, 0.4, 0.4))
    plain = solve_ik(sah, target, method="auto")
    assert plain.success
    assert min(_object_distances(sah, plain.to_dict(sah), pieces).values()) < -0.01
    result = solve_ik(sah, target, obstacle=plate, method=method, max_inits=4)
    assert not result.success
    assert result.reason == "object_collision"
    assert "object_collision" in result.attempts
    assert result.object_clearance_m is not None and result.object_clearance_m < 0.0
    distances = _object_distances(sah, result.to_dict(sah), pieces)
    assert distances[result.closest_link] == pytest.approx(result.object_clearance_m, abs=1e-6)


def test_a_hopeless_object_repair_is_given_up_before_the_cap(sah: Hand) -> None:
    """The pinch through the plate: no step clears it and holds the contacts, so it stops early.

    Where the repair ends depends on the start: still in the plate, or out of it but colliding
    with itself; either way the configuration is refused.
    """
    target = _pinch(0.03, 0.03)
    plate, _ = _box((0.03, 0.4, 0.4))
    settings = IKSettings()
    plain = solve_ik(sah, target, method="auto")
    problem = ContactProblem(sah, target, (), plate, settings.d_min_m)
    q, used = _separate(sah, problem, plain.q, settings, None)
    assert REPAIR_PATIENCE <= used < settings.repair_iterations
    assert problem.collision(q) is not None


def test_obstacle_must_be_a_grasp_object(sah: Hand) -> None:
    problem = random_problems(sah, 1, seed=5)[0]
    with pytest.raises(InvalidTargetError, match="obstacle must be a GraspObject"):
        solve_ik(sah, problem, obstacle=coal.Box(0.1, 0.1, 0.1))
