"""The learned IK start: rigid-invariant keys, Kabsch, the database file and `sahgrasp learn`."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from sahgrasp.hand import Hand
from sahgrasp.ik import learned, random_problems, solve_ik
from sahgrasp.ik.learned import (
    LEARN_SEED,
    GraspDatabase,
    GraspDatabaseError,
    build_database,
    default_database,
    kabsch,
    rigid_features,
)

ROOT = Path(__file__).resolve().parents[1]


def _random_motion(rng: np.random.Generator) -> pin.SE3:
    quat = rng.normal(size=4)
    return pin.XYZQUATToSE3(np.concatenate([rng.uniform(-1, 1, 3), quat / np.linalg.norm(quat)]))


def test_features_do_not_change_under_a_rigid_motion(sah: Hand) -> None:
    rng = np.random.default_rng(11)
    state = sah.contact_state(sah.random_configuration(rng))
    T = _random_motion(rng)
    moved_points = state.points @ T.rotation.T + T.translation
    moved_normals = state.normals @ T.rotation.T
    before = rigid_features(state.points, state.normals)
    np.testing.assert_allclose(rigid_features(moved_points, moved_normals), before, atol=1e-12)
    # ... but they do change when the contacts do.
    other = sah.contact_state(sah.random_configuration(rng))
    assert np.abs(rigid_features(other.points, other.normals) - before).max() > 1e-3


def test_kabsch_recovers_a_rigid_motion() -> None:
    rng = np.random.default_rng(12)
    source = rng.normal(size=(8, 3))
    T = _random_motion(rng)
    found = kabsch(source, source @ T.rotation.T + T.translation)
    np.testing.assert_allclose(found.homogeneous, T.homogeneous, atol=1e-12)


def test_learned_starts_solve_at_the_first_start(sah: Hand) -> None:
    db = default_database(sah)
    assert db is not None and db.seed == LEARN_SEED
    results = [solve_ik(sah, p, init="learned") for p in random_problems(sah, 10, seed=3)]
    assert all(r.success for r in results)
    assert sum(r.inits_used == 1 for r in results) >= 9


def test_learned_start_places_the_neighbours_wrist_onto_the_target(sah: Hand) -> None:
    db = default_database(sah)
    assert db is not None
    problem = random_problems(sah, 1, seed=4)[0]
    (start,) = list(db.starts(sah, problem, 1))
    state = sah.contact_state(start)
    target = np.array([problem.contact(f).point for f in sah.fingers])
    # The neighbour's contacts, rigidly aligned: within a few centimetres of the target's.
    assert np.linalg.norm(state.points - target, axis=1).max() < 0.05


def test_no_learned_start_for_a_target_with_free_fingers(sah: Hand) -> None:
    db = default_database(sah)
    assert db is not None
    problem = random_problems(sah, 1, seed=4)[0]
    three = type(problem)(problem.name, [c for c in problem.contacts if c.finger != "ring"])
    assert list(db.starts(sah, three, 2)) == []
    assert solve_ik(sah, three, init="learned", free_fingers=("ring",)).success


def test_database_of_another_hand_is_refused(sah: Hand, allegro: Hand) -> None:
    db = default_database(allegro)
    assert db is not None
    with pytest.raises(GraspDatabaseError, match="made for hand 'allegro'"):
        solve_ik(sah, random_problems(sah, 1, seed=4)[0], init="learned", database=db)


@pytest.mark.parametrize(
    ("content", "message"),
    [(b"", "not a valid"), (b"PK\x03\x04garbage", "not a valid"), (None, "not found")],
)
def test_missing_or_corrupt_database_is_a_typed_error(
    tmp_path: Path, content: bytes | None, message: str
) -> None:
    path = tmp_path / "db.npz"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(GraspDatabaseError, match=message):
        GraspDatabase.load(path)


def test_database_with_non_finite_entries_is_refused(sah: Hand, tmp_path: Path) -> None:
    db = build_database(sah, 3, tmp_path / "db.npz", seed=5)
    bad = GraspDatabase(db.hand, db.hand_digest, db.configurations * np.nan, db.features, 5)
    bad.save(tmp_path / "bad.npz")
    with pytest.raises(GraspDatabaseError, match="finite"):
        GraspDatabase.load(tmp_path / "bad.npz")


def test_build_resumes_after_an_interruption(
    sah: Hand, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(learned, "CHUNK_SAMPLES", 4)
    fresh = build_database(sah, 10, tmp_path / "fresh.npz", seed=6)

    def stop_after_first(done: int, total: int) -> None:
        if done == 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        build_database(sah, 10, tmp_path / "db.npz", seed=6, progress=stop_after_first)
    assert not (tmp_path / "db.npz").exists()
    assert len(list((tmp_path / "db.npz.parts").iterdir())) == 1
    resumed = build_database(sah, 10, tmp_path / "db.npz", seed=6)
    np.testing.assert_array_equal(resumed.configurations, fresh.configurations)
    np.testing.assert_array_equal(resumed.features, fresh.features)
    assert not (tmp_path / "db.npz.parts").exists()
    loaded = GraspDatabase.load(tmp_path / "db.npz")
    np.testing.assert_array_equal(loaded.configurations, fresh.configurations)


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-m", "sahgrasp", *args], capture_output=True, text=True, env=env
    )


def test_learn_command_writes_a_database(sah: Hand, tmp_path: Path) -> None:
    out = tmp_path / "sah.npz"
    done = _cli("learn", "--hand", "sah", "--samples", "6", "--seed", "8", "--workers", "1",
                "--out", str(out))  # fmt: skip
    assert done.returncode == 0, done.stderr
    db = GraspDatabase.load(out)
    assert db.configurations.shape == (6, sah.nq) and db.seed == 8
    db.check_hand(sah)


def test_learn_command_refuses_bad_samples(tmp_path: Path) -> None:
    done = _cli("learn", "--samples", "0", "--out", str(tmp_path / "x.npz"))
    assert done.returncode == 2
    assert "argument --samples: 0 is out of range: must be an integer >= 1" in done.stderr
