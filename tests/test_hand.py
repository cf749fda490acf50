import importlib.util
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
import yourdfpy

from sahgrasp.core.errors import HandModelError, InvalidConfigurationError, InvalidSettingsError
from sahgrasp.model import hand as hand_module
from sahgrasp.model.hand import Hand, HandDescription, load_hand, sah_description

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


def test_in_collision_matches_the_colliding_pairs(any_hand: Hand) -> None:
    """``in_collision`` stops at the first colliding pair; it must agree with listing them all."""
    rng = np.random.default_rng(7)
    verdicts = []
    for _ in range(300):
        q = any_hand.random_configuration(rng)
        verdicts.append(any_hand.in_collision(q))
        assert verdicts[-1] == bool(any_hand.collision.colliding_pairs(q))
    assert 0 < sum(verdicts) < len(verdicts)  # both answers were exercised


@pytest.mark.parametrize("margin_m", [1e-3, 5e-3])
def test_penetrations_found_exactly_when_a_pair_is_within_the_margin(
    any_hand: Hand, margin_m: float
) -> None:
    """The broad-phase gate of ``penetrations`` prunes no pair within the margin."""
    rng = np.random.default_rng(8)
    found = []
    for _ in range(300):
        q = any_hand.random_configuration(rng)
        distance = any_hand.min_distance(q)
        if abs(distance - margin_m) < 1e-7:  # on the boundary either answer is right
            continue
        found.append(bool(any_hand.penetrations(q, margin_m)))
        assert found[-1] == (distance < margin_m)
    assert 0 < sum(found) < len(found)


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


def test_urdf_given_for_a_description_is_explained() -> None:
    with pytest.raises(HandModelError, match="is a URDF; give the path of a hand description"):
        load_hand(sah_description().urdf_path)


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


def _description_data(urdf: str, tip: str = "tip") -> dict[str, Any]:
    fingers = [
        {"name": f, "tip_link": f"{f}_{tip}", "tip_axis": [0, 1, 0], "pad_axis": [1, 0, 0]}
        for f in ("thumb", "index", "middle", "ring")
    ]
    return {
        "name": "mine",
        "urdf": urdf,
        "fingertip_radius_m": 0.01,
        "contact_pitch_limits_rad": [-0.26, 1.4],
        "contact_yaw_limits_rad": [-0.6, 0.6],
        "fingers": fingers,
    }


def _description_json(folder: Path, urdf: str, tip: str = "tip") -> Path:
    path = folder / "hand.json"
    path.write_text(json.dumps(_description_data(urdf, tip)))
    return path


# ----- validation of URDFs (before Pinocchio sees them) -------------------------------------------
_SAH_URDF = sah_description().urdf_path.read_text()
_EXTRA_JOINT = """<joint name="{name}" type="fixed"><parent link="{parent}"/><child link="{child}"/>
</joint>"""
_TWO_LINKS = '<link name="a"/><link name="b"/>'


def _edited(old: str, new: str, count: int = 1) -> str:
    assert old in _SAH_URDF, old
    return _SAH_URDF.replace(old, new, count)


def _with(extra: str) -> str:
    return _SAH_URDF.replace("</robot>", extra + "</robot>")


_J4 = '<mimic joint="index_j3" multiplier="1" offset="0"/>'
_J2_LIMIT = '<limit lower="-1.30899694" upper="0.0698131701" effort="5" velocity="2"/>'

