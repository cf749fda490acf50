"""Hand-object clearance (sahgrasp.collision.hand_object), checked against coal directly."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest

from sahgrasp.collision.hand_object import HandObjectClearance
from sahgrasp.collision.hand_self import CollisionPair
from sahgrasp.core.errors import InvalidConfigurationError, InvalidSettingsError, InvalidTargetError
from sahgrasp.experiments.ik_examples import solve_example
from sahgrasp.experiments.setups import SAH_EXPERIMENTS, run_experiment
from sahgrasp.ik import IKSettings, solve_ik
from sahgrasp.model.hand import Hand
from sahgrasp.objects import (
    GRASP_NAMES,
    BoxSolid,
    GraspObject,
    can_patches,
    load_object,
    placement,
)

CUBE_M = 0.004


def _cube_at(centre_m: np.ndarray, rotation: np.ndarray | None = None) -> GraspObject:
    return GraspObject(
        "cube", (BoxSolid("cube", (CUBE_M,) * 3),), (1, 0, 0, 1), placement(rotation, centre_m)
    )


def _mid_hand(hand: Hand) -> np.ndarray:
    return hand.configuration(pin.SE3.Identity())  # every joint mid-range


def _geometry_world(hand: Hand, q: np.ndarray) -> tuple[list[str], list[pin.SE3]]:
    gm = hand.collision.geometry_model
    gd = pin.GeometryData(gm)
    pin.updateGeometryPlacements(hand.model, hand.model.createData(), gm, gd, q)
    links = [hand.model.frames[g.parentFrame].name for g in gm.geometryObjects]
    return links, [gd.oMg[i].copy() for i in range(len(links))]


def _link_centre(hand: Hand, q: np.ndarray, link: str) -> np.ndarray:
    links, placements = _geometry_world(hand, q)
    return placements[links.index(link)].translation


def test_box_through_a_phalanx_is_named(sah: Hand) -> None:
    q = _mid_hand(sah)
    cube = _cube_at(_link_centre(sah, q, "index_middle"))
    checker = HandObjectClearance(sah, cube)
    result = checker.clearance(q)
    assert result.link == "index_middle"
    assert result.distance_m < -CUBE_M / 2
    assert not result.clear()
    penetrations = checker.penetrations(q, 0.0)
    assert {p.joint_b for p in penetrations} == {int(sah.model.getJointId("index_j3"))}
    assert all(p.joint_a == 0 for p in penetrations)
    assert penetrations[0].depth_m == pytest.approx(-result.distance_m)


def test_far_hand_distance_matches_coal(sah: Hand) -> None:
    q = _mid_hand(sah)
    far = np.array([0.3, -0.2, 0.5])
    checker = HandObjectClearance(sah, _cube_at(far))
    result = checker.clearance(q)
    links, placements = _geometry_world(sah, q)
    box, at_box = coal.Box(CUBE_M, CUBE_M, CUBE_M), coal.Transform3s(np.eye(3), far)
    expected = {}
    geometries = sah.collision.geometry_model.geometryObjects
    for link, geom, M in zip(links, geometries, placements, strict=True):
        at_link = coal.Transform3s(M.rotation, M.translation)
        d = coal.distance(
            box, at_box, geom.geometry, at_link, coal.DistanceRequest(), coal.DistanceResult()
        )
        expected[link] = min(expected.get(link, np.inf), d)
    closest = min(expected, key=expected.__getitem__)
    assert result.link == closest
    assert result.distance_m == pytest.approx(expected[closest], abs=1e-9)
    assert result.distance_m > 0.3
    assert result.links_m == pytest.approx(expected, abs=1e-9)
    assert checker.penetrations(q, margin_m=0.01) == []


def _tip_probe(hand: Hand, q: np.ndarray, overlap_m: float) -> GraspObject:
    """A cube beyond the index fingertip whose face enters its sphere by ``overlap_m``."""
    tip = hand.frame_placements(q)["index_tip"]
    outward = tip.rotation @ np.array([0.0, 1.0, 0.0])  # the SAH fingertip axis
    centre = tip.translation + outward * (hand.radius_m - overlap_m + CUBE_M / 2)
    return _cube_at(centre, tip.rotation)  # a face normal to the fingertip axis


def test_contact_tip_within_allowance_is_not_reported(sah: Hand) -> None:
    q = _mid_hand(sah)
    checker = HandObjectClearance(sah, _tip_probe(sah, q, 1.0e-3))
    assert checker.penetrations(q, 0.0, contacts=("index",)) == []
    touching = checker.clearance(q, contacts=("index",))
    assert touching.clear()
    assert touching.link != "index_tip"
    assert touching.links_m["index_tip"] == pytest.approx(-1.0e-3, abs=1e-6)
    # Without the contact, the same tip is a penetration.
    (free,) = checker.penetrations(q, 0.0)
    assert free.depth_m == pytest.approx(1.0e-3, abs=1e-6)
    assert checker.clearance(q).link == "index_tip"


def test_contact_tip_beyond_allowance_is_reported(sah: Hand) -> None:
    q = _mid_hand(sah)
    checker = HandObjectClearance(sah, _tip_probe(sah, q, 2.5e-3))
    (deep,) = checker.penetrations(q, 1e-3, contacts=("index",), allowance_m=1.5e-3)
    assert deep.depth_m == pytest.approx(1.0e-3, abs=1e-6)  # the margin does not apply to it
    assert checker.clearance(q, contacts=("index",)).distance_m == pytest.approx(-2.5e-3, 1e-3)
    # Moving the tip along the normal by the depth brings it back to the allowance.
    assert np.linalg.norm(deep.normal) == pytest.approx(1.0)
    assert deep.normal @ (deep.point_b - deep.point_a) < 0.0  # witnesses cross inside


def test_object_placement_override(sah: Hand) -> None:
    q = _mid_hand(sah)
    centre = _link_centre(sah, q, "palm")
    checker = HandObjectClearance(sah, _cube_at(np.zeros(3)))
    assert checker.clearance(q, T_world_object=placement(None, centre)).link == "palm"


def test_bad_input_is_typed(sah: Hand) -> None:
    checker = HandObjectClearance(sah, _cube_at(np.ones(3)))
    q = _mid_hand(sah)
    with pytest.raises(InvalidTargetError, match="pinky"):
        checker.penetrations(q, contacts=("pinky",))
    with pytest.raises(InvalidSettingsError, match="allowance_m"):
        checker.clearance(q, allowance_m=-1.0)
    with pytest.raises(InvalidSettingsError, match="margin_m"):
        checker.penetrations(q, margin_m=float("nan"))
    with pytest.raises(InvalidConfigurationError):
        checker.clearance(q[:5])


@pytest.fixture(scope="module")
def can_grasp(sah: Hand) -> tuple[np.ndarray, GraspObject]:
    """The IK's three-finger grasp of the atlas paper's can: its free ring finger is in the can."""
    result = solve_ik(sah, can_patches().target(), free_fingers=("ring",))
    assert result.success
    return result.q, load_object("can")


def test_free_finger_is_placed_clear(sah: Hand, can_grasp: tuple[np.ndarray, GraspObject]) -> None:
    q, can = can_grasp
    checker = HandObjectClearance(sah, can)
    contacts = ("thumb", "index", "middle")
    assert checker.clearance(q, contacts).links_m["ring_distal"] < -0.01
    placed = checker.place_free_fingers(q, ["ring"], margin_m=2e-3)
    assert placed.clear and placed.distance_m >= 2e-3
    ring = [sah.coordinate_index(f"ring_j{j}") for j in (1, 2, 3)]
    moved = np.flatnonzero(placed.q[7:] != q[7:])
    assert set(moved) <= set(ring) and moved.size
    assert np.array_equal(placed.q[:7], q[:7])
    after = checker.clearance(placed.q, contacts)
    assert (
        min(after.links_m[f"ring_{link}"] for link in ("proximal", "middle", "distal", "tip"))
        >= 2e-3
    )
    assert not sah.in_collision(placed.q)
    # A finger that already is clear stays where it is.
    assert np.array_equal(checker.place_free_fingers(placed.q, ["ring"]).q, placed.q)


def test_free_finger_inside_a_big_box_is_not_clear(sah: Hand) -> None:
    q = _mid_hand(sah)
    box = GraspObject("box", (BoxSolid("box", (0.5, 0.5, 0.5)),), (1, 0, 0, 1))
    placed = HandObjectClearance(sah, box).place_free_fingers(q, ["ring"])
    assert not placed.clear and placed.distance_m < -0.05
    with pytest.raises(InvalidTargetError, match="pinky"):
        HandObjectClearance(sah, box).place_free_fingers(q, ["pinky"])


# ----- every shipped grasp, checked with coal alone -------------------------------------------
TOLERANCE_M = 0.2e-3


def _coal_depths(
    hand: Hand, q: np.ndarray, obj: GraspObject, T_world_object: np.ndarray, contacts: set[str]
) -> dict[str, float]:
    """Depth [m] of every link inside ``obj`` but the contact fingertips, by brute-force coal."""
    links, placements = _geometry_world(hand, q)
    geometries = hand.collision.geometry_model.geometryObjects
    tips = {f.tip_link for f in hand.description.fingers if f.name in contacts}
    pieces = [(s.geometry, s.transform(T_world_object)) for s in obj.collision_shapes()]
    depths = {}
    for link, geometry, M in zip(links, geometries, placements, strict=True):
        if link in tips:
            continue
        at_link = coal.Transform3s(M.rotation, M.translation)
        request = coal.DistanceRequest()
        nearest = min(
            coal.distance(piece, at, geometry.geometry, at_link, request, coal.DistanceResult())
            for piece, at in pieces
        )
        depths[link] = max(depths.get(link, 0.0), -nearest)
    return depths


@pytest.mark.parametrize("name", GRASP_NAMES)
def test_demo_grasps_leave_the_object_alone(sah: Hand, name: str) -> None:
    # What `sahgrasp demo` and examples/grasp_paper_object.py solve: the paper's Algorithm 1,
    # its starts from the sequence (experiments.arguments.ik_settings).
    example = solve_example(sah, name, IKSettings(init="sequence"))
    assert example.result.success
    depths = _coal_depths(
        sah, example.result.q, example.obj, example.obj.T_world_object, set(sah.fingers)
    )
    assert max(depths.values()) <= TOLERANCE_M, sorted(depths.items(), key=lambda kv: -kv[1])[:3]


@pytest.mark.parametrize("name", sorted(SAH_EXPERIMENTS))
def test_experiment_grasps_leave_the_object_alone(sah: Hand, name: str) -> None:
    result = run_experiment(name)  # as examples/optimize_<name>.py runs it
    system, obj = result.problem.system, SAH_EXPERIMENTS[name].object()
    contacts = {c.finger for c in system.contacts}
    assert result.valid[result.best] and result.valid[result.worst]
    for chart in np.flatnonzero(result.valid):
        T = system.object_pose(result.atlas.centres[chart]).homogeneous
        depths = _coal_depths(sah, result.configurations[chart], obj, T, contacts)
        assert max(depths.values()) <= TOLERANCE_M, (chart, max(depths, key=depths.__getitem__))


def test_without_an_object_free_fingers_clear_the_other_links(sah: Hand) -> None:
    def ring_pairs(q: np.ndarray) -> list[CollisionPair]:
        return [p for p in sah.collision.colliding_pairs(q) if "ring" in p.link_a + p.link_b]

    q = _mid_hand(sah)
    ring, middle = sah.coordinate_index("ring_j1"), sah.coordinate_index("middle_j1")
    q[7 + ring], q[7 + middle] = sah.lower[ring], sah.upper[middle]  # spread into each other
    assert ring_pairs(q)
    checker = HandObjectClearance(sah, None)
    assert checker.clearance(q).distance_m == np.inf and checker.penetrations(q) == []
    placed = checker.place_free_fingers(q, ["ring"])
    assert placed.clear and not ring_pairs(placed.q)
    assert placed.q[7 + middle] == sah.upper[middle]  # the other fingers stay


# ----- the broad phase against every (link, piece) pair ---------------------------------------
def _every_pair(hand: Hand, obj: GraspObject, q: np.ndarray) -> np.ndarray:
    """Signed distance of every (hand geometry, object piece) pair, with coal alone: (G, P)."""
    _, placements = _geometry_world(hand, q)
    geometries = hand.collision.geometry_model.geometryObjects
    request = coal.DistanceRequest()
    request.enable_signed_distance = True
    shapes = obj.collision_shapes()
    out = np.empty((len(placements), len(shapes)))
    for g, (geometry, M) in enumerate(zip(geometries, placements, strict=True)):
        at_link = coal.Transform3s(M.rotation, M.translation)
        for i, s in enumerate(shapes):
            out[g, i] = coal.distance(
                s.geometry, s.transform(obj.T_world_object), geometry.geometry, at_link,
                request, coal.DistanceResult(),
            )  # fmt: skip
    return out


@pytest.fixture(scope="module")
def near_grasps(sah: Hand) -> list[tuple[GraspObject, np.ndarray]]:
    """The coffee cup's paper grasp and nearby configurations: links touch, enter, clear it."""
    from sahgrasp.objects import paper_grasp

    cup = load_object("coffee_cup")
    q0 = solve_ik(sah, paper_grasp("coffee_cup"), obstacle=cup).q
    rng = np.random.default_rng(3)
    configurations = [q0]
    for scale in (0.05, 0.15, 0.3):
        q = q0.copy()
        q[7:] = np.clip(q[7:] + rng.normal(0.0, scale, len(q) - 7), sah.lower, sah.upper)
        configurations.append(q)
    return [(cup, q) for q in configurations]


