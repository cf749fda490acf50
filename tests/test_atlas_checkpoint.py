"""Checkpoints of an atlas build: interrupted, resumed, equal to an uninterrupted build."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import numpy as np
import pytest

from sahgrasp.atlas import Atlas, AtlasCheckpoint, AtlasSettings, build_atlas
from sahgrasp.atlas.polytope import Polytope
from sahgrasp.core.errors import AtlasError


def sphere_f(x: np.ndarray) -> np.ndarray:
    return (x * x).sum(axis=-1, keepdims=True) - 1.0


def sphere_j(x: np.ndarray) -> np.ndarray:
    return 2.0 * x[..., None, :]


def _arrays(atlas: Atlas) -> list[bytes]:
    arrays = (atlas.centres, atlas.tangents, atlas.edges, atlas.parents, atlas.boundary)
    flags = (atlas.open, atlas.singular_points)
    counters = (atlas.newton_failures, atlas.rejections, atlas.bound_rejections)
    return [np.ascontiguousarray(a).tobytes() for a in arrays + flags] + [str(counters).encode()]


def _build(settings: AtlasSettings, checkpoint: AtlasCheckpoint | None = None,
           stop_at: int | None = None) -> Atlas:  # fmt: skip
    """S^3 (bounded by x_4 >= -0.5, so that boundary charts and cuts by bounds occur)."""

    def progress(_stage: str, done: int, _total: int | None) -> None:
        if stop_at is not None and done == stop_at:
            os.kill(os.getpid(), signal.SIGINT)  # as Ctrl-C: the build saves, then raises

    x0 = np.array([1.0, 0.0, 0.0, 0.0])
    lower = np.array([-np.inf, -np.inf, -np.inf, -0.5])
    return build_atlas(sphere_f, sphere_j, x0, 3, settings, lower=lower, progress=progress,
                       stacked=True, checkpoint=checkpoint)  # fmt: skip


@pytest.mark.parametrize("batch", [1, 32])
def test_an_interrupted_and_resumed_build_equals_an_uninterrupted_one(
    tmp_path: Path, batch: int
) -> None:
    settings = AtlasSettings(radius=0.35, epsilon=0.2, batch=batch)
    whole = _build(settings)
    path = tmp_path / "s3.npz"
    checkpoint = AtlasCheckpoint(path, key="S3", every_seconds=1e9)
    with pytest.raises(KeyboardInterrupt):
        _build(settings, checkpoint, stop_at=whole.n_charts // 3)
    assert path.exists()
    resumed = _build(settings, AtlasCheckpoint(path, key="S3", resume=True, every_seconds=1e9))
    assert whole.complete and resumed.complete
    assert _arrays(resumed) == _arrays(whole)
    # Resumed twice more (from a state saved at every wave, then from the final state).
    again = _build(settings, AtlasCheckpoint(path, key="S3", resume=True, every_seconds=1e-9))
    assert _arrays(again) == _arrays(whole)


def test_a_checkpoint_of_another_problem_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "s3.npz"
    settings = AtlasSettings(radius=0.5, epsilon=0.2)
    _build(settings, AtlasCheckpoint(path, key="S3"))
    with pytest.raises(AtlasError, match=r"another problem.*key"):
        _build(settings, AtlasCheckpoint(path, key="other", resume=True))
    with pytest.raises(AtlasError, match=r"another problem.*settings"):
        _build(AtlasSettings(radius=0.4, epsilon=0.2), AtlasCheckpoint(path, key="S3", resume=True))
    path.write_bytes(b"not an archive")
    with pytest.raises(AtlasError, match="not an atlas checkpoint"):
        _build(settings, AtlasCheckpoint(path, key="S3", resume=True))


def test_resume_without_a_file_starts_afresh(tmp_path: Path) -> None:
    settings = AtlasSettings(radius=0.5, epsilon=0.2)
    atlas = _build(settings, AtlasCheckpoint(tmp_path / "new.npz", resume=True))
    assert _arrays(atlas) == _arrays(_build(settings))


def test_polytopes_survive_their_bytes() -> None:
    p = Polytope.cube(3, 1.0)
    p.cut([1.0, 1.0, 1.0], 0.5, 1e-9)
    p.block(0)
    q = Polytope.from_bytes(p.to_bytes())
    assert (q.verts, q.masks, q.blocked, q.reach2) == (p.verts, p.masks, p.blocked, p.reach2)
    with pytest.raises(ValueError, match="not the bytes of a polytope"):
        Polytope.from_bytes(p.to_bytes()[:-1])


def test_bad_checkpoint_settings_are_refused() -> None:
    with pytest.raises(AtlasError, match="every_seconds"):
        AtlasCheckpoint("x.npz", every_seconds=0.0)
    with pytest.raises(AtlasError, match="empty"):
        AtlasCheckpoint("")


def test_a_second_build_on_the_same_checkpoint_is_refused(tmp_path: Path) -> None:
    from sahgrasp.atlas.checkpoint import checkpoint_lock

    path = tmp_path / "s3.npz"
    with checkpoint_lock(path), pytest.raises(AtlasError, match="another build is writing"):
        _build(AtlasSettings(radius=0.5, epsilon=0.2), AtlasCheckpoint(path))


@pytest.mark.slow
def test_a_resumed_sah_bottle_atlas_with_k_3_equals_an_uninterrupted_one(tmp_path: Path) -> None:
    from sahgrasp.experiments.setups import make_experiment

    problem = make_experiment("bottle", k=3, motions="random", length_scale_m=0.1, unit_m=0.004)
    settings = AtlasSettings(radius=1.0, epsilon=0.5, start_tol=1e-4)
    lower, upper = problem.bounds()

    def build(checkpoint: AtlasCheckpoint | None = None, stop_at: int | None = None) -> Atlas:
        def progress(_stage: str, done: int, _total: int | None) -> None:
            if stop_at is not None and done == stop_at:
                os.kill(os.getpid(), signal.SIGINT)

        return build_atlas(problem.F, problem.J, problem.start, 3, settings, lower, upper,
                           progress=progress, checkpoint=checkpoint)  # fmt: skip

    whole = build()
    assert whole.complete and whole.n_charts > 300
    path = tmp_path / "bottle.npz"
    with pytest.raises(KeyboardInterrupt):
        build(AtlasCheckpoint(path, key="bottle k3"), stop_at=whole.n_charts // 2)
    resumed = build(AtlasCheckpoint(path, key="bottle k3", resume=True))
    assert _arrays(resumed) == _arrays(whole)
