"""Every array argument of every compiled entry point refuses a bad array by name.

The compiled modules (``sahgrasp/atlas/_polytope.c``, ``_planar.c``, ``_quality.c``,
``sahgrasp/ik/_lm.c``) read arrays through ``sahgrasp/_arrays.h``: a list, another item type, a
non-contiguous or (where written) read-only array is a TypeError and a wrong shape a ValueError,
each naming the argument; never a crash. The constants the Python side uses are the modules'.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from sahgrasp.atlas import _planar, _polytope, _quality
from sahgrasp.atlas._polytope import Polytope
from sahgrasp.ik import _lm, compiled
from sahgrasp.ik.compiled import _export, _shapes, _tree_arguments, compiled_tree, tree_joint
from sahgrasp.model.hand import Hand, load_hand
from sahgrasp.optimization.planar import make_planar_problem


@dataclass(frozen=True)
class EntryPoint:
    """A compiled function, its good arguments and which of its arrays it checks how.

    Attributes:
        call: The function, called with the arguments as keywords.
        arguments: Fresh good arguments on each call (arrays and scalars, by name).
        written: Arrays the function writes (a read-only one is refused).
        sized: Arrays whose length follows from the others (one value more is refused).
    """

    call: Callable[..., object]
    arguments: Callable[[], dict[str, Any]]
    written: frozenset[str] = field(default_factory=frozenset)
    sized: frozenset[str] = field(default_factory=frozenset)


def _positional(function: Callable[..., object], *names: str) -> Callable[..., object]:
    """``function`` called with keywords ``names`` in their positional order."""
    return lambda **kw: function(*(kw[name] for name in names))


_HAND: dict[str, Hand] = {}


def _sah() -> Hand:
    if "sah" not in _HAND:
        _HAND["sah"] = load_hand("sah")
    return _HAND["sah"]


def _tree() -> _lm.Tree:
    return compiled_tree(_sah())


def _q() -> np.ndarray:
    return _sah().configuration().copy()


def _pieces_arguments() -> dict[str, Any]:
    """One box piece in one cell."""
    return {
        "kinds": np.array([compiled.BOX], np.int64),
        "placements": np.array([[*np.eye(3).ravel(), 0.0, 0.0, 0.3]]),
        "sizes": np.array([[0.01, 0.01, 0.01, 0.0]]),
        "balls": np.array([[0.0, 0.0, 0.3, 0.02]]),
        "vertex_start": np.array([0, 0], np.int64),
        "vertices": np.empty((0, 3)),
        "first": np.empty(0, np.int64),
        "neighbours": np.empty(0, np.int64),
        "cell_balls": np.array([[0.0, 0.0, 0.3, 0.02]]),
        "cell_start": np.array([0, 1], np.int64),
        "cell_members": np.array([0], np.int64),
    }


def _tree_with_pieces(**kw: Any) -> object:
    method = getattr(_tree(), kw.pop("method"))
    out = (kw["out"],) if "out" in kw else ()
    pieces = _lm.Pieces(**_pieces_arguments())
    return method(pieces, kw["q"], kw["T_world_object"], kw["thresholds"], *out)


def _object_query(method: str, with_out: bool) -> dict[str, Any]:
    ns = _tree().shape_count
    arguments = {"q": _q(), "T_world_object": np.eye(4), "thresholds": np.zeros(ns)}
    if with_out:
        arguments["out"] = np.empty(ns, np.int64)
    return arguments


def _set_shapes(**kw: Any) -> None:
    _export(_sah()).set_shapes(**kw)


def _shape_arguments() -> dict[str, Any]:
    shapes = _shapes(_sah().collision.geometry_model)
    assert shapes is not None
    return shapes


def _repair_arguments() -> dict[str, Any]:
    return {
        "q": _q(),
        "target": np.zeros(6),
        "fingers": np.array([0], np.int64),
        "joints": np.array([tree_joint(0), 3], np.int64),
        "points": np.zeros(6),
        "normals": np.array([0.0, 0.0, 1.0]),
        "depths": np.array([0.001]),
        "out": np.empty(_sah().nq),
    }


def _planar_jacobian_arguments() -> dict[str, Any]:
    problem = make_planar_problem()
    constant, where, rates = problem._jacobian_map
    return {
        "x": problem.x1[None].copy(),
        "constant": constant.copy(),
        "where": where.copy(),
        "radii": np.array([0.05, 0.04, 0.03]),
        "rates": rates.copy(),
        "out": np.empty((1, 16 + len(rates), 19)),
    }


def _planar_features_arguments() -> dict[str, Any]:
    problem = make_planar_problem()
    return {
        "x": problem.x1[None].copy(),
        "reference": problem.x1.copy(),
        "out": np.empty((1, 56)),
        "cosines": np.empty((1, 6)),
    }


def _orthogonal_tail_arguments() -> dict[str, Any]:
    h, tau = np.linalg.qr(np.random.default_rng(3).normal(size=(4, 5, 3)), mode="raw")
    return {"h": np.ascontiguousarray(h), "tau": tau, "out": np.empty((4, 5, 2))}


def _semi_axes_arguments() -> dict[str, Any]:
    rng = np.random.default_rng(4)
    return {
        "actuated": rng.normal(size=(4, 6, 3)),
        "obj": rng.normal(size=(4, 2, 3)),
        "out": np.empty((4, 2)),
        "rank_tol": 1e-12,
    }


def _compatible_arguments() -> dict[str, Any]:
    return {
        "polys": [Polytope.cube(2, 0.1)],
        "centres": np.ones((1, 3)),
        "parent_centres": np.ones((1, 3)),
        "phi": np.ones((1, 3, 2)),
        "parent_phi": np.ones((1, 3, 2)),
        "vertices": np.ones((1, 2)),
        "r": 0.1,
        "r2": 0.01,
        "tol": 1e-9,
        "threshold": 0.5,
    }


ENTRY_POINTS: dict[str, EntryPoint] = {
    "Tree": EntryPoint(
        lambda **kw: _lm.Tree(**kw),
        lambda: _tree_arguments(_sah()),
        sized=frozenset(
            [
                "placements",
                "axes",
                "prismatic",
                "q_index",
                "v_index",
                "scale",
                "offset",
                "lower",
                "upper",
            ]
        ),
    ),
    "Tree.set_shapes": EntryPoint(
        _set_shapes, _shape_arguments, sized=frozenset({"placements", "kinds", "sizes", "balls"})
    ),
    "Tree.solve": EntryPoint(
        lambda **kw: _tree().solve(kw["q"], kw["target"], kw["fingers"], 3, 0.0, 1e-4, 3, None),
        lambda: {"q": _q(), "target": np.zeros(6), "fingers": np.array([0], np.int64)},
        written=frozenset({"q"}),
        sized=frozenset({"q", "target"}),
    ),
    "Tree.stack": EntryPoint(
        _positional(lambda *a: _tree().stack(*a), "q", "fingers", "stack_out", "jacobian_out"),
        lambda: {
            "q": _q(),
            "fingers": np.array([0, 1], np.int64),
            "stack_out": np.empty(12),
            "jacobian_out": np.empty((12, _sah().nv)),
        },
        written=frozenset({"stack_out", "jacobian_out"}),
        sized=frozenset({"q", "stack_out", "jacobian_out"}),
    ),
    "Tree.errors": EntryPoint(
        _positional(lambda *a: _tree().errors(*a), "q", "target", "fingers", "out"),
        lambda: {
            "q": _q(),
            "target": np.zeros(12),
            "fingers": np.array([0, 1], np.int64),
            "out": np.empty(4),
        },
        written=frozenset({"out"}),
        sized=frozenset({"q", "target", "out"}),
    ),
    "Tree.integrate": EntryPoint(
        lambda **kw: _tree().integrate(kw["q"], kw["v"], kw["out"], True),
        lambda: {"q": _q(), "v": np.zeros(_sah().nv), "out": np.empty(_sah().nq)},
        written=frozenset({"out"}),
        sized=frozenset({"q", "v", "out"}),
    ),
    "Tree.align": EntryPoint(
        _positional(lambda *a: _tree().align(*a), "q", "goal", "fingers"),
        lambda: {"q": _q(), "goal": np.zeros(6), "fingers": np.array([0], np.int64)},
        written=frozenset({"q"}),
        sized=frozenset({"q", "goal"}),
    ),
    "Tree.repair": EntryPoint(
        _positional(
            lambda *a: _tree().repair(*a),
            *["q", "target", "fingers", "joints", "points", "normals", "depths", "out"],
        ),
        _repair_arguments,
        written=frozenset({"out"}),
        sized=frozenset({"q", "target", "joints", "points", "normals", "out"}),
    ),
    "Tree.pairs_within": EntryPoint(
        lambda **kw: _tree().pairs_within(kw["q"], 0.0, kw["out"]),
        lambda: {"q": _q(), "out": np.empty(_tree().pair_count, np.int64)},
        written=frozenset({"out"}),
        sized=frozenset({"q"}),
    ),
    "Tree.object_clearance": EntryPoint(
        lambda **kw: _tree_with_pieces(method="object_clearance", **kw),
        lambda: _object_query("object_clearance", False),
        sized=frozenset({"q", "T_world_object", "thresholds"}),
    ),
    "Tree.shapes_near": EntryPoint(
        lambda **kw: _tree_with_pieces(method="shapes_near", **kw),
        lambda: _object_query("shapes_near", True),
        written=frozenset({"out"}),
        sized=frozenset({"q", "T_world_object", "thresholds", "out"}),
    ),
    "Pieces": EntryPoint(
        lambda **kw: _lm.Pieces(**kw),
        _pieces_arguments,
        sized=frozenset({"placements", "sizes", "balls", "vertex_start", "cell_members"}),
    ),
    "rigid_key": EntryPoint(
        lambda **kw: _lm.rigid_key(kw["points"], kw["normals"], 1.0, kw["out"]),
        lambda: {
            "points": np.random.default_rng(5).normal(size=(3, 3)),
            "normals": np.tile([0.0, 0.0, 1.0], (3, 1)),
            "out": np.empty(18),
        },
        written=frozenset({"out"}),
        sized=frozenset({"normals", "out"}),
    ),
    "det_signs": EntryPoint(
        _positional(_polytope.det_signs, "a", "out"),
        lambda: {"a": np.random.default_rng(6).normal(size=(3, 4, 4)), "out": np.empty(3)},
        written=frozenset({"out"}),
        sized=frozenset({"out"}),
    ),
    "min_singular_values": EntryPoint(
        _positional(_polytope.min_singular_values, "a", "out"),
        lambda: {"a": np.random.default_rng(7).normal(size=(3, 5, 2)), "out": np.empty(3)},
        written=frozenset({"out"}),
        sized=frozenset({"out"}),
    ),
    "compatible": EntryPoint(
        _positional(
            _polytope.compatible,
            *[
                "polys",
                "centres",
                "parent_centres",
                "phi",
                "parent_phi",
                "vertices",
                "r",
                "r2",
                "tol",
                "threshold",
            ],
        ),
        _compatible_arguments,
        sized=frozenset({"parent_centres", "parent_phi", "vertices"}),
    ),
    "jacobian": EntryPoint(
        _positional(_planar.jacobian, "x", "constant", "where", "radii", "rates", "out"),
        _planar_jacobian_arguments,
        written=frozenset({"out"}),
        sized=frozenset({"x", "constant", "where", "radii", "out"}),
    ),
    "features": EntryPoint(
        _positional(_planar.features, "x", "reference", "out", "cosines"),
        _planar_features_arguments,
        written=frozenset({"out", "cosines"}),
        sized=frozenset({"x", "reference", "out", "cosines"}),
    ),
    "orthogonal_tail": EntryPoint(
        _positional(_quality.orthogonal_tail, "h", "tau", "out"),
        _orthogonal_tail_arguments,
        written=frozenset({"out"}),
        sized=frozenset({"tau", "out"}),
    ),
    "semi_axes": EntryPoint(
        _positional(_quality.semi_axes, "actuated", "obj", "out", "rank_tol"),
        _semi_axes_arguments,
        written=frozenset({"out"}),
        sized=frozenset({"obj", "out"}),
    ),
}


def _cases() -> list[tuple[str, str]]:
    cases = []
    for name, entry in ENTRY_POINTS.items():
        for argument, value in entry.arguments().items():
            if isinstance(value, np.ndarray):
                cases.append((name, argument))
    return cases


CASES = _cases()


def _other_type(array: np.ndarray) -> np.ndarray:
    return array.astype(np.float32 if array.dtype == np.float64 else np.float64)


def _strided(array: np.ndarray) -> np.ndarray:
    """The same values, every other item of a larger array: not C-contiguous."""
    wide = np.repeat(array, 2, axis=-1)
    return wide[..., ::2]


def _longer(array: np.ndarray) -> np.ndarray:
    """One more value along the last axis."""
    return np.concatenate([array, np.zeros((*array.shape[:-1], 1), array.dtype)], axis=-1)


def _refused(entry: EntryPoint, argument: str, bad: object, error: type[Exception]) -> str:
    arguments = entry.arguments()
    arguments[argument] = bad
    with pytest.raises(error) as caught:
        entry.call(**arguments)
    return str(caught.value)


def _names(message: str, argument: str) -> bool:
    return re.search(rf"(^|\W){re.escape(argument)}(\W|$)", message) is not None


@pytest.mark.parametrize(("entry", "argument"), CASES, ids=[f"{e}-{a}" for e, a in CASES])
def test_bad_arrays_are_refused_by_name(entry: str, argument: str) -> None:
    point = ENTRY_POINTS[entry]
    good = point.arguments()
    point.call(**good)  # the good arguments pass
    array = good[argument]
    message = _refused(point, argument, array.tolist(), TypeError)
    assert _names(message, argument) and "got list" in message, message
    message = _refused(point, argument, _other_type(array), TypeError)
    assert _names(message, argument) and "items of another type" in message, message
    if array.size > 1:
        message = _refused(point, argument, _strided(array), TypeError)
        assert _names(message, argument) and "non-contiguous" in message, message
    if argument in point.written:
        frozen = array.copy()
        frozen.setflags(write=False)
        message = _refused(point, argument, frozen, TypeError)
        assert _names(message, argument) and "read-only" in message, message
    if argument in point.sized:
        message = _refused(point, argument, _longer(array), ValueError)
        assert _names(message, argument) and "expected" in message, message


def test_every_entry_point_with_arrays_is_covered() -> None:
    covered = {name.split(".")[-1] for name in ENTRY_POINTS}
    for module in (_lm, _polytope, _planar, _quality):
        for name in dir(module):
            if callable(getattr(module, name)) and not name.startswith("_"):
                if name in ("Polytope",):  # takes sequences of floats, not arrays
                    continue
                assert name in covered, f"{module.__name__}.{name} is not checked here"
    for name in dir(_lm.Tree):
        if not name.startswith("_") and callable(getattr(_lm.Tree, name)):
            assert name in covered, f"Tree.{name} is not checked here"


@pytest.mark.parametrize("factory", ["Tree", "Pieces", "Tree.set_shapes"])
def test_the_compiled_types_take_named_arguments_only(factory: str) -> None:
    entry = ENTRY_POINTS[factory]
    arguments = entry.arguments()
    target: Callable[..., object] = {
        "Tree": _lm.Tree,
        "Pieces": _lm.Pieces,
        "Tree.set_shapes": _export(_sah()).set_shapes,
    }[factory]
    with pytest.raises(TypeError):
        target(*arguments.values())
    first = next(iter(arguments))
    with pytest.raises(TypeError, match=f"missing required keyword argument '{first}'"):
        target(**{k: v for k, v in arguments.items() if k != first})


def test_python_reads_the_compiled_constants() -> None:
    assert compiled.OUTCOMES == {
        _lm.CONVERGED: "converged",
        _lm.NO_PROGRESS: "no_progress",
        _lm.MAX_ITERATIONS: "max_iterations",
    }
    kinds = (compiled.POINT, compiled.BOX, compiled.CYLINDER, compiled.ELLIPSOID, compiled.CONVEX)
    assert kinds == (
        _lm.SHAPE_POINT, _lm.SHAPE_BOX, _lm.SHAPE_CYLINDER, _lm.SHAPE_ELLIPSOID, _lm.SHAPE_CONVEX
    )  # fmt: skip
    assert len(set(kinds)) == 5
    assert tree_joint(0) == _lm.FIXED_JOINT  # Pinocchio's universe is the tree's fixed world


def test_the_tree_numbers_joints_by_the_one_mapping() -> None:
    hand = _sah()
    arguments = _tree_arguments(hand)
    model = hand.model
    assert arguments["parents"][0] == _lm.FIXED_JOINT
    for j in range(1, model.njoints):
        assert arguments["parents"][tree_joint(j)] == tree_joint(model.parents[j])
        assert arguments["q_index"][tree_joint(j)] == model.joints[j].idx_q
    shapes = _shape_arguments()
    for k, g in enumerate(hand.collision.geometry_model.geometryObjects):
        assert shapes["joints"][k] == tree_joint(g.parentJoint)
        kinds = {compiled.POINT: ("Sphere",), compiled.CYLINDER: ("Capsule", "Cylinder")}
        assert type(g.geometry).__name__ in kinds.get(int(shapes["kinds"][k]), ("Box", "Ellipsoid"))


@pytest.mark.parametrize(
    ("call", "error", "message"),
    [
        (lambda p: p.cut(None, 0.1, 1e-9), TypeError, r"^a must be a sequence of 2 floats"),
        (lambda p: p.cut([1.0], 0.1, 1e-9), ValueError, r"^a must have 2 entries, got 1"),
        (lambda p: p.cut(["x", 1.0], 0.1, 1e-9), TypeError, r"^a\[0\] must be a real number"),
        (lambda p: p.index(None), TypeError, r"^vertex must be a sequence of 2 floats"),
        (lambda p: p.index([1.0, 2.0, 3.0]), ValueError, r"^vertex must have 2 entries"),
        (
            lambda p: Polytope.from_planes(2, 0.1, [[1.0, 0.0, 0.0]], [0.1], 1e-9),
            ValueError,
            r"^planes\[0\] must have 2 entries",
        ),
        (
            lambda p: Polytope.from_planes(2, 0.1, [[1.0, 0.0]], ["x"], 1e-9),
            TypeError,
            r"^offsets\[0\] must be a real number, got str",
        ),
    ],
)
def test_polytope_vectors_are_refused_by_name(
    call: Callable[[Polytope], object], error: type[Exception], message: str
) -> None:
    with pytest.raises(error, match=message):
        call(Polytope.cube(2, 0.1))


@pytest.mark.parametrize(
    ("max_iterations", "stall", "error", "message"),
    [
        (10**12, 3, ValueError, r"^max_iterations must be an integer in \[0, "),
        (-1, 3, ValueError, r"^max_iterations must be an integer in \[0, "),
        (5.0, 3, TypeError, r"^max_iterations must be an integer, got float"),
        (5, 0, ValueError, r"^stall must be an integer in \[1, "),
        (5, None, TypeError, r"^stall must be an integer, got NoneType"),
    ],
)
def test_the_loops_counts_are_refused_by_name(
    max_iterations: object, stall: object, error: type[Exception], message: str
) -> None:
    q, target, fingers = _q(), np.zeros(6), np.array([0], np.int64)
    with pytest.raises(error, match=message):
        _tree().solve(q, target, fingers, max_iterations, 0.0, 1e-4, stall, None)
    _tree().solve(q, target, fingers, np.int64(2), 0.0, 1e-4, np.int64(3), None)  # numpy ints


def test_the_polytope_dimension_is_refused_by_name() -> None:
    with pytest.raises(ValueError, match=r"^k must be an integer in \[1, "):
        Polytope.cube(10**12, 0.1)
    with pytest.raises(TypeError, match=r"^k must be an integer, got float"):
        Polytope.from_planes(2.0, 0.1, [[1.0, 0.0]], [0.1], 1e-9)


@pytest.mark.parametrize(
    ("argument", "at", "value", "message"),
    [
        ("parents", 0, 0, r"^Tree: parents\[0\] = 0: expected FIXED_JOINT"),
        ("parents", 2, 5, r"^Tree: parents\[2\] = 5: expected an earlier joint"),
        ("q_index", 3, 99, r"^Tree: q_index\[3\] = 99"),
        ("yaw", 1, 0, r"^Tree: yaw\[1\] = 0: expected a finger joint"),
    ],
)
def test_tree_values_are_refused_by_name(argument: str, at: int, value: int, message: str) -> None:
    arguments = _tree_arguments(_sah())
    arguments[argument] = arguments[argument].copy()
    arguments[argument][at] = value
    with pytest.raises(ValueError, match=message):
        _lm.Tree(**arguments)