def test_broad_phase_misses_no_pair(
    sah: Hand, near_grasps: list[tuple[GraspObject, np.ndarray]]
) -> None:
    """Penetrations and clearances equal a search over every (link, piece) pair with coal."""
    contacts = ("thumb", "index")
    tips = {f.tip_link for f in sah.description.fingers if f.name in contacts}
    for obj, q in near_grasps:
        checker = HandObjectClearance(sah, obj)
        pairs = _every_pair(sah, obj, q)
        nearest = pairs.min(axis=1)
        thresholds = np.array([-1.5e-3 if link in tips else 2e-3 for link in checker.links])
        found = sorted(
            (p.joint_b, round(p.depth_m, 9)) for p in checker.penetrations(q, 2e-3, contacts)
        )
        joints = [int(g.parentJoint) for g in sah.collision.geometry_model.geometryObjects]
        expected = sorted(
            (joints[g], round(float(thresholds[g] - d), 9))
            for g, i in zip(*np.nonzero(pairs < thresholds[:, None]), strict=True)
            for d in [pairs[g, i]]
        )
        assert found == expected
        full = checker.clearance(q, contacts)
        assert full.links_m == pytest.approx(
            dict(zip(checker.links, nearest, strict=True)), abs=1e-9
        )
        counted = [d for d, t in zip(nearest, thresholds, strict=True) if not (t < 0 <= d - t)]
        assert full.distance_m == pytest.approx(min(counted), abs=1e-9)
        closest = checker.clearance(q, contacts, all_links=False)
        assert (closest.distance_m, closest.link) == (full.distance_m, full.link)
        assert all(full.links_m[link] == d for link, d in closest.links_m.items())


