"""The learned IK start: keys, the alignment, the database file and `sahgrasp learn`."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from sahgrasp.ik import learned, learning, random_problems, solve_ik
from sahgrasp.ik.compiled import compiled_tree
from sahgrasp.ik.learned import (
    LEARN_SEED,
    GraspDatabase,
    GraspDatabaseError,
    contact_key,
    default_database,
    rigid_features,
    target_key,
)
from sahgrasp.ik.learning import build_database
from sahgrasp.ik.solver import ContactProblem
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import Hand

ROOT = Path(__file__).resolve().parents[1]


def _random_motion(rng: np.random.Generator) -> pin.SE3:
    quat = rng.normal(size=4)
    return pin.XYZQUATToSE3(np.concatenate([rng.uniform(-1, 1, 3), quat / np.linalg.norm(quat)]))


def test_features_are_the_contacts_in_their_own_frame(sah: Hand) -> None:
    state = sah.contact_state(sah.random_configuration(np.random.default_rng(10)))
    points, normals = state.points, state.normals
    centred = points - points.mean(axis=0)
    x = centred[0] / np.linalg.norm(centred[0])
    side = points[-1] - points[1]
    y = side - (side @ x) * x
    y /= np.linalg.norm(y)
    axes = np.array([x, y, np.cross(x, y)])
    expected = np.concatenate([centred @ axes.T, learned.NORMAL_WEIGHT_M * normals @ axes.T])
    np.testing.assert_allclose(rigid_features(points, normals), expected.ravel(), atol=1e-15)
    # A target's normals point into the fingertips: its key flips them back.
    np.testing.assert_allclose(contact_key(points, -normals), expected.ravel(), atol=1e-15)


def test_key_refuses_bad_input() -> None:
    with pytest.raises(ValueError, match="F >= 3"):
        rigid_features(np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="normals"):
        contact_key(np.zeros((4, 3)), np.zeros((3, 3)))


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


def _stack(hand: Hand, q: np.ndarray) -> np.ndarray:
    out = np.empty((2 * len(hand.fingers), 3))
    compiled_tree(hand).stack(q, np.arange(len(hand.fingers)), out, None)
    return out


def _svd_fit(source: np.ndarray, goal: np.ndarray) -> pin.SE3:
    """Reference least-squares rigid motion (Kabsch, by SVD) mapping ``source`` onto ``goal``."""
    cs, cg = source.mean(axis=0), goal.mean(axis=0)
    U, _, Vt = np.linalg.svd((source - cs).T @ (goal - cg))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return pin.SE3(R, cg - R @ cs)


@pytest.mark.parametrize("noise_m", [0.0, 0.01])
def test_align_moves_the_wrist_by_the_least_squares_rigid_motion(sah: Hand, noise_m: float) -> None:
    rng = np.random.default_rng(12)
    for _ in range(50):
        q = sah.random_configuration(rng)
        source = _stack(sah, q)
        goal = source @ _random_motion(rng).rotation.T + rng.normal(scale=noise_m, size=(8, 3))
        expected = q.copy()
        expected[:7] = pin.SE3ToXYZQUAT(_svd_fit(source, goal) * sah.wrist_pose(q))
        compiled_tree(sah).align(q, goal.ravel(), np.arange(4))
        np.testing.assert_allclose(_stack(sah, q), _stack(sah, expected), atol=1e-12)
        if noise_m == 0.0:  # an exact rigid motion is recovered exactly
            np.testing.assert_allclose(_stack(sah, q), goal, atol=1e-12)


def test_learned_starts_solve_at_the_first_start(sah: Hand) -> None:
    db = default_database(sah)
    assert db is not None and db.seed == LEARN_SEED
    results = [solve_ik(sah, p, init="learned") for p in random_problems(sah, 10, seed=3)]
    assert all(r.success for r in results)
    assert sum(r.inits_used == 1 for r in results) >= 9


def _arrays(problem: GraspTarget, hand: Hand) -> tuple[np.ndarray, np.ndarray]:
    contacts = [problem.contact(f) for f in hand.fingers]
    return np.array([c.point for c in contacts]), np.array([c.normal for c in contacts])


def test_learned_start_places_the_neighbours_wrist_onto_the_target(sah: Hand) -> None:
    db = default_database(sah)
    assert db is not None
    problem = random_problems(sah, 1, seed=4)[0]
    contacts = [problem.contact(f) for f in sah.fingers]
    goal = np.array([row for c in contacts for row in (c.point, c.centre(sah.radius_m))]).ravel()
    (start,) = list(db.starts(sah, contact_key(*_arrays(problem, sah)), goal, 1))
    state = sah.contact_state(start)
    target = np.array([problem.contact(f).point for f in sah.fingers])
    # The neighbour's contacts, rigidly aligned: within a few centimetres of the target's.
    assert np.linalg.norm(state.points - target, axis=1).max() < 0.05


def test_no_learned_start_for_a_target_with_free_fingers(sah: Hand) -> None:
    db = default_database(sah)
    assert db is not None
    problem = random_problems(sah, 1, seed=4)[0]
    three = type(problem)(problem.name, [c for c in problem.contacts if c.finger != "ring"])
    assert target_key(sah, three) is None
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
    monkeypatch.setattr(learned, "PRIMITIVES_PER_CHUNK", 1)
    fresh = build_database(sah, 10, tmp_path / "fresh.npz", seed=6, grasp_sets=10)
    assert fresh.grasp_entries > 0

    def stop_after_first(done: int, total: int) -> None:
        if done == 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        build_database(
            sah, 10, tmp_path / "db.npz", seed=6, progress=stop_after_first, grasp_sets=10
        )
    assert not (tmp_path / "db.npz").exists()
    assert len(list((tmp_path / "db.npz.parts").iterdir())) == 1
    resumed = build_database(sah, 10, tmp_path / "db.npz", seed=6, grasp_sets=10)
    assert resumed.grasp_entries == fresh.grasp_entries
    np.testing.assert_array_equal(resumed.configurations, fresh.configurations)
    np.testing.assert_array_equal(resumed.features, fresh.features)
    assert not (tmp_path / "db.npz.parts").exists()
    loaded = GraspDatabase.load(tmp_path / "db.npz")
    np.testing.assert_array_equal(loaded.configurations, fresh.configurations)


def test_grasp_entries_are_solved_grasps_keyed_by_their_contacts(sah: Hand, tmp_path: Path) -> None:
    db = build_database(sah, 1, tmp_path / "db.npz", seed=9, grasp_sets=10)
    assert db.grasp_entries >= 5
    for q, key in zip(db.configurations[1:], db.features[1:], strict=True):
        state = sah.contact_state(q.astype(np.float64))
        # float32 storage: the keys agree to its precision.
        np.testing.assert_allclose(rigid_features(state.points, state.normals), key, atol=1e-5)
        assert not sah.in_collision(q.astype(np.float64))


def test_grasp_entries_do_not_pass_through_their_solids(sah: Hand, tmp_path: Path) -> None:
    db = build_database(sah, 1, tmp_path / "db.npz", seed=9, grasp_sets=10)
    entries = db.configurations[1:].astype(np.float64)
    matched = np.zeros(len(entries), dtype=bool)
    for mesh, targets in learning.primitive_grasp_sets(sah, 9, 0, 2):
        solid = learning.primitive_object(mesh)
        for target in targets:
            problem = ContactProblem(sah, target, obstacle=solid)
            for i, q in enumerate(entries):
                if max(np.max(e) for e in problem.errors_at(q)) < 1e-4:  # this set's grasp
                    matched[i] = True
                    assert problem.collision(q) is None
    assert matched.all()


def test_grasp_entries_need_a_known_reach(allegro: Hand, tmp_path: Path) -> None:
    with pytest.raises(GraspDatabaseError, match="reach"):
        build_database(allegro, 1, tmp_path / "db.npz", grasp_sets=5)
    assert not (tmp_path / "db.npz.parts").exists()


def test_database_without_grasp_entries_field_loads(sah: Hand, tmp_path: Path) -> None:
    db = build_database(sah, 3, tmp_path / "db.npz", seed=5)
    with np.load(tmp_path / "db.npz") as data:
        fields = {k: data[k] for k in data.files if k != "grasp_entries"}
    np.savez(tmp_path / "old.npz", **fields)
    assert GraspDatabase.load(tmp_path / "old.npz").grasp_entries == 0
    assert db.grasp_entries == 0


def test_shipped_sah_database_starts_object_grasps(sah: Hand) -> None:
    from sahgrasp.objects import load_object
    from sahgrasp.objects.grasp_sampler import sample_object_grasps

    db = default_database(sah)
    assert db is not None and db.grasp_entries > 0
    targets = sample_object_grasps(load_object("can"), 10, seed=12)
    results = [solve_ik(sah, t, init="learned") for t in targets]
    assert sum(r.success and r.inits_used == 1 for r in results) >= 8


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-m", "sahgrasp", *args], capture_output=True, text=True, env=env
    )


@pytest.mark.slow
def test_learn_command_writes_a_database(sah: Hand, tmp_path: Path) -> None:
    out = tmp_path / "sah.npz"
    done = _cli("learn", "--hand", "sah", "--samples", "6", "--grasps", "5", "--seed", "8",
                "--workers", "1", "--out", str(out))  # fmt: skip
    assert done.returncode == 0, done.stderr
    db = GraspDatabase.load(out)
    assert db.configurations.shape == (6 + db.grasp_entries, sah.nq) and db.seed == 8
    assert 0 < db.grasp_entries <= 5
    db.check_hand(sah)


def test_learn_command_refuses_bad_samples(tmp_path: Path) -> None:
    done = _cli("learn", "--samples", "0", "--out", str(tmp_path / "x.npz"))
    assert done.returncode == 2
    assert "argument --samples: 0 is out of range: must be an integer >= 1" in done.stderr
