"""Tests of the planar three-finger hand experiment (Fig. 8-9)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from sahgrasp.errors import AtlasError
from sahgrasp.planar import (
    DEFAULT_HAND,
    PlanarResult,
    make_planar_problem,
    optimize_planar,
    run_planar,
)
from sahgrasp.quality import INDICES


@pytest.fixture(scope="module")
def result() -> PlanarResult:
    return optimize_planar()


def central_differences(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> np.ndarray:
    h = 1e-6
    return np.stack([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(x.size)], axis=-1)


def test_initial_grasp_is_feasible_and_f_has_dimension_three() -> None:
    problem = make_planar_problem()
    assert np.abs(problem.residual(problem.x1)).max() <= 1e-12
    assert np.linalg.matrix_rank(problem.grasp_jacobian(problem.x1)) == 16  # t = 19 - 16
    assert np.linalg.matrix_rank(problem.jacobian(problem.x1)) == 17  # k = 19 - 17
    lower, upper = problem.bounds()
    assert (problem.x1 >= lower).all() and (problem.x1 <= upper).all()
    assert np.isfinite(lower[:12]).any() and np.isfinite(lower[16:]).all()  # joints and arcs


def test_jacobians_match_central_differences() -> None:
    problem = make_planar_problem()
    rng = np.random.default_rng(0)
    for x in problem.x1 + 0.1 * rng.normal(size=(3, 19)):  # off the manifold too
        assert np.allclose(problem.jacobian(x), central_differences(problem.residual, x), atol=1e-8)
        joints = central_differences(problem.joint_motion, x)
        assert np.allclose(problem.joint_jacobian(x), joints, atol=1e-8)


def test_batched_evaluation_matches_single() -> None:
    problem = make_planar_problem()
    X = problem.x1 + 0.05 * np.random.default_rng(1).normal(size=(4, 19))
    assert np.allclose(problem.residual(X)[2], problem.residual(X[2]))
    assert np.allclose(problem.jacobian(X)[3], problem.jacobian(X[3]))


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


def test_atlas_covers_r_like_the_paper(result: PlanarResult) -> None:
    assert (result.t, result.k) == (3, 2)
    assert result.atlas.complete
    assert 600 <= result.charts <= 1000  # the paper: about 750 with r = 0.125, epsilon = 0.4
    residual = result.problem.residual(result.atlas.centres)
    assert np.abs(residual).max() <= 1e-8
    lower, upper = result.problem.bounds()
    assert (result.atlas.centres >= lower).all() and (result.atlas.centres <= upper).all()


def test_best_grasp_is_a_local_maximum(result: PlanarResult) -> None:
    for name in INDICES:
        values = result.quality.index(name)
        best = result.best[name].chart
        assert values[best] == result.best[name].value == values.max()
        assert (values[result.atlas.neighbours(best)] <= values[best]).all()
        assert result.worst[name].value == values.min()
    assert result.quality.singular("volume").any()  # fully stretched fingers (Fig. 9)


def test_best_value_does_not_depend_on_the_start(result: PlanarResult) -> None:
    centres = result.atlas.centres
    far = int(np.argmax(np.linalg.norm(centres - result.problem.x1, axis=1)))
    again = optimize_planar(result.problem, start=centres[far])
    assert again.atlas.complete
    for name in INDICES:
        assert again.best[name].value == pytest.approx(result.best[name].value, rel=0.02)


def test_run_planar_writes_json_and_plot(tmp_path: Path) -> None:
    summary = run_planar(json_out=str(tmp_path / "p.json"), plot_out=str(tmp_path / "p.png"))
    for key in ("charts", "t", "k", "atlas_seconds", "quality_seconds", "best", "worst"):
        assert key in summary
    assert json.loads((tmp_path / "p.json").read_text()) == summary
    assert (tmp_path / "p.png").read_bytes()[:4] == b"\x89PNG"
    best = summary["best"]["configuration"]
    assert len(best["joint_angles_rad"]) == 6 and len(best["x"]) == 19
    assert (summary["stop_reason"], summary["complete"]) == ("complete", True)
    with pytest.raises(AtlasError, match="valid"):
        run_planar(index="dexterity")


def test_a_tiny_radius_stops_at_max_charts_and_says_so() -> None:
    heard: list[int] = []
    summary = run_planar(r=1e-4, max_charts=50, progress=lambda _s, done, _t: heard.append(done))
    assert summary["charts"] == 50 and summary["max_charts"] == 50
    assert (summary["stop_reason"], summary["complete"]) == ("max_charts", False)
    assert heard[-1] == 50


@pytest.mark.parametrize(
    ("options", "match"),
    [({"r": 0.0}, "radius"), ({"eps": 0.0}, "epsilon"), ({"max_charts": 0}, "max_charts")],
)
def test_run_planar_refuses_bad_settings(options: dict[str, float], match: str) -> None:
    with pytest.raises(AtlasError, match=match):
        run_planar(**options)  # type: ignore[arg-type]