def test_solver_and_clearance_share_one_definition(
    sah: Hand, near_grasps: list[tuple[GraspObject, np.ndarray]]
) -> None:
    """The IK's acceptance test, its repair's penetrations and the clearance agree everywhere.

    Contact tips within the allowance, beyond it, and links clear or inside the object.
    """
    from sahgrasp.ik.obstacle import Obstacle

    q_mid = _mid_hand(sah)
    cases = [(obj, q, ("thumb", "index")) for obj, q in near_grasps]
    cases += [(_tip_probe(sah, q_mid, d), q_mid, ("index",)) for d in (1.0e-3, 2.5e-3)]
    cases += [(_tip_probe(sah, q_mid, 1.0e-3), q_mid, ())]
    verdicts = []
    for obj, q, contacts in cases:
        checker = HandObjectClearance(sah, obj)
        closest = checker.clearance(q, contacts, all_links=False)
        inside = not closest.clear()
        assert bool(checker.penetrations(q, 0.0, contacts)) == inside
        assert checker.penetrated(q, contacts) == inside
        # The broad-phase verdict is the search's, and a clear configuration's clearance too.
        found = checker.clearance_if_clear(q, contacts)
        assert (found is None) == inside
        if found is not None:
            assert found.link == closest.link
            assert found.distance_m == pytest.approx(closest.distance_m, abs=1e-12)
        obstacle = Obstacle(sah, obj, contacts, 1.5e-3)
        assert obstacle.penetrated(q) == inside
        # The reported clearance is exact whether the verdict was inside or clear (measured in
        # the object's frame when clear: equal up to rounding for an object placed elsewhere).
        assert obstacle.clearance(q).link == closest.link
        assert obstacle.clearance(q).distance_m == pytest.approx(closest.distance_m, abs=1e-12)
        assert obstacle.penetrated(q) == inside  # kept, and unchanged by the exact query
        verdicts.append(inside)
    assert True in verdicts and False in verdicts  # both sides of the boundary were tried


