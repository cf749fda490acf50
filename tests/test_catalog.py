"""The catalog is a registry of builders: adding an object is one call, every loader knows it."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from sahgrasp.core.errors import InvalidTargetError
from sahgrasp.objects import (
    CATALOG,
    GRASP_NAMES,
    OBJECT_NAMES,
    PAPER_IK_REPORT,
    CatalogEntry,
    EllipsoidSolid,
    GraspObject,
    load_object,
    paper_grasp,
    placement,
    register_object,
)
from sahgrasp.objects.targets import build_object, object_spec

RADIUS_M = 0.04


def _ball() -> CatalogEntry:
    """A 40 mm ball resting on the floor, and a four-finger grasp around its equator."""
    ball = EllipsoidSolid("ball", (RADIUS_M,) * 3, placement(None, (0.0, 0.0, RADIUS_M)))
    grasp = {
        "thumb": ball.jet(math.pi, 0.0),
        "index": ball.jet(0.5, 0.3),
        "middle": ball.jet(0.0, 0.0),
        "ring": ball.jet(-0.5, -0.3),
    }
    return CatalogEntry(GraspObject("ball", (ball,), (0.2, 0.6, 0.9, 1.0)), grasp)


@pytest.fixture
def ball() -> Iterator[str]:
    """The test object, registered for one test: the single place that adds it."""
    register_object("ball", _ball, grasped=True)
    try:
        yield "ball"
    finally:
        CATALOG.unregister("ball")


def test_the_catalog_holds_the_papers_objects_in_order() -> None:
    assert tuple(OBJECT_NAMES) == ("fork", "cup", "buddha", "coffee_cup", "can", "bottle")
    assert tuple(GRASP_NAMES) == tuple(PAPER_IK_REPORT)  # the grasps of Claret & Suárez
    assert tuple(CATALOG) == OBJECT_NAMES


def test_an_added_object_is_loaded_placed_and_grasped(ball: str) -> None:
    assert ball in OBJECT_NAMES and ball in GRASP_NAMES  # views taken at import see it
    T = placement(None, (0.1, 0.0, 0.0))
    obj = load_object(ball, T)
    assert obj.name == "ball"
    target = paper_grasp(ball, T)
    assert target.fingers == ("thumb", "index", "middle", "ring")
    for contact in target.contacts:  # on the placed ball, normals outwards
        offset = contact.point - np.array([0.1, 0.0, RADIUS_M])
        assert np.linalg.norm(offset) == pytest.approx(RADIUS_M)
        np.testing.assert_allclose(contact.normal, offset / RADIUS_M, atol=1e-12)


def test_an_added_object_can_be_named_in_a_targets_file(ball: str, tmp_path: Path) -> None:
    spec = object_spec({"name": ball, "xyz": [0.0, 0.2, 0.0]}, tmp_path)
    assert spec is not None and spec.name == "ball"
    assert build_object(spec).name == "ball"


def test_an_object_without_a_grasp_is_loaded_but_not_grasped(tmp_path: Path) -> None:
    register_object("plain_ball", lambda: CatalogEntry(_ball().object))
    try:
        assert "plain_ball" in OBJECT_NAMES and "plain_ball" not in GRASP_NAMES
        assert load_object("plain_ball").name == "ball"
        with pytest.raises(InvalidTargetError, match="unknown object 'plain_ball'; valid names"):
            paper_grasp("plain_ball")
    finally:
        CATALOG.unregister("plain_ball")
    with pytest.raises(InvalidTargetError, match="unknown object 'plain_ball'; valid names"):
        load_object("plain_ball")
    with pytest.raises(InvalidTargetError, match="unknown object 'plain_ball'"):
        object_spec({"name": "plain_ball"}, tmp_path)


def test_bad_registrations_are_typed_errors(ball: str) -> None:
    with pytest.raises(InvalidTargetError, match="object 'ball' is already registered"):
        register_object(ball, _ball)
    with pytest.raises(InvalidTargetError, match="non-empty name"):
        register_object("", _ball)
    with pytest.raises(InvalidTargetError, match="unknown object 'nothing'; valid: fork, cup"):
        CATALOG.unregister("nothing")
    register_object("empty", lambda: CatalogEntry(_ball().object), grasped=True)
    try:
        with pytest.raises(InvalidTargetError, match="registered with a grasp, but built none"):
            paper_grasp("empty")
    finally:
        CATALOG.unregister("empty")
