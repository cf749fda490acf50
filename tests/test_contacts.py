"""Contact targets: their checks, their JSON form and their pickling."""

import numpy as np
import pytest

from sahgrasp.core.errors import InvalidTargetError
from sahgrasp.model.contacts import ContactTarget, GraspTarget

FINGERS = ("thumb", "index", "middle", "ring")


def test_centre_is_offset_along_normal() -> None:
    c = ContactTarget("thumb", [0, 0, 0], [0, 0, 1])
    np.testing.assert_allclose(c.centre(0.01), [0, 0, 0.01])


@pytest.mark.parametrize(
    ("point", "normal", "match"),
    [
        ([0, 0, float("nan")], [0, 0, 1], "NaN"),
        ([0, 0, float("inf")], [0, 0, 1], "NaN or inf"),
        ([0, 0, 0], [0, 0, 2], "unit vector"),
        ([0, 0], [0, 0, 1], "3 components"),
        ([0, 0, 0], "up", "3 numbers"),
    ],
)
def test_invalid_contact(point: list, normal: object, match: str) -> None:
    with pytest.raises(InvalidTargetError, match=match):
        ContactTarget("thumb", point, normal)  # type: ignore[arg-type]


def test_repeated_unknown_and_missing_fingers() -> None:
    c = ContactTarget("thumb", [0, 0, 0], [0, 0, 1])
    with pytest.raises(InvalidTargetError, match="more than once"):
        GraspTarget("g", [c, c])
    with pytest.raises(InvalidTargetError, match=r"unknown finger.*valid fingers"):
        GraspTarget("g", [ContactTarget("pinky", [0, 0, 0], [0, 0, 1])]).check_fingers(FINGERS)
    with pytest.raises(InvalidTargetError, match="at least two of"):
        GraspTarget("g", [c]).check_fingers(FINGERS)
    index, ring = (ContactTarget(f, [0, 0, 0], [0, 0, 1]) for f in ("index", "ring"))
    with pytest.raises(InvalidTargetError, match="missing contact for the thumb"):
        GraspTarget("g", [index, ring]).check_fingers(FINGERS)


def test_swapped_or_wrong_arguments_are_a_typed_error() -> None:
    contacts = [
        ContactTarget("thumb", [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
        ContactTarget("index", [0.05, 0.0, 0.0], [-1.0, 0.0, 0.0]),
    ]
    with pytest.raises(InvalidTargetError, match="name must be a string, got list"):
        GraspTarget(contacts, "pinch")  # type: ignore[arg-type]
    with pytest.raises(InvalidTargetError, match="iterable of ContactTarget, got int"):
        GraspTarget("pinch", 5)  # type: ignore[arg-type]
    with pytest.raises(InvalidTargetError, match="iterable of ContactTarget, got str"):
        GraspTarget("pinch", "thumb")  # type: ignore[arg-type]
    with pytest.raises(InvalidTargetError, match=r"must be a ContactTarget, got \['tuple'\]"):
        GraspTarget("pinch", [("thumb", [0, 0, 0], [1, 0, 0])])  # type: ignore[list-item]


def test_a_grasp_may_leave_fingers_free() -> None:
    """Contacts for a subset of the fingers: at least two, the thumb among them if any."""
    thumb, index = (ContactTarget(f, [0, 0, 0], [0, 0, 1]) for f in ("thumb", "index"))
    pinch = GraspTarget("pinch", [index, thumb])
    pinch.check_fingers(FINGERS)
    assert pinch.free_fingers(FINGERS) == ("middle", "ring")
    GraspTarget("no thumb", [index, ContactTarget("ring", [0, 0, 0], [0, 0, 1])]).check_fingers(
        ("index", "ring")  # a hand without a thumb
    )


@pytest.mark.parametrize(
    ("point", "match"),
    [
        (["0.1", 0, 0], "3 numbers"),
        ([True, 0, 0], "3 numbers"),
        ([None, 0, 0], "3 numbers"),
        ([[0, 0, 0]], "3 numbers"),
        ({"x": 0}, "3 numbers"),
        ([10**400, 0, 0], "too large for a float"),
        ([1e400, 0, 0], "NaN or inf"),
        ([0, 0, 0, 0], "3 components"),
    ],
)
def test_points_must_be_three_real_numbers(point: object, match: str) -> None:
    with pytest.raises(InvalidTargetError, match=match):
        ContactTarget("thumb", point, [0, 0, 1])  # type: ignore[arg-type]


def test_numpy_inputs_still_accepted() -> None:
    c = ContactTarget("thumb", np.array([[0.0], [0.0], [1.0]]), np.array([0, 0, 1], dtype=np.int64))
    np.testing.assert_array_equal(c.point, [0, 0, 1])
    with pytest.raises(InvalidTargetError, match="3 numbers"):
        ContactTarget("thumb", np.array([True, False, True]), [0, 0, 1])


def test_lone_surrogate_in_a_name_becomes_a_replacement_character() -> None:
    g = GraspTarget("bad\ud800name", [ContactTarget("thumb", [0, 0, 0], [0, 0, 1])])
    assert g.name == "bad\ufffdname"
    g.name.encode("utf-8")


def test_a_pickled_target_comes_back_equal_bit_for_bit_and_read_only() -> None:
    import pickle

    target = GraspTarget("p", [ContactTarget("thumb", [0.1, 1 / 3, -2e-300], [0.0, 0.6, 0.8])])
    back = pickle.loads(pickle.dumps(target, pickle.HIGHEST_PROTOCOL))
    assert back == target and back.contacts[0].point.tobytes() == target.contacts[0].point.tobytes()
    assert (
        not back.contacts[0].point.flags.writeable and not back.contacts[0].normal.flags.writeable
    )