BAD_URDFS = {
    "two parents": (
        _with(_EXTRA_JOINT.format(name="x", parent="palm", child="index_tip")),
        r"'index_tip' has two parent joints",
    ),
    "missing link": (
        _with(_EXTRA_JOINT.format(name="x", parent="palm", child="nowhere")),
        r"child link 'nowhere', which is not a link",
    ),
    "two roots": (_with('<link name="orphan"/>'), r"2 root links \['palm', 'orphan'\]"),
    "detached cycle": (
        _with(
            _TWO_LINKS
            + _EXTRA_JOINT.format(name="x", parent="a", child="b")
            + _EXTRA_JOINT.format(name="y", parent="b", child="a")
        ),
        r"links \['a', 'b'\] form a cycle",
    ),
    "root in a cycle": (
        _with(_EXTRA_JOINT.format(name="x", parent="index_tip", child="palm")),
        "0 root links",
    ),
    "duplicate link": (_with('<link name="palm"/>'), "two links are named 'palm'"),
    "mimic leader missing": (
        _edited(_J4, _J4.replace("index_j3", "index_j9")),
        "mimics 'index_j9'",
    ),
    "mimic of itself": (_edited(_J4, _J4.replace("index_j3", "index_j4")), "mimics 'index_j4'"),
    "mimic of a mimic": (
        _edited('<mimic joint="middle_j3"', '<mimic joint="index_j4"'),
        "itself a mimic joint",
    ),
    "mimic multiplier 0": (_edited(_J4, _J4.replace('"1"', '"0"')), "multiplier 0"),
    "zero axis": (_edited('<axis xyz="0 0 1"/>', '<axis xyz="0 0 0"/>'), "zero axis"),
    "NaN axis": (_edited('<axis xyz="0 0 1"/>', '<axis xyz="0 nan 1"/>'), "3 finite number"),
    "inverted limits": (
        _edited(_J2_LIMIT, _J2_LIMIT.replace("-1.30899694", "0.5")),
        r"lower < upper, got lower=0.5",
    ),
    "equal limits": (
        _edited(_J2_LIMIT, _J2_LIMIT.replace("0.0698131701", "-1.30899694")),
        "lower <",
    ),
    "infinite limit": (_edited(_J2_LIMIT, _J2_LIMIT.replace("-1.30899694", "-inf")), "finite"),
    "huge limit": (_edited(_J2_LIMIT, _J2_LIMIT.replace("-1.30899694", "-1e300")), "unit mistake"),
    "no limit": (_edited(_J2_LIMIT, ""), r"needs <limit lower upper>"),
    "NaN effort": (_edited(_J2_LIMIT, _J2_LIMIT.replace('effort="5"', 'effort="nan"')), "finite"),
    "continuous": (
        _edited('name="index_j2" type="revolute"', 'name="index_j2" type="continuous"'),
        "no limits",
    ),
    "floating": (
        _edited('name="index_j2" type="revolute"', 'name="index_j2" type="floating"'),
        "free flyer",
    ),
    "unknown type": (
        _edited('name="index_j2" type="revolute"', 'name="index_j2" type="screw"'),
        "valid",
    ),
    "NaN origin": (_edited('<origin xyz="0.03 0 0"', '<origin xyz="0.03 NaN 0"'), "finite"),
    "negative box": (
        _edited('<box size="0.022 0.03 0.026"/>', '<box size="0.022 -0.03 0.026"/>'),
        "> 0",
    ),
    # XML 1.0 forbids C0 controls such as ESC; C1 controls (8-bit CSI) and bidi overrides parse.
    "ANSI link name": (_SAH_URDF.replace("index_tip", "index_\x1b[31mtip"), "not well-formed"),
    "C1 CSI link name": (_SAH_URDF.replace("index_tip", "index_\x9b31mtip"), r"printable.*\\x9b"),
    "bidi joint name": (_SAH_URDF.replace("index_j2", "index\u202ej2"), r"printable.*\\u202e"),
    "DOCTYPE": (
        '<?xml version="1.0"?><!DOCTYPE robot [<!ENTITY x "palm">]>' + _SAH_URDF.split("?>", 1)[1],
        "DOCTYPE",
    ),
    "deep nesting": (_with("<a>" * 5000 + "</a>" * 5000), "nests elements more than 32 deep"),
    "not XML": ("robot", "not well-formed"),
    "virtual joint name taken": (
        _SAH_URDF.replace('"index_j1"', '"index_contact_pitch"'),
        "a joint named 'index_contact_pitch', the name of a virtual contact joint",
    ),
    # urdfdom only logs this and drops the palm's collision box: the load must fail instead.
    "inertial without mass": (
        _edited('<mass value="0.05"/>', ""),
        r"Inertial element must have a mass element; .*Link \[palm\]",
    ),
    "not a robot": ("<model/>", "not <robot>"),
}


@pytest.mark.parametrize("case", sorted(BAD_URDFS))
def test_bad_urdf_is_refused_with_its_reason(tmp_path: Path, case: str) -> None:
    text, reason = BAD_URDFS[case]
    (tmp_path / "hand.urdf").write_text(text)
    with pytest.raises(HandModelError, match=reason) as info:
        load_hand(_description_json(tmp_path, urdf="hand.urdf"))
    assert str(info.value).isprintable()


@pytest.mark.parametrize("data", [b"\xff\xfe<\x00r\x00", "<robot/>".encode("utf-16")])
def test_non_utf8_urdf_is_refused(tmp_path: Path, data: bytes) -> None:
    (tmp_path / "hand.urdf").write_bytes(data)
    with pytest.raises(HandModelError, match="not UTF-8"):
        load_hand(_description_json(tmp_path, urdf="hand.urdf"))


