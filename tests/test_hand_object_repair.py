"""The IK's repair query and acceptance test: the links left out and the links placed at once.

``HandObjectClearance.penetrations(per_link=1)`` asks the piece tree only about the links whose
bounding balls come near the object's box, and places the link objects with Pinocchio's broad
phase of the hand when the object frame is the world's. Both must leave every answer as it was:
one piece-tree query per link, each link placed in the object frame by hand.
"""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest

from sahgrasp.collision.hand_object import HandObjectClearance
from sahgrasp.collision.shapes import PieceTree
from sahgrasp.ik import solve_ik
from sahgrasp.model.hand import Hand
from sahgrasp.objects import GraspObject, load_object, paper_grasp

ALLOWANCE_M = 1.5e-3
CONTACTS = ("thumb", "index")


def _configurations(hand: Hand, name: str, count: int) -> list[np.ndarray]:
    """The paper grasp of ``name`` solved without the object, then perturbed: links inside it,
    touching it and clear of it; the wrist moved too, so that whole fingers leave it."""
    q0 = solve_ik(hand, paper_grasp(name)).q
    rng = np.random.default_rng(5)
    out = [q0]
    for k in range(1, count):
        q = q0.copy()
        q[7:] = np.clip(q[7:] + rng.normal(0.0, 0.1 * (k % 3), len(q) - 7), hand.lower, hand.upper)
        q[:3] += rng.normal(0.0, 0.01 * (k % 4), 3)
        out.append(q)
    return out


def _turned(obj: GraspObject) -> np.ndarray:
    turned = np.eye(4)
    turned[:3, :3] = pin.utils.rotate("z", 0.4) @ pin.utils.rotate("x", 0.2)
    turned[:3, 3] = (3e-3, -2e-3, 1e-3)
    return obj.T_world_object @ turned


def _tree_pairs(
    hand: Hand, obj: GraspObject, q: np.ndarray, margin_m: float, T: np.ndarray
) -> list[tuple[int, float, tuple[float, ...]]]:
    """One piece-tree query per hand geometry, each placed in the object frame with coal alone.

    (joint, depth [m], world normal) of each pair found, in geometry order.
    """
    geometry_model = hand.collision.geometry_model
    geometry_data = pin.GeometryData(geometry_model)
    pin.updateGeometryPlacements(
        hand.model, hand.model.createData(), geometry_model, geometry_data, q
    )
    tree = PieceTree(obj.collision_shapes())
    tips = {f.tip_link for f in hand.description.fingers if f.name in CONTACTS}
    object_world = pin.SE3(T).inverse()
    found = []
    for g, geometry in enumerate(geometry_model.geometryObjects):
        M = object_world * geometry_data.oMg[g]
        link = coal.CollisionObject(geometry.geometry, coal.Transform3s(M.rotation, M.translation))
        link.computeAABB()
        tip = hand.model.frames[geometry.parentFrame].name in tips
        threshold_m = -ALLOWANCE_M if tip else margin_m
        pair = tree.first_pair(link, threshold_m)
        if pair is not None:
            normal = T[:3, :3] @ pair[3]
            depth_m = threshold_m - pair[0]
            found.append((int(geometry.parentJoint), depth_m, tuple(normal)))
    return found


@pytest.mark.parametrize("name", [pytest.param("coffee_cup", marks=pytest.mark.slow), "can"])
def test_repair_query_asks_the_tree_about_every_link_that_can_have_a_pair(
    sah: Hand, name: str
) -> None:
    """The repair's pairs are those of one piece-tree query per link, wherever the object is."""
    obj = load_object(name)
    checker = HandObjectClearance(sah, obj)
    counts = []
    for q in _configurations(sah, name, 12):
        for T in (obj.T_world_object, _turned(obj)):
            for margin_m in (0.0, 2e-3):
                found = checker.penetrations(q, margin_m, CONTACTS, ALLOWANCE_M, T, per_link=1)
                expected = _tree_pairs(sah, obj, q, margin_m, T)
                assert [p.joint_b for p in found] == [e[0] for e in expected]
                for p, (_, depth_m, normal) in zip(found, expected, strict=True):
                    assert abs(p.depth_m - depth_m) <= 1e-12
                    np.testing.assert_allclose(p.normal, normal, rtol=0.0, atol=1e-12)
                counts.append(len(found))
    assert 0 in counts and max(counts) > 3  # clear hands and links deep in the object


def test_links_placed_at_once_or_one_by_one_give_the_same_answers(sah: Hand) -> None:
    """Pinocchio's broad phase places the link objects as placing them one by one does."""
    obj = load_object("coffee_cup")
    at_once = HandObjectClearance(sah, obj)
    one_by_one = HandObjectClearance(sah, obj)
    assert at_once._hand_tree is not None  # the SAH's geometries are all in collision pairs
    one_by_one._hand_tree = None
    verdicts = set()
    for q in _configurations(sah, "coffee_cup", 12):
        answers = []
        for checker in (at_once, one_by_one):
            pairs = checker.penetrations(q, 2e-3, CONTACTS, ALLOWANCE_M, per_link=1)
            accepted = checker.clearance_if_clear(q, CONTACTS, ALLOWANCE_M)
            closest = checker.clearance(q, CONTACTS, ALLOWANCE_M, all_links=False)
            answers.append(
                (
                    [(p.joint_b, p.depth_m, tuple(p.point_a), tuple(p.normal)) for p in pairs],
                    accepted,
                    closest,
                    checker.penetrated(q, CONTACTS, ALLOWANCE_M),
                )
            )
        assert answers[0] == answers[1]
        verdicts.add(answers[0][1] is None)
    assert verdicts == {True, False}  # configurations inside the object and clear of it