def test_reported_clearance_is_the_accepted_one(sah: Hand) -> None:
    from sahgrasp.objects import paper_grasp

    cup = load_object("coffee_cup")
    result = solve_ik(sah, paper_grasp("coffee_cup"), obstacle=cup)
    assert result.success and result.object_clearance_m is not None
    clearance = HandObjectClearance(sah, cup).clearance(result.q, contacts=sah.fingers)
    assert (result.object_clearance_m, result.closest_link) == (
        pytest.approx(clearance.distance_m, abs=1e-12),
        clearance.link,
    )
    assert result.object_clearance_m >= 0.0
    assert result.time_s >= result.attempt_seconds[-1]  # the final query is in the time


def test_a_few_penetrations_per_link_name_the_same_links(
    sah: Hand, near_grasps: list[tuple[GraspObject, np.ndarray]]
) -> None:
    """The IK's repair asks for a few pairs per link: the same links as every pair."""
    contacts = ("thumb", "index")
    counts = []
    for obj, q in near_grasps:
        checker = HandObjectClearance(sah, obj)
        every = checker.penetrations(q, 2e-3, contacts)
        found = {(p.joint_b, round(p.depth_m, 9)) for p in every}
        for per_link in (1, 4):
            few = checker.penetrations(q, 2e-3, contacts, per_link=per_link)
            assert {p.joint_b for p in few} == {p.joint_b for p in every}
            assert len(few) <= per_link * len(checker.links)
            assert all((p.joint_b, round(p.depth_m, 9)) in found for p in few)
            counts.append((len(few), len(every)))
    assert any(n < m for n, m in counts)  # some link overlapped more pieces than asked for