def test_placeholder_effort_and_velocity_are_accepted(tmp_path: Path) -> None:
    limit = _J2_LIMIT.replace('effort="5" velocity="2"', 'effort="1e9" velocity="1e9"')
    (tmp_path / "hand.urdf").write_text(_edited(_J2_LIMIT, limit))
    assert load_hand(_description_json(tmp_path, urdf="hand.urdf")).nv == 27


def test_tip_link_must_be_a_link_not_a_joint(tmp_path: Path) -> None:
    desc = _description_json(tmp_path, urdf=str(sah_description().urdf_path), tip="j2")
    with pytest.raises(HandModelError, match=r"'thumb_j2' is not in the URDF"):
        load_hand(desc)


def test_excluded_collisions_must_name_links(tmp_path: Path) -> None:
    path = _description_json(tmp_path, urdf=str(sah_description().urdf_path))
    data = json.loads(path.read_text())
    data["excluded_collisions"] = [["palm", "pinky_base"]]
    path.write_text(json.dumps(data))
    with pytest.raises(HandModelError, match=r"\['pinky_base'\], which are not links"):
        load_hand(path)


# ----- validation of hand descriptions ------------------------------------------------------------
def _finger_edit(key: str, value: object, index: int = 1) -> dict[str, object]:
    fingers = _description_data("")["fingers"]
    fingers[index][key] = value
    return {"fingers": fingers}


BAD_DESCRIPTIONS: dict[str, tuple[dict[str, object], str]] = {
    "zero radius": ({"fingertip_radius_m": 0.0}, r"fingertip_radius_m must be in \(0, 1.0\]"),
    "negative radius": ({"fingertip_radius_m": -0.01}, "must be in"),
    "radius in mm": ({"fingertip_radius_m": 10}, "must be in"),
    "NaN radius": ({"fingertip_radius_m": math.nan}, "must be finite"),
    "huge int radius": ({"fingertip_radius_m": 10**400}, "must be finite"),
    "string radius": ({"fingertip_radius_m": "0.01"}, "must be a number"),
    "boolean radius": ({"fingertip_radius_m": True}, "must be a number"),
    "no fingers": ({"fingers": []}, "has no fingers"),
    "fingers not a list": ({"fingers": {}}, "fingers must be a list"),
    "duplicate finger": (_finger_edit("name", "thumb"), r"finger names \['thumb'\] appear more"),
    "duplicate tip": (_finger_edit("tip_link", "thumb_tip"), r"tip_links \['thumb_tip'\]"),
    "inverted pitch": ({"contact_pitch_limits_rad": [1.0, -1.0]}, "-pi < lower < upper < pi"),
    "pitch beyond pi": ({"contact_pitch_limits_rad": [-0.2, 3.5]}, "-pi < lower < upper < pi"),
    "infinite yaw": ({"contact_yaw_limits_rad": [-math.inf, 0.5]}, "must be finite"),
    "one yaw limit": ({"contact_yaw_limits_rad": [0.5]}, "list of 2 numbers"),
    "zero axis": (_finger_edit("tip_axis", [0, 0, 0]), "non-zero finite vector"),
    "short axis": (_finger_edit("pad_axis", [1, 0]), "list of 3 numbers"),
    "axes not orthogonal": (_finger_edit("pad_axis", [1, 1, 0]), "must be orthogonal"),
    "ANSI hand name": ({"name": "\x1b[2Jmine"}, r"printable.*\\x1b"),
    "ANSI finger name": (_finger_edit("name", "in\x1bdex"), "printable"),
    "empty finger name": (_finger_edit("name", ""), "non-empty"),
    "unknown key": ({"fingertip_radius": 0.01}, r"unknown keys \['fingertip_radius'\]"),
    "finger key missing": (
        {"fingers": [{"name": "thumb", "tip_link": "thumb_tip", "tip_axis": [0, 1, 0]}]},
        "exactly the keys",
    ),
    "urdf not a string": ({"urdf": 3}, "urdf must be a non-empty string"),
}


