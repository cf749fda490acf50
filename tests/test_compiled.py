"""The compiled tree and loop of the IK against Pinocchio, finite differences and a plain loop."""

import dataclasses
import itertools
import math
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import pytest
from scipy.linalg import solve

from sahgrasp.ik import IKSettings, hang_from_thumb, random_problems, solve_ik
from sahgrasp.ik._lm import Tree
from sahgrasp.ik.compiled import (
    CYLINDER,
    OUTCOMES,
    POINT,
    _export,
    _shapes,
    compiled_tree,
    near_pairs,
    self_collides,
)
from sahgrasp.ik.solver import ContactProblem, _lm_loop
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import Hand, load_hand, sah_description

FINGER_SETS = (None, [0, 2, 3], [1])


def _indices(hand: Hand, fingers: list[int] | None) -> np.ndarray:
    return np.arange(len(hand.fingers)) if fingers is None else np.array(fingers)


def _stack(tree: Tree, hand: Hand, q: np.ndarray, fingers: np.ndarray) -> tuple:
    stack, J = np.empty(6 * len(fingers)), np.empty((6 * len(fingers), hand.nv))
    tree.stack(q, fingers, stack, J)
    return stack, J


def _configurations(hand: Hand, count: int, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    pin.seed(seed)
    return [hand.random_configuration(rng, T_world_palm=pin.SE3.Random()) for _ in range(count)]


@pytest.fixture(scope="module")
def prismatic_hand(tmp_path_factory: pytest.TempPathFactory) -> Hand:
    """The SAH with its index proximal joint made a slide (limits in metres)."""
    description = sah_description()
    urdf = description.urdf_path.read_text()
    old = '<joint name="index_j2" type="revolute">'
    assert old in urdf
    urdf = urdf.replace(old, '<joint name="index_j2" type="prismatic">').replace(
        'lower="-1.30899694" upper="0.0698131701"', 'lower="-0.02" upper="0.02"', 1
    )
    path = Path(tmp_path_factory.mktemp("prismatic")) / "sah_prismatic.urdf"
    path.write_text(urdf)
    return Hand(dataclasses.replace(description, urdf_path=path))


@pytest.fixture(params=["sah", "allegro", "prismatic"])
def hand(request: pytest.FixtureRequest, sah: Hand, allegro: Hand, prismatic_hand: Hand) -> Hand:
    return {"sah": sah, "allegro": allegro, "prismatic": prismatic_hand}[request.param]


@pytest.mark.parametrize("fingers", FINGER_SETS)
def test_stack_and_jacobian_match_pinocchio(hand: Hand, fingers: list[int] | None) -> None:
    tree = compiled_tree(hand)
    for q in _configurations(hand, 20, 3):
        stack, J = _stack(tree, hand, q, _indices(hand, fingers))
        expected_stack, expected_J = hand.contact_stack_jacobian(q, fingers)
        np.testing.assert_allclose(stack, expected_stack, rtol=0, atol=1e-12)
        np.testing.assert_allclose(J, expected_J, rtol=0, atol=1e-12)


def test_jacobian_matches_finite_differences(hand: Hand) -> None:
    tree, fingers, h = compiled_tree(hand), _indices(hand, None), 1e-7
    for q in _configurations(hand, 5, 4):
        stack, J = _stack(tree, hand, q, fingers)
        moved, numeric = np.empty(hand.nq), np.empty_like(J)
        for c in range(hand.nv):
            tree.integrate(q, h * np.eye(hand.nv)[c], moved, False)
            numeric[:, c] = (_stack(tree, hand, moved, fingers)[0] - stack) / h
        np.testing.assert_allclose(J, numeric, rtol=0, atol=1e-6)


def test_integration_matches_pinocchio_and_clamps(hand: Hand) -> None:
    tree, rng = compiled_tree(hand), np.random.default_rng(5)
    out = np.empty(hand.nq)
    for q in _configurations(hand, 20, 5):
        v = rng.normal(size=hand.nv) * rng.choice([1e-9, 1e-5, 1.0])
        tree.integrate(q, v, out, False)
        np.testing.assert_allclose(out, pin.integrate(hand.model, q, v), rtol=0, atol=1e-12)
        tree.integrate(q, 10.0 * v / np.abs(v).max(), out, True)
        assert np.all(out[7:] >= hand.lower) and np.all(out[7:] <= hand.upper)
        assert np.linalg.norm(out[3:7]) == pytest.approx(1.0, abs=1e-15)


def _plain_loop(hand: Hand, problem: ContactProblem, q: np.ndarray, s: IKSettings) -> tuple:
    """The loop of ``_lm_loop`` written out in numpy on Pinocchio's kinematics (the reference)."""
    damping, fingers = 1e-3, problem.rows.tolist()
    stack, J = hand.contact_stack_jacobian(q, fingers)
    e = problem.target_stack - stack
    costs = [e.dot(e)]

    def max_error(r: np.ndarray) -> float:
        return math.sqrt((r * r).reshape(-1, 3).sum(axis=1).max())

    for k in range(s.max_iterations):
        if max_error(e) < s.refine_m:
            return q, "converged", k
        stall = s.stall_iterations
        if (len(costs) > stall and costs[-1] > 0.5 * costs[-1 - stall]) or damping > 1e4:
            return q, "converged" if max_error(e) < s.d_min_m else "no_progress", k
        g = J.T @ e
        x = q[7:]
        fixed = ((x <= hand.lower + 1e-12) & (g[6:] < 0)) | (
            (x >= hand.upper - 1e-12) & (g[6:] > 0)
        )
        free = np.concatenate([np.ones(6, bool), ~fixed])
        while damping <= 1e4:
            step = np.zeros(hand.nv)
            A = J[:, free].T @ J[:, free] + damping * np.eye(free.sum())
            step[free] = solve(A, g[free], assume_a="pos")
            candidate = pin.integrate(hand.model, q, step)
            candidate[7:] = np.clip(candidate[7:], hand.lower, hand.upper)
            e_new = problem.target_stack - hand.contact_stack(candidate, fingers)
            if e_new.dot(e_new) < costs[-1]:
                q, e, damping = candidate, e_new, max(damping / 3, 1e-7)
                J = hand.contact_stack_jacobian(q, fingers)[1]
                costs.append(e.dot(e))
                break
            damping *= 4
    return q, "converged" if max_error(e) < s.d_min_m else "max_iterations", s.max_iterations


def _start(hand: Hand, target: GraspTarget) -> np.ndarray:
    """The hand at mid-range, hung from the thumb contact."""
    return hang_from_thumb(hand, 0.5 * (hand.lower + hand.upper), target)[0]


@pytest.mark.parametrize("free", [(), ("ring",)])
def test_loop_matches_a_plain_numpy_loop(sah: Hand, free: tuple[str, ...]) -> None:
    settings = IKSettings()
    outcomes = []
    for target in random_problems(sah, 25, 6):
        if free:
            target = GraspTarget(target.name, [c for c in target.contacts if c.finger not in free])
        problem = ContactProblem(sah, target, free)
        q0 = _start(sah, target)
        attempt = _lm_loop(sah, problem, q0, settings, settings.max_iterations, None)
        q, outcome, iterations = _plain_loop(sah, problem, q0, settings)
        outcomes.append(attempt.outcome)
        assert (attempt.outcome, attempt.iterations) == (outcome, iterations)
        np.testing.assert_allclose(attempt.q, q, rtol=0, atol=1e-6)
    assert set(outcomes) >= {"converged", "no_progress"}


def test_history_holds_every_accepted_step(sah: Hand) -> None:
    settings = IKSettings()
    target = random_problems(sah, 1, 7)[0]
    problem = ContactProblem(sah, target)
    q0 = _start(sah, target)
    history = [q0.copy()]
    attempt = _lm_loop(sah, problem, q0, settings, settings.max_iterations, history)
    assert attempt.outcome in OUTCOMES.values()
    assert len(history) > 2 and np.array_equal(history[-1], attempt.q)
    assert all(not np.array_equal(a, b) for a, b in itertools.pairwise(history))


def test_bad_input_is_a_typed_error(sah: Hand) -> None:
    tree, q = compiled_tree(sah), np.array(sah.configuration())
    stack, target = np.empty(24), np.zeros(24)
    with pytest.raises(ValueError, match="q: expected 28"):
        tree.stack(q[:-1], np.arange(4), stack, None)
    with pytest.raises(ValueError, match="finger index out of range"):
        tree.stack(q, np.array([0, 4]), np.empty(12), None)
    with pytest.raises(ValueError, match="stack"):
        tree.stack(q, np.arange(4), np.empty(12), None)
    with pytest.raises(TypeError, match="fingers must be a C-contiguous int64 array"):
        tree.stack(q, np.arange(4.0), stack, None)
    with pytest.raises(TypeError, match="q must be a C-contiguous float64 array"):
        tree.stack(q.astype(np.float32), np.arange(4), stack, None)
    with pytest.raises(ValueError, match="max_iterations"):
        tree.solve(q, target, np.arange(4), -1, 1e-5, 1.5e-3, 10, None)
    with pytest.raises(ValueError, match="fingers must not be empty"):
        tree.solve(q, np.zeros(0), np.arange(0), 10, 1e-5, 1.5e-3, 10, None)
    with pytest.raises(RuntimeError, match="not initialised"):
        Tree.__new__(Tree).integrate(q, np.zeros(27), q.copy(), False)


def test_errors_raised_by_history_propagate(sah: Hand) -> None:
    tree, target = compiled_tree(sah), random_problems(sah, 1, 8)[0]
    problem = ContactProblem(sah, target)
    q = _start(sah, target)

    def failing() -> None:
        raise KeyError("from history")

    with pytest.raises(KeyError, match="from history"):
        tree.solve(q, problem.target_stack, problem.rows, 50, 1e-5, 1.5e-3, 10, failing)


def test_a_second_load_of_the_hand_gets_its_own_tree() -> None:
    first, second = load_hand("sah"), load_hand("sah")
    assert compiled_tree(first) is compiled_tree(first)
    assert compiled_tree(first) is not compiled_tree(second)


def _reference_repair(
    hand: Hand, q: np.ndarray, target: np.ndarray, fingers: np.ndarray, pairs: list
) -> np.ndarray:
    """One collision-repair step from Pinocchio's Jacobians and numpy (the step before it was
    compiled): contact rows and witness rows in damped least squares, bounds as an active set."""
    stack, J_contacts = _stack(compiled_tree(hand), hand, q, fingers)
    state = hand.state(q, jacobians=True)
    rows = [n @ (state.point_jacobian(jb, xb) - state.point_jacobian(ja, xa))
            for ja, jb, xa, xb, n, _ in pairs]  # fmt: skip
    J = np.vstack([J_contacts, rows])
    e = np.concatenate([target - stack, [p[5] for p in pairs]])
    g = J.T @ e
    x, (low, high) = hand.finger_part(q), hand.bound_tests
    fixed = ((x <= low) & (g[6:] < 0.0)) | ((x >= high) & (g[6:] > 0.0))
    free = np.concatenate([np.ones(6, bool), ~fixed])
    step = np.zeros(hand.nv)
    JF = J[:, free]
    step[free] = solve(JF.T @ JF + 1e-6 * np.eye(free.sum()), JF.T @ e, assume_a="pos")
    out = pin.integrate(hand.model, q, step)
    joints = hand.finger_part(out)
    joints[:] = np.clip(joints, hand.lower, hand.upper)
    return out


@pytest.mark.parametrize("fingers", FINGER_SETS)
def test_repair_step_matches_pinocchio_and_numpy(hand: Hand, fingers: list[int] | None) -> None:
    tree, idx = compiled_tree(hand), _indices(hand, fingers)
    rng = np.random.default_rng(31)
    njoints = hand.model.njoints
    for q in _configurations(hand, 10, 32):
        # Joints at their bounds, so that the active set has work to do.
        x = hand.finger_part(q)
        x[::3] = np.where(rng.random(x[::3].size) < 0.5, hand.lower[::3], hand.upper[::3])
        target = _stack(tree, hand, q, idx)[0] + rng.normal(scale=0.01, size=6 * len(idx))
        # Pairs between random joints (0: the world) at random points, unit normals, depths [m].
        pairs = []
        for _ in range(3):
            ja, jb = rng.integers(0, njoints, 2)
            n = rng.normal(size=3)
            pairs.append((ja, jb, rng.normal(size=3) * 0.1, rng.normal(size=3) * 0.1,
                          n / np.linalg.norm(n), rng.uniform(0.0, 0.005)))  # fmt: skip
        out = np.empty(hand.nq)
        ok = tree.repair(
            q, target, idx,
            np.array([(p[0] - 1, p[1] - 1) for p in pairs], dtype=np.int64),
            np.array([(p[2], p[3]) for p in pairs]), np.array([p[4] for p in pairs]),
            np.array([p[5] for p in pairs]), out,
        )  # fmt: skip
        assert ok
        expected = _reference_repair(hand, q, target, idx, pairs)
        # A large step can land on the other sign of the same wrist quaternion.
        for config in (out, expected):
            config[3:7] *= np.sign(config[6])
        np.testing.assert_allclose(out, expected, atol=1e-9)


def test_repair_refuses_bad_input(sah: Hand) -> None:
    tree, q, out = compiled_tree(sah), sah.configuration(), np.empty(sah.nq)
    good = (np.zeros(24), np.arange(4), np.zeros((1, 2), np.int64), np.zeros((1, 2, 3)),
            np.ones((1, 3)), np.zeros(1), out)  # fmt: skip
    assert tree.repair(q, *good) in (True, False)
    with pytest.raises(ValueError, match="joint out of range"):
        tree.repair(q, *good[:2], np.full((1, 2), 99, np.int64), *good[3:])
    with pytest.raises(ValueError, match="normals"):
        tree.repair(q, *good[:4], np.ones((2, 3)), *good[5:])
    with pytest.raises(TypeError):
        tree.repair(q, *good[:2], np.zeros((1, 2)), *good[3:])  # float joints


def _coal_distances(hand: Hand, q: np.ndarray) -> np.ndarray:
    """coal's signed distance of every checked pair at ``q`` [m], in pair order."""
    collision = hand.collision
    pin.computeDistances(
        hand.model, collision.data, collision.geometry_model, collision.geometry_data, q
    )
    return np.array([r.min_distance for r in collision.geometry_data.distanceResults])


def _self_collision_configurations(hand: Hand) -> list[np.ndarray]:
    """Random configurations (half of them colliding) and IK solutions (near contact)."""
    solved = [r.q for r in (solve_ik(hand, t) for t in random_problems(hand, 20, seed=8123))]
    return _configurations(hand, 60, 8124) + solved


@pytest.mark.parametrize("margin_m", [0.0, 1e-3, 5e-3])
def test_pairs_within_match_coal_distances(hand: Hand, margin_m: float) -> None:
    tree = compiled_tree(hand)
    assert tree.shape_count == len(hand.collision.geometry_model.geometryObjects)
    assert tree.pair_count == len(hand.collision.pairs)
    out, counted = np.empty(tree.pair_count, dtype=np.int64), 0
    for q in _self_collision_configurations(hand):
        distances = _coal_distances(hand, q)
        found = set(out[: tree.pairs_within(q, margin_m, out)].tolist())
        clear_cut = np.abs(distances - margin_m) > 1e-9  # GJK's tolerance decides the others
        expected = set(np.flatnonzero(clear_cut & (distances < margin_m)).tolist())
        assert found & set(np.flatnonzero(clear_cut)) == expected
        counted += len(expected)
    assert counted > 0  # some pairs were within the margin


def test_pairs_within_stops_at_the_length_of_out(sah: Hand) -> None:
    tree = compiled_tree(sah)
    q = next(q for q in _configurations(sah, 50, 8125) if sah.in_collision(q))
    every = np.empty(tree.pair_count, dtype=np.int64)
    count = tree.pairs_within(q, 0.01, every)
    first = np.empty(1, dtype=np.int64)
    assert count >= 1 and tree.pairs_within(q, 0.01, first) == 1
    assert first[0] == every[0]
    with pytest.raises(ValueError, match="margin_m"):
        tree.pairs_within(q, -1e-3, every)
    with pytest.raises(TypeError):
        tree.pairs_within(q, 0.0, np.empty(3))  # float indices


def test_self_collides_is_the_verdict_of_coal_distances(hand: Hand) -> None:
    verdicts = []
    for q in _self_collision_configurations(hand):
        deepest_m = _coal_distances(hand, q).min()
        if abs(deepest_m) > 1e-9:
            assert self_collides(hand, q) == (deepest_m < 0.0)
            verdicts.append(deepest_m < 0.0)
    assert any(verdicts) and not all(verdicts)


def test_near_pairs_give_the_same_witnesses_as_coal_alone(sah: Hand) -> None:
    for q in _configurations(sah, 40, 8126):
        near = near_pairs(sah, q, 2e-3)
        assert near is not None
        alone = sah.penetrations(q, 2e-3)
        guided = sah.penetrations(q, 2e-3, near)
        assert [(p.joint_a, p.joint_b, p.depth_m) for p in guided] == [
            (p.joint_a, p.joint_b, p.depth_m) for p in alone
        ]


def test_a_hand_with_a_mesh_shape_falls_back_to_coal(tmp_path: Path) -> None:
    description = sah_description()
    mesh = Path(__file__).resolve().parents[1] / "examples" / "meshes" / "mug.stl"
    urdf = description.urdf_path.read_text()
    palm = '<geometry><box size="0.0657 0.12 0.13"/></geometry></collision>'
    assert palm in urdf
    urdf = urdf.replace(
        palm, f'<geometry><mesh filename="{mesh}" scale="0.5 0.5 0.5"/></geometry></collision>', 1
    )
    path = tmp_path / "sah_mesh_palm.urdf"
    path.write_text(urdf)
    hand = Hand(dataclasses.replace(description, urdf_path=path))
    assert compiled_tree(hand).shape_count == 0
    assert near_pairs(hand, hand.configuration(), 1e-3) is None
    for q in _configurations(hand, 10, 8127):
        assert self_collides(hand, q) == hand.in_collision(q)


def test_capsules_are_inflated_segments(sah: Hand) -> None:
    geometry = pin.GeometryModel()
    for name, shape in (("ball", coal.Sphere(0.01)), ("capsule", coal.Capsule(0.02, 0.1))):
        geometry.addGeometryObject(pin.GeometryObject(name, 1, pin.SE3.Identity(), shape))
    shapes = _shapes(geometry)
    assert shapes is not None
    placements, kinds, sizes = shapes["placements"], shapes["kinds"], shapes["sizes"]
    assert kinds.tolist() == [POINT, CYLINDER]  # a point and a cylinder of radius 0, inflated
    np.testing.assert_allclose(sizes, [[0, 0, 0, 0.01], [0, 0.05, 0, 0.02]])
    tree, out, pair = _export(sah), np.empty(1, dtype=np.int64), np.array([[0, 1]], np.int64)
    # The capsule moved along x from the sphere's centre: they touch at x = 0.03 m.
    for x_m, touching in ((0.0299, True), (0.0301, False)):
        moved = np.array([placements[0], [*np.eye(3).ravel(), x_m, 0.0, 0.0]])
        tree.set_shapes(**{**shapes, "placements": moved, "pairs": pair})
        assert (tree.pairs_within(sah.configuration(), 0.0, out) == 1) is touching


@pytest.mark.parametrize("fingers", FINGER_SETS)
def test_errors_match_pinocchio(hand: Hand, fingers: list[int] | None) -> None:
    tree, rows = compiled_tree(hand), _indices(hand, fingers)
    target = np.random.default_rng(8128).normal(0.0, 0.1, 6 * len(rows))
    for q in _configurations(hand, 5, 8129):
        state = hand.contact_state(q)
        points, centres = target.reshape(-1, 2, 3)[:, 0], target.reshape(-1, 2, 3)[:, 1]
        out = np.empty(2 * len(rows))
        tree.errors(q, target, rows, out)
        np.testing.assert_allclose(
            out[: len(rows)], np.linalg.norm(state.points[rows] - points, axis=1), atol=1e-12
        )
        np.testing.assert_allclose(
            out[len(rows) :], np.linalg.norm(state.centres[rows] - centres, axis=1), atol=1e-12
        )
    with pytest.raises(ValueError, match="out"):
        tree.errors(hand.configuration(), target, rows, np.empty(1))
