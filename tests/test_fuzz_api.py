"""Fuzzing the public API's arguments: hostile values give a typed error or a valid answer.

Every argument of the public functions (``solve_ik``, ``solve_many``, ``IKSettings``,
``random_problems`` and the public methods of :class:`~sahgrasp.model.hand.Hand`) is replaced by
values a careless or hostile caller passes: None, integers far out of range, NaN and infinities,
wrong types. Each call must return or raise a :class:`SahGraspError` subclass: never
``AttributeError``, ``OverflowError`` from the C loop, an ``IndexError``, or a silently wrapped
index.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sahgrasp import IKSettings, solve_ik, solve_many
from sahgrasp.core.errors import (
    InvalidConfigurationError,
    InvalidSettingsError,
    InvalidTargetError,
    SahGraspError,
)
from sahgrasp.ik import random_problems
from sahgrasp.model.hand import Hand, load_hand

EXAMPLES = 60

HOSTILE = st.one_of(
    st.none(),
    st.booleans(),
    st.sampled_from([-1, 0, 10**12, -(10**12), 2**63, 2**64 + 1]),
    st.integers(),
    st.sampled_from([math.nan, math.inf, -math.inf, -0.0, 1e308, 5e-324]),
    st.floats(),
    st.text(max_size=5),
    st.lists(st.integers(-5, 5), max_size=3),
    st.just(object()),
    st.just(np.array([np.nan])),
)
"""Values a careless or hostile caller passes where any argument is expected."""


@pytest.fixture(scope="module")
def sah() -> Hand:
    return load_hand("sah")


def _typed_or_fine(call: Callable[[], object]) -> object:
    """The call's value, or None after a typed error; any other exception fails the test."""
    try:
        return call()
    except SahGraspError:
        return None


INTEGER_FIELDS = {
    "max_inits": (1, 1000),
    "learned_starts": (0, 1000),
    "max_iterations": (1, 1_000_000),
    "stall_iterations": (1, 1_000_000),
    "repair_iterations": (1, 1_000_000),
}


@pytest.mark.parametrize("name", [*INTEGER_FIELDS, "seed"])
@pytest.mark.parametrize("value", [-1, 0, 10**12, 2**31, 2**63, None, math.nan, 1.5, "3", True])
def test_integer_settings_out_of_range_are_typed_errors(name: str, value: object) -> None:
    low, high = INTEGER_FIELDS.get(name, (0, None))
    valid = isinstance(value, int) and not isinstance(value, bool) and low <= value
    valid = valid and (high is None or value <= high)  # type: ignore[operator]
    if valid:
        assert getattr(IKSettings(**{name: value}), name) == value
    else:
        with pytest.raises(InvalidSettingsError, match=name):
            IKSettings(**{name: value})


def test_max_iterations_beyond_the_c_loop_is_refused(sah: Hand) -> None:
    target = random_problems(sah, 1, 0)[0]
    for name in ("max_iterations", "stall_iterations", "repair_iterations"):
        with pytest.raises(InvalidSettingsError, match=rf"{name} must be an integer between"):
            solve_ik(sah, target, **{name: 10**12})


@settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(field=st.sampled_from([f.name for f in dataclasses.fields(IKSettings)]), value=HOSTILE)
def test_any_setting_value_gives_settings_or_a_typed_error(field: str, value: Any) -> None:
    made = _typed_or_fine(lambda: IKSettings(**{field: value}))
    assert made is None or isinstance(made, IKSettings)


def test_solve_ik_refuses_missing_and_mistyped_arguments(sah: Hand) -> None:
    target = random_problems(sah, 1, 0)[0]
    with pytest.raises(InvalidTargetError, match="target must be a GraspTarget"):
        solve_ik(sah, None)  # type: ignore[arg-type]
    with pytest.raises(InvalidSettingsError, match="hand must be a Hand"):
        solve_ik(None, target)  # type: ignore[arg-type]
    with pytest.raises(InvalidSettingsError, match="settings must be an IKSettings"):
        solve_ik(sah, target, settings={"max_inits": 2})  # type: ignore[arg-type]
    with pytest.raises(InvalidSettingsError, match=r"unknown IK setting\(s\) \['inits'\]"):
        solve_ik(sah, target, inits=3)
    with pytest.raises(InvalidTargetError, match="free_fingers must be a tuple"):
        solve_ik(sah, target, free_fingers="ring")  # type: ignore[arg-type]


@settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(
    argument=st.sampled_from(
        ["hand", "target", "settings", "sequence", "free_fingers", "database"]
    ),
    value=HOSTILE,
)
def test_solve_ik_arguments_give_a_result_or_a_typed_error(
    sah: Hand, argument: str, value: Any
) -> None:
    call: dict[str, Any] = {
        "hand": sah,
        "target": random_problems(sah, 1, 0)[0],
        "settings": IKSettings(max_inits=1, init="sequence"),
    }
    call[argument] = value
    _typed_or_fine(lambda: solve_ik(**call))


@settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(argument=st.sampled_from(["targets", "settings", "workers"]), value=HOSTILE)
def test_solve_many_arguments_give_results_or_a_typed_error(
    sah: Hand, argument: str, value: Any
) -> None:
    call: dict[str, Any] = {"targets": [], "settings": None, "workers": 1}
    call[argument] = value
    if argument == "workers" and isinstance(value, int) and value > 1:
        call["targets"] = []  # a valid worker count starts no pool for no work
        call["executor"] = None
        if value <= 8:
            return  # valid: starting worker processes is tested elsewhere
    _typed_or_fine(lambda: solve_many(sah, **call))


def test_random_configuration_refuses_what_is_no_generator(sah: Hand) -> None:
    for rng in (None, 5, np.random.RandomState(0), "seed"):
        with pytest.raises(InvalidSettingsError, match=r"rng must be a numpy\.random\.Generator"):
            sah.random_configuration(rng)  # type: ignore[arg-type]
    rng = np.random.default_rng(0)
    with pytest.raises(InvalidSettingsError, match="max_tries must be an integer >= 1"):
        sah.random_configuration(rng, max_tries=0)
    with pytest.raises(InvalidConfigurationError, match=r"T_world_palm must be a pinocchio\.SE3"):
        sah.random_configuration(rng, T_world_palm=np.eye(4))  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "fingers", [[-1], [4], [99], [10**20], [0, 0], [], [0.5], [True], ["index"], [[0]], 3, "0"]
)
def test_contact_stack_refuses_finger_indices_that_are_not_fingers(sah: Hand, fingers: Any) -> None:
    q = sah.configuration()
    with pytest.raises(InvalidTargetError, match=r"fingers must be distinct indices 0\.\.3"):
        sah.contact_stack(q, fingers)
    with pytest.raises(InvalidTargetError, match=r"fingers must be distinct indices 0\.\.3"):
        sah.contact_stack_jacobian(q, fingers)


def test_contact_stack_of_valid_indices_is_the_fingers_rows(sah: Hand) -> None:
    q = sah.random_configuration(np.random.default_rng(4))
    every = sah.contact_stack(q).reshape(-1, 6)
    chosen = sah.contact_stack(q, [np.int64(3), 1]).reshape(-1, 6)
    np.testing.assert_array_equal(chosen, every[[3, 1]])


Q_METHODS = ("contact_state", "contact_stack", "contact_jacobians", "within_limits", "state",
             "joint_values", "contact_parameters", "frame_placements", "check_q")  # fmt: skip


@settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(
    method=st.sampled_from(Q_METHODS),
    q=st.one_of(
        HOSTILE,
        st.lists(st.floats(), min_size=28, max_size=28),
        st.integers(0, 27).map(lambda i: np.where(np.arange(28) == i, np.nan, 0.1)),
    ),
)
def test_configurations_give_an_answer_or_a_typed_error(sah: Hand, method: str, q: Any) -> None:
    _typed_or_fine(lambda: getattr(sah, method)(q))


@settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(pose=st.one_of(HOSTILE, st.just(pin.SE3.Identity())), coordinates=HOSTILE)
def test_configuration_arguments_give_a_configuration_or_a_typed_error(
    sah: Hand, pose: Any, coordinates: Any
) -> None:
    q = _typed_or_fine(lambda: sah.configuration(pose, coordinates))
    assert q is None or np.all(np.isfinite(q))  # type: ignore[arg-type]


@settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(count=HOSTILE, seed=HOSTILE)
def test_random_problems_arguments(count: Any, seed: Any) -> None:
    hand = load_hand("sah")
    if isinstance(count, int) and not isinstance(count, bool) and count > 2:
        count = 2  # a valid count: only the seed is under test
    problems = _typed_or_fine(lambda: random_problems(hand, count, seed))
    assert problems is None or isinstance(problems, list)