@pytest.mark.parametrize("case", sorted(BAD_DESCRIPTIONS))
def test_bad_description_is_refused_with_its_reason(tmp_path: Path, case: str) -> None:
    edit, reason = BAD_DESCRIPTIONS[case]
    data = _description_data(str(sah_description().urdf_path)) | edit
    path = tmp_path / "hand.json"
    path.write_text(json.dumps(data))
    with pytest.raises(HandModelError, match=reason) as info:
        load_hand(path)
    assert "\x1b" not in str(info.value)


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (b"\x89PNG\r\n\x1a\n\x00\x00", "not UTF-8 text"),
        ('{"name": "x"}'.encode("utf-16"), "not UTF-8 text"),
        (b"[" * 100_000 + b"]" * 100_000, "nested too deeply"),
        (b"[1, 2]", "must hold a JSON object, got list"),
        (b"{name: x}", "not valid JSON"),
    ],
)
def test_unreadable_description_files(tmp_path: Path, data: bytes, reason: str) -> None:
    path = tmp_path / "hand.json"
    path.write_bytes(data)
    with pytest.raises(HandModelError, match=reason):
        load_hand(path)


def test_description_built_in_code_is_checked_too() -> None:
    sah = sah_description()
    with pytest.raises(HandModelError, match="unit vector"):
        HandDescription(
            **{
                **sah.__dict__,
                "fingers": (sah.fingers[0].__class__("t", "t", (0.0, 2.0, 0.0), (1.0, 0.0, 0.0)),),
            }
        )
    with pytest.raises(HandModelError, match="has no fingers"):
        HandDescription(**{**sah.__dict__, "fingers": ()})


# ----- configurations -----------------------------------------------------------------------------
@pytest.mark.parametrize(
    "query", ["contact_state", "contact_jacobians", "in_collision", "min_distance"]
)
@pytest.mark.parametrize(
    ("index", "value"), [(3, math.nan), (9, math.nan), (0, math.inf), (20, -math.inf)]
)
def test_queries_refuse_non_finite_configurations(
    sah: Hand, query: str, index: int, value: float
) -> None:
    q = sah.configuration()
    q[index] = value
    with pytest.raises(InvalidConfigurationError, match="NaN or inf"):
        getattr(sah, query)(q)


@pytest.mark.parametrize(
    "query", ["contact_state", "contact_jacobians", "in_collision", "min_distance"]
)
def test_queries_refuse_wrong_sizes(sah: Hand, query: str) -> None:
    with pytest.raises(InvalidConfigurationError, match="must have 28 values"):
        getattr(sah, query)(np.zeros(27))


def test_huge_but_finite_configuration_is_not_called_nan(sah: Hand) -> None:
    q = sah.configuration()
    q[0] = 1e300  # its square, or a sum of such values, would overflow
    assert np.isfinite(sah.contact_state(q).normals).all()


# ----- digest -------------------------------------------------------------------------------------
def test_loaded_hand_digest_is_pinned_to_the_urdf_it_was_built_from(tmp_path: Path) -> None:
    urdf = tmp_path / "hand.urdf"
    urdf.write_text(_SAH_URDF)
    hand = load_hand(_description_json(tmp_path, urdf="hand.urdf"))
    digest = hand.description.digest()
    urdf.write_text(_SAH_URDF.replace('effort="5"', 'effort="6"'))
    assert hand.description.digest() == digest  # the hand in memory did not change
    fresh = HandDescription.from_json(tmp_path / "hand.json")
    assert fresh.digest() != digest  # the file did: a new description sees it
    urdf.unlink()
    assert hand.description.digest() == digest  # no file access at all
    with pytest.raises(HandModelError, match="cannot read URDF"):
        fresh.digest()


def test_digest_is_the_same_for_a_description_and_its_loaded_hand(sah: Hand) -> None:
    assert sah_description().digest() == sah.description.digest()
    assert sah.description == sah_description()


def test_generator_reproduces_the_shipped_urdf() -> None:
    # The URDF bytes are hashed into the digest the shipped sequences are keyed by.
    root = Path(__file__).resolve().parents[1]
    spec = importlib.util.spec_from_file_location("make_sah_urdf", root / "tools/make_sah_urdf.py")
    assert spec is not None and spec.loader is not None
    generator = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(generator)
    assert generator.urdf() == (root / "urdf/sah_right.urdf").read_text(encoding="utf-8")


@pytest.mark.parametrize("calls", [0, -1, True])
def test_bench_kinematics_refuses_non_positive_calls(calls: int) -> None:
    from sahgrasp.bench.kinematics import run

    with pytest.raises(InvalidSettingsError, match="calls must be a positive integer"):
        run(calls=calls)


