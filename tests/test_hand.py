import json
import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yourdfpy

from sahgrasp.errors import HandModelError, InvalidConfigurationError
from sahgrasp.hand import Hand, HandDescription, load_hand, sah_description

DEG = math.pi / 180


def test_sah_dof_and_mimic(sah: Hand) -> None:
    assert sah.dof() == {"wrist": 6, "fingers": 13, "virtual": 8, "total": 27}
    assert sah.nv == 27
    assert set(sah.mimic_joints) == {f"{f}_j4" for f in ("thumb", "index", "middle", "ring")}
    assert all(v[1:] == (1.0, 0.0) for v in sah.mimic_joints.values())


def test_allegro_dof(allegro: Hand) -> None:
    assert allegro.dof() == {"wrist": 6, "fingers": 16, "virtual": 8, "total": 30}
    assert allegro.mimic_joints == {}


def test_urdf_loads_in_pinocchio_with_mimic_and_yourdfpy() -> None:
    path = str(sah_description().urdf_path)
    model = pin.buildModelFromUrdf(path, mimic=True)
    assert model.nq == 13
    mimics = [j for j in model.joints if j.shortname() == "JointModelMimic"]
    assert len(mimics) == 4
    urdf = yourdfpy.URDF.load(path)
    assert len(urdf.actuated_joint_names) == 13


def _zero_pose(hand: Hand, **joints: float) -> np.ndarray:
    coords = {n: 0.0 for n in hand.coordinate_names}
    coords.update(joints)
    return hand.configuration(None, coords)


def test_fk_finger_bases_match_fact_sheet(sah: Hand) -> None:
    placements = sah.frame_placements(_zero_pose(sah))
    bases_mm = {
        "thumb_knuckle": (-9.0, 114.0, 97.0),
        "index_base": (-4.3, 40.165, 145.43),
        "middle_base": (-4.3, 0.0, 150.143),
        "ring_base": (-4.3, -40.165, 145.43),
    }
    for link, xyz in bases_mm.items():
        np.testing.assert_allclose(placements[link].translation * 1e3, xyz, atol=1e-6)


def test_fk_zero_pose_fingertip_directions(sah: Hand) -> None:
    q = _zero_pose(sah)
    state = sah.contact_state(q)
    placements = sah.frame_placements(q)
    directions = {
        "thumb": (0, 0.574, 0.819),
        "index": (0, 0.035, 0.999),
        "middle": (0, 0, 1),
        "ring": (0, -0.034, 0.999),
    }
    base = {"thumb": "thumb_knuckle"} | {f: f"{f}_base" for f in ("index", "middle", "ring")}
    for i, f in enumerate(sah.fingers):
        origin = placements[base[f]].translation
        along = state.centres[i] - origin
        assert np.linalg.norm(along) == pytest.approx(0.1273, abs=1e-9)
        np.testing.assert_allclose(along / np.linalg.norm(along), directions[f], atol=2e-3)


def test_fk_hand_computed_flexions(sah: Hand) -> None:
    # Proximal flexed -90 deg: the whole finger points along +x (palmar side) from its base.
    q = _zero_pose(sah, middle_j2=-90 * DEG)
    centre = sah.contact_state(q).centres[sah.fingers.index("middle")]
    np.testing.assert_allclose(centre * 1e3, (-4.3 + 127.3, 0.0, 150.143), atol=1e-6)
    # Middle and (mimic) distal flexed -90 deg: 67.8 up, 30 along +x, 29.5 down.
    q = _zero_pose(sah, middle_j3=-90 * DEG)
    centre = sah.contact_state(q).centres[sah.fingers.index("middle")]
    np.testing.assert_allclose(centre * 1e3, (-4.3 + 30.0, 0.0, 150.143 + 67.8 - 29.5), atol=1e-6)


def test_mimic_joint_follows_leader(sah: Hand) -> None:
    q = _zero_pose(sah, index_j3=-0.7)
    joints = sah.joint_values(q)
    assert joints["index_j4"] == joints["index_j3"] == -0.7


def test_virtual_joints_place_contact_on_pad(sah: Hand) -> None:
    q = _zero_pose(sah, middle_contact_pitch=90 * DEG)
    state = sah.contact_state(q)
    i = sah.fingers.index("middle")
    # Pitch 90 deg turns the contact from the fingertip axis (+z) to the pad (+x of the palm).
    np.testing.assert_allclose(state.normals[i], (1.0, 0.0, 0.0), atol=1e-6)


def test_jacobians_match_finite_differences(any_hand: Hand) -> None:
    rng = np.random.default_rng(3)
    eps = 1e-6
    for _ in range(3):
        q = any_hand.random_configuration(rng)
        q[:3] = rng.normal(scale=0.1, size=3)
        jac = any_hand.contact_jacobians(q)
        for i in range(any_hand.nv):
            step = np.zeros(any_hand.nv)
            step[i] = eps
            plus = any_hand.contact_state(any_hand.integrate(q, step))
            minus = any_hand.contact_state(any_hand.integrate(q, -step))
            for name in ("points", "centres", "normals"):
                fd = (getattr(plus, name) - getattr(minus, name)) / (2 * eps)
                analytic = getattr(jac, name)[:, :, i]
                scale = max(1.0, float(np.abs(analytic).max()))
                np.testing.assert_allclose(analytic, fd, atol=1e-6 * scale, rtol=1e-6)