def test_one_pair_per_link_is_one_of_every_pair_wherever_the_object_is(sah: Hand) -> None:
    """The piece tree's pair (``per_link=1``) is a pair of the full query, witnesses included.

    The tree answers in the object frame: with the object turned and moved, its points and
    normal must still be the world's.
    """
    from sahgrasp.objects import paper_grasp

    obj = load_object("can")
    q0 = solve_ik(sah, paper_grasp("can")).q  # without the object: links inside it
    turned = np.eye(4)
    turned[:3, :3] = pin.utils.rotate("z", 0.3)
    turned[:3, 3] = (2e-3, -1e-3, 0.0)
    checker = HandObjectClearance(sah, obj)
    rng = np.random.default_rng(3)
    checked = 0
    for k in range(6):
        q = pin.normalize(sah.model, q0 + rng.normal(0.0, 0.05, q0.shape) * (k > 0))
        for T in (obj.T_world_object, obj.T_world_object @ turned):
            every = checker.penetrations(q, 1e-3, ("thumb",), 1.5e-3, T)
            one = checker.penetrations(q, 1e-3, ("thumb",), 1.5e-3, T, per_link=1)
            assert {p.joint_b for p in one} == {p.joint_b for p in every}
            for p in one:
                assert any(
                    e.joint_b == p.joint_b
                    and e.depth_m == pytest.approx(p.depth_m, abs=1e-9)
                    and np.allclose(e.point_a, p.point_a, atol=1e-7)
                    and np.allclose(e.point_b, p.point_b, atol=1e-7)
                    and np.allclose(e.normal, p.normal, atol=1e-6)
                    for e in every
                )
                checked += 1
    assert checked > 0


@pytest.mark.parametrize(
    "name",
    # The coffee cup's 645 pieces make it the slow one: the full suite runs it.
    [pytest.param(n, marks=pytest.mark.slow) if n == "coffee_cup" else n for n in GRASP_NAMES],
)
def test_closest_link_matches_every_pair_about_the_paper_grasps(sah: Hand, name: str) -> None:
    """The closest link and its distance equal a search over every (link, piece) pair.

    Sixteen configurations about each paper grasp (joints and wrist perturbed: links clear of
    the object, touching it, inside it), with the paper's contact fingers and with none.
    """
    from sahgrasp.objects import paper_grasp

    obj, target = load_object(name), paper_grasp(name)
    fingers = tuple(c.finger for c in target.contacts)
    q0 = solve_ik(sah, target, obstacle=obj).q
    rng = np.random.default_rng(11)
    checker = HandObjectClearance(sah, obj)
    signs = set()
    for k in range(16):
        q = q0.copy()
        q[7:] = np.clip(q[7:] + rng.normal(0.0, 0.03 * (k % 4), len(q) - 7), sah.lower, sah.upper)
        q[:3] += rng.normal(0.0, 2e-3 * (k % 3), 3)
        nearest = _every_pair(sah, obj, q).min(axis=1)
        for contacts in (fingers, ()):
            tips = {f.tip_link for f in sah.description.fingers if f.name in contacts}
            allowed = [
                link in tips and d >= -1.5e-3
                for link, d in zip(checker.links, nearest, strict=True)
            ]
            counted = np.where(allowed, np.inf, nearest)
            closest = checker.clearance(q, contacts, all_links=False)
            assert closest.link == checker.links[int(np.argmin(counted))]
            assert closest.distance_m == pytest.approx(counted.min(), abs=1e-9)
            signs.add(closest.clear())
    assert signs == {True, False}  # configurations on both sides of the boundary