def test_state_is_an_immutable_snapshot(any_hand: Hand) -> None:
    rng = np.random.default_rng(21)
    q = any_hand.random_configuration(rng)
    state = any_hand.state(q, jacobians=True)
    points = state.contacts.points.copy()
    any_hand.contact_state(any_hand.random_configuration(rng))  # another query in between
    np.testing.assert_array_equal(state.contacts.points, points)
    with pytest.raises(ValueError, match="read-only"):
        state.contacts.points[0, 0] = 1.0
    assert state.jacobians is not None
    with pytest.raises(ValueError, match="read-only"):
        state.jacobians.points[0, 0, 0] = 1.0
    assert any_hand.state(q).jacobians is None


def test_stack_jacobian_and_point_jacobian_match_finite_differences(any_hand: Hand) -> None:
    rng = np.random.default_rng(22)
    q = any_hand.random_configuration(rng)
    stack, J = any_hand.contact_stack_jacobian(q)
    state = any_hand.state(q, jacobians=True)
    np.testing.assert_allclose(stack.reshape(-1, 2, 3)[:, 0], state.contacts.points, atol=1e-15)
    np.testing.assert_allclose(stack.reshape(-1, 2, 3)[:, 1], state.contacts.centres, atol=1e-15)
    v, eps = rng.normal(size=any_hand.nv), 1e-7
    moved = any_hand.integrate(q, eps * v)
    fd = (any_hand.contact_stack(moved) - stack) / eps
    np.testing.assert_allclose(fd, J @ v, atol=1e-5)
    # A point on the last joint's body moves with it; the world (joint 0) does not move.
    joint, point = any_hand.model.njoints - 1, state.contacts.points[-1]
    np.testing.assert_allclose(state.point_jacobian(joint, point), J[-6:-3], atol=1e-12)
    assert not state.point_jacobian(0, point).any()
    with pytest.raises(InvalidConfigurationError, match="no Jacobians"):
        any_hand.state(q).point_jacobian(joint, point)


def test_wrist_and_finger_parts_split_q(sah: Hand) -> None:
    q = sah.random_configuration(np.random.default_rng(23))
    np.testing.assert_array_equal(np.concatenate([sah.wrist_part(q), sah.finger_part(q)]), q)
    assert sah.finger_part(q).shape == (len(sah.coordinate_names),)


def test_penetrations_refuse_non_finite_q(sah: Hand) -> None:
    q = sah.configuration()
    q[9] = np.nan
    with pytest.raises(InvalidConfigurationError, match="NaN"):
        sah.penetrations(q, 1e-3)


def test_jacobians_of_a_mimic_joint_moving_another_finger_than_its_leader(tmp_path: Path) -> None:
    # The middle finger's distal joint follows the index's: data.J is masked before the mimic
    # columns are folded (the built-in hands fold first), and the rows match finite differences.
    urdf = tmp_path / "crossed.urdf"
    urdf.write_text(_edited('<mimic joint="middle_j3"', '<mimic joint="index_j3"'))
    hand = load_hand(_description_json(tmp_path, urdf=str(urdf)))
    assert not hand._fold_first
    assert load_hand("sah")._fold_first
    rng = np.random.default_rng(31)
    q = hand.random_configuration(rng)
    stack, J = hand.contact_stack_jacobian(q)
    np.testing.assert_allclose(J.reshape(-1, 2, 3, hand.nv)[:, 0], hand.contact_jacobians(q).points)
    index_j3 = np.eye(hand.nv)[6 + hand.coordinate_index("index_j3")]
    eps = 1e-7
    for v in (rng.normal(size=hand.nv), index_j3):
        fd = (hand.contact_stack(hand.integrate(q, eps * v)) - stack) / eps
        np.testing.assert_allclose(fd, J @ v, atol=1e-5)
    # The index's j3 moves the middle's contact point, through the mimic joint only.
    middle = 6 * hand.fingers.index("middle")
    assert np.abs(J[middle : middle + 3] @ index_j3).max() > 1e-3


def test_joint_placements_view_follows_pinocchio(any_hand: Hand) -> None:
    # The single view of data.oMi and the per-joint views it stands for hold the same values,
    # those of the latest query, and the contact frames agree with them.
    rng = np.random.default_rng(33)
    for _ in range(2):
        q = any_hand.random_configuration(rng)
        state = any_hand.contact_state(q)
        flat = any_hand._joint_vector()
        assert flat.base is not None  # the single view of data.oMi: no copy per query
        np.testing.assert_array_equal(flat, hand_module._flattened(any_hand._placement_parts))
        for i, finger in enumerate(any_hand.fingers):
            placement = any_hand.contact_placement(q, finger)
            np.testing.assert_allclose(state.points[i], placement.translation, atol=1e-15)
            np.testing.assert_allclose(state.normals[i], placement.rotation[:, 0], atol=1e-15)