def test_contact_on_sphere_and_unit_normal(any_hand: Hand) -> None:
    rng = np.random.default_rng(4)
    for _ in range(20):
        state = any_hand.contact_state(any_hand.random_configuration(rng))
        dist = np.linalg.norm(state.points - state.centres, axis=1)
        np.testing.assert_allclose(dist, any_hand.radius_m, atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(state.normals, axis=1), 1.0, atol=1e-12)


def test_random_configuration_within_limits_and_collision_free(any_hand: Hand) -> None:
    rng = np.random.default_rng(5)
    for _ in range(10):
        q = any_hand.random_configuration(rng, collision_free=True)
        assert any_hand.within_limits(q)
        assert not any_hand.in_collision(q)


def test_open_and_closed_without_abduction_are_collision_free(sah: Hand) -> None:
    j3_open = -4 * DEG
    open_hand = _zero_pose(sah, **{f"{f}_j3": j3_open for f in sah.fingers})
    assert not sah.in_collision(open_hand)
    assert sah.min_distance(open_hand) > 0
    closed = {f"{f}_j{j}": -75 * DEG for f in ("index", "middle", "ring") for j in (2, 3)}
    closed |= {"thumb_j0": -90 * DEG, "thumb_j3": j3_open}
    assert not sah.in_collision(_zero_pose(sah, **closed))


def test_neighbours_abducted_towards_each_other_collide(sah: Hand) -> None:
    j3 = {f"{f}_j3": -4 * DEG for f in sah.fingers}
    q = _zero_pose(sah, index_j1=15 * DEG, middle_j1=-15 * DEG, **j3)
    pairs = {(p.link_a, p.link_b) for p in sah.collision.colliding_pairs(q)}
    assert ("index_proximal", "middle_proximal") in pairs
    apart = _zero_pose(sah, index_j1=-15 * DEG, middle_j1=15 * DEG, ring_j1=15 * DEG, **j3)
    assert not any("index" in p.link_a for p in sah.collision.colliding_pairs(apart))


def test_finger_closed_into_palm_is_detected(sah: Hand) -> None:
    # The thumb, not opposed (j0 = 0), folds across the palm when it closes.
    q = _zero_pose(sah, thumb_j2=-75 * DEG, thumb_j3=-75 * DEG)
    pairs = {(p.link_a, p.link_b) for p in sah.collision.colliding_pairs(q)}
    assert any("palm" in pair for pair in pairs)
    assert sah.min_distance(q) < 0


def test_adjacent_links_not_checked(sah: Hand) -> None:
    pairs = {frozenset((p.link_a, p.link_b)) for p in sah.collision.pairs}
    assert frozenset(("index_proximal", "index_middle")) not in pairs
    assert frozenset(("palm", "index_base")) not in pairs
    assert frozenset(("index_proximal", "middle_proximal")) in pairs


def test_configuration_errors(sah: Hand) -> None:
    with pytest.raises(InvalidConfigurationError, match="must have 28 values"):
        sah.check_q(np.zeros(5))
    q = sah.configuration()
    q[9] = np.nan
    with pytest.raises(InvalidConfigurationError, match="NaN"):
        sah.check_q(q)
    with pytest.raises(HandModelError, match="valid"):
        sah.configuration(None, {"pinky_j1": 0.0})


def test_unknown_hand_and_missing_urdf(tmp_path: Path) -> None:
    with pytest.raises(HandModelError, match="sah"):
        load_hand("shadow")
    desc = _description_json(tmp_path, urdf="missing.urdf")
    with pytest.raises(HandModelError, match="not found"):
        load_hand(desc)


def test_malformed_urdf(tmp_path: Path) -> None:
    (tmp_path / "bad.urdf").write_text("<robot name='x'><link name='a'>")
    with pytest.raises(HandModelError, match="not well-formed XML"):
        load_hand(_description_json(tmp_path, urdf="bad.urdf"))


def test_missing_tip_link(tmp_path: Path) -> None:
    desc = _description_json(tmp_path, urdf=str(sah_description().urdf_path), tip="nail")
    with pytest.raises(HandModelError, match=r"nail.*links are"):
        load_hand(desc)


def test_malformed_description(tmp_path: Path) -> None:
    path = tmp_path / "hand.json"
    path.write_text(json.dumps({"name": "x"}))
    with pytest.raises(HandModelError, match=r"missing keys \[.urdf."):
        HandDescription.from_json(path)


def test_user_description_loads_same_hand(tmp_path: Path, sah: Hand) -> None:
    hand = load_hand(_description_json(tmp_path, urdf=str(sah_description().urdf_path)))
    assert hand.nv == sah.nv


def test_digest_depends_on_kinematics(sah: Hand, allegro: Hand) -> None:
    assert sah.description.digest() == load_hand("sah").description.digest()
    assert sah.description.digest() != allegro.description.digest()


def _description_json(folder: Path, urdf: str, tip: str = "tip") -> Path:
    fingers = [
        {"name": f, "tip_link": f"{f}_{tip}", "tip_axis": [0, 1, 0], "pad_axis": [1, 0, 0]}
        for f in ("thumb", "index", "middle", "ring")
    ]
    data = {
        "name": "mine",
        "urdf": urdf,
        "fingertip_radius_m": 0.01,
        "contact_pitch_limits_rad": [-0.26, 1.4],
        "contact_yaw_limits_rad": [-0.6, 0.6],
        "fingers": fingers,
    }
    path = folder / "hand.json"
    path.write_text(json.dumps(data))
    return path
