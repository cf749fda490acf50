"""The IK's compiled hand-object verdicts (``Tree.object_clearance``, ``Tree.shapes_near``)
against coal's (``HandObjectClearance.clearance_if_clear`` and the repair query)."""

from __future__ import annotations

from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import pytest

from sahgrasp.ik import solve_ik
from sahgrasp.ik._lm import Pieces
from sahgrasp.ik.compiled import describe_shape
from sahgrasp.ik.obstacle import (
    REPAIR_PAIRS_PER_LINK,
    Obstacle,
    build_pieces,
    checker_of,
    pieces_of,
)
from sahgrasp.model.hand import Hand
from sahgrasp.objects import GraspObject, load_mesh, load_object
from sahgrasp.objects.grasp_sampler import registered_reach, sample_object_grasps

MUG = Path(__file__).resolve().parents[1] / "examples" / "meshes" / "mug.stl"
ALLOWANCE_M = 1.5e-3
# Convex hulls with and without hill climbing, boxes, ellipsoids and a mesh's pieces.
OBJECTS = ("can", "fork", "coffee_cup", "buddha", "mug")


@pytest.fixture(scope="module", params=OBJECTS)
def obj(request: pytest.FixtureRequest) -> GraspObject:
    if request.param == "mug":
        return load_mesh(MUG)
    placed = load_object(request.param)
    if request.param == "can":  # a placement that is not the identity: the frames must agree
        return placed.placed(
            pin.SE3(pin.rpy.rpyToMatrix(0.3, -0.2, 0.5), np.array([0.02, 0, 0.01]))
        )
    return placed


def _configurations(hand: Hand, obj: GraspObject) -> list[np.ndarray]:
    """Grasps of sampled contact sets solved without the object (often through it), perturbed,
    solved with it (clear of it) and moved off it (clear, near and far)."""
    rng = np.random.default_rng(31)
    out = []
    for target in sample_object_grasps(obj, 6, 9031, registered_reach("sah")):
        q = solve_ik(hand, target).q
        for scale in (0.0, 0.05, 0.15):
            moved = q.copy()
            moved[7:] += rng.normal(0.0, scale, len(q) - 7)
            moved[7:] = np.clip(moved[7:], hand.lower, hand.upper)
            moved[:3] += rng.normal(0.0, scale / 10, 3)
            out.append(moved)
        out.append(solve_ik(hand, target, obstacle=obj).q)
        for step_m in (0.03, 0.3):
            off = q.copy()
            off[2] += step_m
            out.append(off)
    return out


def test_the_compiled_acceptance_test_is_coals(sah: Hand, obj: GraspObject) -> None:
    checker = checker_of(sah, obj)
    assert pieces_of(checker) is not None
    verdicts = []
    for contacts in (("thumb", "index", "middle", "ring"), ("thumb", "middle")):
        obstacle = Obstacle(sah, obj, contacts, ALLOWANCE_M)
        for q in _configurations(sah, obj):
            coal_answer = checker.clearance_if_clear(q, contacts, ALLOWANCE_M)
            compiled = obstacle.penetrated(q)
            assert compiled == (coal_answer is None)
            verdicts.append(compiled)
            if coal_answer is not None:
                found = obstacle.clearance(q)
                assert found.distance_m == pytest.approx(coal_answer.distance_m, abs=1e-6)
                assert found.link == coal_answer.link
    assert any(verdicts) and not all(verdicts)  # both verdicts were tried


def test_the_compiled_repair_query_asks_coal_about_the_same_links(
    sah: Hand, obj: GraspObject
) -> None:
    checker = checker_of(sah, obj)
    contacts = ("thumb", "index", "middle", "ring")
    obstacle, found = Obstacle(sah, obj, contacts, ALLOWANCE_M), 0
    for q in _configurations(sah, obj):
        for margin_m in (0.0, 1e-3):
            alone = checker.penetrations(
                q, margin_m, contacts, ALLOWANCE_M, per_link=REPAIR_PAIRS_PER_LINK
            )
            guided = obstacle.penetrations(q, margin_m)
            assert [(p.joint_b, p.depth_m) for p in guided] == [
                (p.joint_b, p.depth_m) for p in alone
            ]
            found += len(alone)
    assert found > 0


def test_pieces_of_unknown_kinds_leave_the_checks_to_coal(
    sah: Hand, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert describe_shape(coal.Cone(0.01, 0.02)) is None
    checker = checker_of(sah, load_object("can"))
    monkeypatch.setattr("sahgrasp.ik.obstacle.describe_shape", lambda geometry: None)
    assert build_pieces(checker) is None


def test_pieces_refuse_inconsistent_arrays() -> None:
    good = {
        "kinds": np.array([1], np.int64),
        "placements": np.array([[*np.eye(3).ravel(), 0.0, 0.0, 0.0]]),
        "sizes": np.array([[0.01, 0.01, 0.01, 0.0]]),
        "balls": np.array([[0.0, 0.0, 0.0, 0.02]]),
        "vertex_start": np.array([0, 0], np.int64),
        "vertices": np.empty((0, 3)),
        "first": np.empty(0, np.int64),
        "neighbours": np.empty(0, np.int64),
        "cell_balls": np.array([[0.0, 0.0, 0.0, 0.02]]),
        "cell_start": np.array([0, 1], np.int64),
        "cell_members": np.array([0], np.int64),
    }
    Pieces(**good)
    for name, bad in (
        ("kinds", np.array([9], np.int64)),  # no such kind
        ("cell_members", np.array([3], np.int64)),  # no such piece
        ("vertex_start", np.array([0, 2], np.int64)),  # vertices that are not there
    ):
        with pytest.raises(ValueError, match="Pieces"):
            Pieces(**{**good, name: bad})
    with pytest.raises(TypeError):
        Pieces(**{**good, "kinds": np.array([1.0])})
