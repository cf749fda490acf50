"""Tests of the planar three-finger hand experiment (Fig. 8-9)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sahgrasp.atlas._planar import features, jacobian
from sahgrasp.core.errors import AtlasError, GraspSystemError, OptimizationError
from sahgrasp.experiments.plotting import plot_planar
from sahgrasp.experiments.report import summary
from sahgrasp.experiments.setups import run_experiment
from sahgrasp.optimization.optimizer import OptimizationResult, OptimizationSettings, optimize
from sahgrasp.optimization.planar import DEFAULT_HAND, PlanarGraspProblem, make_planar_problem
from sahgrasp.quality.ellipsoids import INDICES

PAPER = OptimizationSettings(radius=0.125, epsilon=0.4)


@pytest.fixture(scope="module")
def result() -> OptimizationResult:
    return optimize(make_planar_problem(), PAPER)


def planar(result: OptimizationResult) -> PlanarGraspProblem:
    assert isinstance(result.problem, PlanarGraspProblem)
    return result.problem


def central_differences(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> np.ndarray:
    h = 1e-6
    return np.stack([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(x.size)], axis=-1)


def test_initial_grasp_is_feasible_and_f_has_dimension_three() -> None:
    problem = make_planar_problem()
    assert np.abs(problem.F(problem.x1)).max() <= 1e-12
    assert np.linalg.matrix_rank(problem.grasp_jacobian(problem.x1)) == 16  # t = 19 - 16
    assert np.linalg.matrix_rank(problem.J(problem.x1)) == 17  # k = 19 - 17
    lower, upper = problem.bounds()
    assert (problem.x1 >= lower).all() and (problem.x1 <= upper).all()
    assert np.isfinite(lower[:12]).any() and np.isfinite(lower[16:]).all()  # joints and arcs


def test_jacobians_match_central_differences() -> None:
    problem = make_planar_problem()
    rng = np.random.default_rng(0)
    for x in problem.x1 + 0.1 * rng.normal(size=(3, 19)):  # off the manifold too
        assert np.allclose(problem.J(x), central_differences(problem.F, x), atol=1e-8)
        joints = central_differences(problem.joint_motion, x)
        assert np.allclose(problem.joint_jacobian(x), joints, atol=1e-8)


def reference_jacobian(problem: PlanarGraspProblem, x: np.ndarray) -> np.ndarray:
    """J of the planar hand entry by entry in numpy (what ``_planar.jacobian`` compiles)."""
    hand, jac = problem.hand, np.zeros((len(x), 16 + problem.synergy.shape[1], 19))
    fingers = np.arange(3)
    for i in range(3):  # Eqs. (21), (23): the contact points, linear in x
        contact = slice(7 + 2 * i, 9 + 2 * i)
        jac[:, contact, 4 * i : 4 * i + 2] = hand.phalanges[i, 0] * np.eye(2)
        jac[:, contact, 4 * i + 2 : 4 * i + 4] = hand.phalanges[i, 1] * np.eye(2)
        jac[:, contact, 12:14] = -np.eye(2)
        jac[:, contact, 14] = hand.centres[i, ::-1] * [1.0, -1.0]
        jac[:, contact, 15] = -hand.centres[i]
    for row, cols in enumerate(np.array([*np.arange(12), 14, 15]).reshape(7, 2)):  # (19), (20)
        jac[:, row, cols] = 2.0 * x[:, cols]
    cu, su = np.cos(x[:, 16:]), np.sin(x[:, 16:])
    jac[:, 7 + 2 * fingers, 16 + fingers] = hand.radii * su  # Eq. (23): -l_{i,3} w(u_i)
    jac[:, 8 + 2 * fingers, 16 + fingers] = -hand.radii * cu
    jac[:, 13 + fingers, 4 * fingers + 2] = -su  # Eq. (8): cos u v_2y - sin u v_2x
    jac[:, 13 + fingers, 4 * fingers + 3] = cu
    jac[:, 13 + fingers, 16 + fingers] = -su * x[:, 3:12:4] - cu * x[:, 2:12:4]
    vx, vy = x[:, 0:12:2], x[:, 1:12:2]  # Eq. (13): E_s^T d(theta)/dv
    grad = np.stack((-vy, vx), axis=-1).reshape(len(x), 12) / np.repeat(vx * vx + vy * vy, 2, 1)
    rates = np.repeat(problem.synergy.T @ np.kron(np.eye(3), [[1.0, 0.0], [-1.0, 1.0]]), 2, 1)
    jac[:, 16:, :12] = rates * grad[:, None, :]
    return jac


@pytest.mark.parametrize("k", [1, 2, 3])
def test_compiled_jacobian_equals_the_reference(k: int) -> None:
    problem = make_planar_problem(k=k)
    X = problem.x1 + 0.2 * np.random.default_rng(k).normal(size=(40, 19))
    assert np.allclose(problem.J(X), reference_jacobian(problem, X), rtol=1e-15, atol=1e-17)
    assert np.array_equal(problem.grasp_jacobian(X), problem.J(X)[:, :16])
    assert np.array_equal(problem.J(X.reshape(4, 10, 19)).reshape(40, -1, 19), problem.J(X))


def test_compiled_features_equal_the_reference() -> None:
    problem = make_planar_problem()
    X = problem.x1 + 0.2 * np.random.default_rng(5).normal(size=(40, 19))
    out, cosines = np.empty((40, 56)), np.empty((40, 6))
    features(X, problem.x1, out, cosines)
    cu, su = np.cos(X[:, 16:]), np.sin(X[:, 16:])
    grasp = np.concatenate((X, X * X, cu, su, cu * X[:, 3:12:4], su * X[:, 2:12:4]), axis=1)
    assert np.allclose(out[:, :50], grasp, rtol=1e-15, atol=0.0)
    turns = np.arctan2(out[:, 50:], cosines)  # each phalanx's angle from that at x_1
    angles = np.arctan2(X[:, 1:12:2], X[:, 0:12:2])
    start = np.arctan2(problem.x1[1:12:2], problem.x1[0:12:2])
    assert np.allclose(np.exp(1j * turns), np.exp(1j * (angles - start)), atol=1e-12)
    with pytest.raises(ValueError, match=r"out: expected shape \(40, 56\), got \(40, 50\)"):
        features(X, problem.x1, np.empty((40, 50)), cosines)


def test_compiled_jacobian_refuses_bad_arrays() -> None:
    problem = make_planar_problem()
    constant, where, rates = problem._jacobian_map
    x, out = problem.x1[None], np.empty((1, 17, 19))
    with pytest.raises(TypeError, match="int64"):
        jacobian(x, constant, where.astype(np.int32), DEFAULT_HAND.radii, rates, out)
    with pytest.raises(ValueError, match=r"out: expected shape \(1, 17, 19\)"):
        jacobian(x, constant, where, DEFAULT_HAND.radii, rates, np.empty((1, 16, 19)))
    with pytest.raises(ValueError, match="outside"):
        jacobian(x, constant, where + 1000, DEFAULT_HAND.radii, rates, out)


def test_batched_evaluation_matches_single() -> None:
    problem = make_planar_problem()
    X = problem.x1 + 0.05 * np.random.default_rng(1).normal(size=(4, 19))
    assert np.allclose(problem.F(X)[2], problem.F(X[2]))
    assert np.allclose(problem.J(X)[3], problem.J(X[3]))


def test_object_jacobian_gives_the_object_twist() -> None:
    problem = make_planar_problem()
    x = problem.x1.copy()
    angle = 0.3
    x[14:16] = np.sin(angle), np.cos(angle)
    dx = np.zeros(19)
    dx[12:14] = 0.1, -0.2
    dx[14:16] = np.cos(angle), -np.sin(angle)  # d(sin, cos)/d angle
    assert np.allclose(problem.object_jacobian(x) @ dx, [0.1, -0.2, 1.0])


def test_joint_angles_of_the_initial_posture() -> None:
    problem = make_planar_problem()
    posture = DEFAULT_HAND.posture
    expected = np.column_stack((posture[:, 0], posture[:, 1] - posture[:, 0])).reshape(6)
    assert np.allclose(problem.joint_angles(problem.x1), expected)


def test_atlas_covers_r_like_the_paper(result: OptimizationResult) -> None:
    problem = planar(result)
    assert (problem.t, problem.dimension, result.atlas.dim) == (3, 2, 2)
    assert result.atlas.complete
    assert 600 <= result.atlas.n_charts <= 1000  # the paper: about 750, r = 0.125, eps = 0.4
    residual = problem.F(result.atlas.centres)
    assert np.abs(residual).max() <= 1e-8
    lower, upper = problem.bounds()
    assert (result.atlas.centres >= lower).all() and (result.atlas.centres <= upper).all()
    assert result.valid.all() and np.array_equal(result.configurations, result.atlas.centres)


def test_best_grasp_is_a_local_maximum(result: OptimizationResult) -> None:
    assert result.quality is not None and result.index == "volume"
    for name in INDICES:
        ranked = result.ranked_by(name)
        values = result.quality.index(name)
        assert np.array_equal(ranked.values, values)
        assert values[ranked.best] == values.max() and values[ranked.worst] == values.min()
        assert (values[result.atlas.neighbours(ranked.best)] <= values[ranked.best]).all()
    volume = result.ranked_by("volume")
    assert (result.best, result.worst) == (volume.best, volume.worst)
    assert result.best_overall == result.best  # nothing collides
    assert result.quality.singular("volume").any()  # fully stretched fingers (Fig. 9)


def test_best_value_does_not_depend_on_the_start(result: OptimizationResult) -> None:
    problem = planar(result)
    centres = result.atlas.centres
    far = int(np.argmax(np.linalg.norm(centres - problem.x1, axis=1)))
    again = optimize(problem, PAPER, start=centres[far])
    assert again.atlas.complete and np.array_equal(again.atlas.centres[0], centres[far])
    for name in INDICES:
        ours, theirs = result.ranked_by(name), again.ranked_by(name)
        assert theirs.values[theirs.best] == pytest.approx(ours.values[ours.best], rel=0.02)


def test_summary_and_plot(result: OptimizationResult, tmp_path: Path) -> None:
    out = json.loads(json.dumps(summary("planar", result)))
    assert (out["charts"], out["t"], out["k"], out["s"]) == (result.atlas.n_charts, 3, 2, 1)
    best = out["best"]["configuration"]
    assert len(best["joint_angles_rad"]) == 6 and len(out["best"]["x"]) == 19
    assert (out["stop_reason"], out["complete"], out["colliding_charts"]) == ("complete", True, 0)
    assert set(out["indices"]) == set(INDICES)
    plot_planar(result, tmp_path / "p.png")
    assert (tmp_path / "p.png").read_bytes()[:4] == b"\x89PNG"


def test_a_tiny_radius_stops_at_max_charts_and_says_so() -> None:
    heard: list[int] = []
    result = run_experiment(
        "planar", radius=1e-4, max_charts=50, progress=lambda _s, done, _t: heard.append(done)
    )
    out = summary("planar", result)
    assert out["charts"] == 50 and out["max_charts"] == 50
    assert (out["stop_reason"], out["complete"]) == ("max_charts", False)
    assert heard[-1] == 50


@pytest.mark.parametrize(
    ("options", "error", "match"),
    [
        ({"radius": 0.0}, AtlasError, "radius"),
        ({"epsilon": 0.0}, AtlasError, "epsilon"),
        ({"max_charts": 0}, AtlasError, "max_charts"),
        ({"index": "dexterity"}, OptimizationError, "unknown index 'dexterity'; valid"),
        ({"k": 4}, GraspSystemError, "k must be 1, 2 or 3"),
    ],
)
def test_bad_settings_are_refused(options: dict[str, Any], error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        run_experiment("planar", **options)


class _Watched:
    """The planar problem, recording the shapes ``F`` is called with; ``stacked`` as given."""

    def __init__(self, stacked: bool | None) -> None:
        self.problem = make_planar_problem()
        self.shapes: set[int] = set()
        if stacked is not None:
            self.stacked = stacked

    def __getattr__(self, name: str) -> Any:
        if name == "stacked":  # only what __init__ set
            raise AttributeError(name)
        return getattr(self.problem, name)

    def F(self, x: np.ndarray) -> np.ndarray:
        self.shapes.add(np.ndim(x))
        return self.problem.F(x)


@pytest.mark.parametrize(("stacked", "dims"), [(None, {1}), (False, {1}), (True, {1, 2})])
def test_optimize_gives_stacks_to_a_problem_that_takes_them(
    result: OptimizationResult, stacked: bool | None, dims: set[int]
) -> None:
    watched = _Watched(stacked)
    atlas = optimize(watched, PAPER).atlas  # type: ignore[arg-type]
    assert watched.shapes == dims
    assert atlas.n_charts == result.atlas.n_charts
    assert np.allclose(atlas.centres, result.atlas.centres, atol=1e-9)
