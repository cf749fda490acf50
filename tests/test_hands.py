"""The registry of hands: a hand is a plug-in, generic code names none.

A test hand, ``tripod`` (the SAH's thumb, index and middle finger: a three-finger hand with its
own description), is registered the way docs/how-to/add-a-hand.md says, in one place, and then
works with
``load_hand``, the command line's ``--hand`` (as an installed plug-in), the planner and the IK.
"""

from __future__ import annotations

import ast
import dataclasses
import functools
import json
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from sahgrasp.core.errors import HandModelError
from sahgrasp.ik import solve_ik
from sahgrasp.ik.initial import default_sequence
from sahgrasp.ik.learned import default_database
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import BUILTIN_HANDS, Hand, HandDescription, load_hand, sah_description
from sahgrasp.model.hands import (
    DEFAULT_HAND,
    HANDS,
    HandEntry,
    SamplerReach,
    hand_entry,
    register_hand,
)
from sahgrasp.objects import load_object
from sahgrasp.objects.reach import hand_reach, sampler_reach
from sahgrasp.planner import PlanSettings, plan_grasps

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "sahgrasp"

# The modules allowed to name a hand: the registry, and the hands' own descriptions.
REGISTRY = PACKAGE / "model" / "hands.py"
DESCRIPTIONS = {PACKAGE / "model" / "hand.py": {"sah_description", "allegro_description"}}


def tripod_description() -> HandDescription:
    """A three-finger hand: the SAH's URDF with the thumb, index and middle as its fingers."""
    sah = sah_description()
    return dataclasses.replace(sah, name="tripod", fingers=sah.fingers[:3])


TRIPOD = HandEntry(name="tripod", description=tripod_description)


@pytest.fixture
def tripod() -> Iterator[HandEntry]:
    entry = register_hand(TRIPOD)
    yield entry
    HANDS.unregister("tripod")


def _docstrings(tree: ast.AST) -> set[int]:
    """ids of the docstring constants of a module, its classes and functions, and attributes."""
    found: set[int] = set()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if not isinstance(body, list):
            continue
        for k, statement in enumerate(body):
            is_doc = isinstance(statement, ast.Expr) and isinstance(statement.value, ast.Constant)
            # The first statement, or the string after an assignment (an attribute docstring).
            if is_doc and (k == 0 or isinstance(body[k - 1], ast.Assign | ast.AnnAssign)):
                found.add(id(statement.value))
    return found


def _allowed_nodes(path: Path, tree: ast.AST) -> set[int]:
    allowed: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef) and node.name in DESCRIPTIONS.get(path, ()):
            allowed |= {id(n) for n in ast.walk(node)}
    return allowed


def hand_literals(names: tuple[str, ...]) -> list[str]:
    """Every string literal in sahgrasp/ that names one of ``names`` as a word, outside docstrings,
    the registry and the hands' own description functions."""
    pattern = re.compile(r"\b(" + "|".join(map(re.escape, names)) + r")\b")
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path == REGISTRY:
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        skip = _docstrings(tree) | _allowed_nodes(path, tree)
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Constant)
                and isinstance(node.value, str)
                and id(node) not in skip
                and pattern.search(node.value)
            ):
                found.append(f"{path.relative_to(ROOT)}:{node.lineno}: {node.value[:60]!r}")
    return found


def test_generic_code_names_no_hand() -> None:
    assert hand_literals(("sah", "allegro")) == []


def test_the_name_check_finds_a_planted_literal(tmp_path: Path) -> None:
    tree = ast.parse('"""The sah hand."""\nHAND = "sah"\n')
    literals = [n for n in ast.walk(tree) if isinstance(n, ast.Constant)]
    assert [n.value for n in literals if id(n) not in _docstrings(tree)] == ["sah"]


def test_built_in_hands_are_registered_with_their_data() -> None:
    assert tuple(BUILTIN_HANDS) == tuple(HANDS)
    assert next(iter(HANDS)) == DEFAULT_HAND
    for name, entry in HANDS.items():
        assert entry.name == name
        assert entry.build().name == name
        hand = load_hand(name)
        # The shipped sequence and database are the ones the entry names, made for this hand.
        assert default_sequence(hand).hand_digest == hand.description.digest()
        assert entry.database is not None and default_database(hand) is not None


def test_load_hand_lists_the_registered_names() -> None:
    with pytest.raises(HandModelError, match="unknown hand 'nohand'.*" + ".*".join(HANDS)):
        load_hand("nohand")


def test_a_registration_is_checked(tripod: HandEntry) -> None:
    with pytest.raises(HandModelError, match="already registered"):
        register_hand(TRIPOD)
    with pytest.raises(HandModelError, match="HandEntry"):
        register_hand("tripod")  # type: ignore[arg-type]
    other = register_hand(HandEntry("other", tripod_description))
    try:
        with pytest.raises(HandModelError, match="named 'tripod'; the names must agree"):
            load_hand("other")
    finally:
        HANDS.unregister(other.name)
    broken = register_hand(HandEntry("broken", "sahgrasp.model.hand:no_such_function"))
    try:
        with pytest.raises(HandModelError, match="not importable"):
            load_hand("broken")
    finally:
        HANDS.unregister(broken.name)


def test_each_hand_keeps_its_own_cache() -> None:
    first, second = load_hand(DEFAULT_HAND), load_hand(DEFAULT_HAND)
    assert default_sequence(first) is default_sequence(first)
    assert "default_sequence" in first.cache and "default_sequence" not in second.cache
    built: list[int] = []

    def build(k: int) -> int:
        built.append(k)
        return k

    for k in range(10):
        first.cache.kept("things", k, functools.partial(build, k), 8)
    assert first.cache.kept("things", 9, lambda: -1, 8) == 9  # kept: not rebuilt
    assert first.cache.kept("things", 0, lambda: -1, 8) == -1  # the oldest was dropped
    assert built == list(range(10))


def test_a_test_hand_loads_and_gets_a_derived_reach(tripod: HandEntry) -> None:
    assert "tripod" in BUILTIN_HANDS and hand_entry("tripod") is tripod
    hand = load_hand("tripod")
    assert isinstance(hand, Hand) and hand.fingers == ("thumb", "index", "middle")
    # No shipped data: the paper's lambdas on its own motions, no database.
    assert default_sequence(hand).source == "paper-table1"
    assert default_database(hand) is None
    # No measured reach: the samplers derive it from the model.
    assert sampler_reach(hand) is hand_reach(hand)
    measured = sampler_reach(load_hand(DEFAULT_HAND))
    reach = HANDS[DEFAULT_HAND].reach
    assert isinstance(reach, SamplerReach) and measured.span_m == reach.span_m


@pytest.mark.slow
def test_a_test_hand_plans_and_solves(tripod: HandEntry) -> None:
    hand = load_hand("tripod")
    can = load_object("can")
    settings = PlanSettings(fingers=(3, 2), grasps=2, candidates=8, seed=1)
    plan = plan_grasps(hand, can, settings)
    assert plan.hand == "tripod" and plan.grasps
    best = plan.grasps[0]
    assert best.quality["force_closure"]
    # The planned contacts, solved again with the IK from its own start.
    result = solve_ik(hand, GraspTarget("again", best.contacts), obstacle=can)
    assert result.success
    assert result.position_errors_m.max() < 1e-3


def test_a_hand_plug_in_works_on_the_command_line(tmp_path: Path) -> None:
    # An installed package that declares the hand in the entry-point group sahgrasp.hands.
    (tmp_path / "tripod_hand.py").write_text(
        "import dataclasses\n"
        "from sahgrasp.model.hand import sah_description\n"
        "from sahgrasp.model.hands import HandEntry\n\n"
        "def tripod():\n"
        "    d = sah_description()\n"
        "    return dataclasses.replace(d, name='tripod', fingers=d.fingers[:3])\n\n"
        "ENTRY = HandEntry('tripod', tripod)\n",
        encoding="utf-8",
    )
    info = tmp_path / "tripod_hand-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: tripod-hand\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[sahgrasp.hands]\ntripod = tripod_hand:ENTRY\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(tmp_path)])}
    done = subprocess.run(
        [sys.executable, "-m", "sahgrasp", "info", "--hand", "tripod"],
        capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("hand tripod")
    assert "fingers: thumb (thumb_tip), index (index_tip), middle (middle_tip)" in done.stdout
    targets = tmp_path / "t.json"
    contact = {"finger": "thumb", "point": [0, 0, 0], "normal": [1, 0, 0]}
    targets.write_text(json.dumps({"hand": "tripod", "problems": [{"contacts": [contact]}]}))
    done = subprocess.run(
        [sys.executable, "-m", "sahgrasp", "solve", str(targets)],
        capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120,
    )  # fmt: skip
    # The tripod's targets file: its one-contact problem is refused naming the tripod's fingers.
    assert done.returncode == 1, done.stderr
    assert "at least two of ['thumb', 'index', 'middle']" in done.stdout


def test_a_broken_plug_in_is_named_only_when_asked_for(monkeypatch: pytest.MonkeyPatch) -> None:
    import importlib.metadata

    import sahgrasp.model.hands as hands

    points = [
        importlib.metadata.EntryPoint("nowhere", "no_such_module:ENTRY", hands.ENTRY_POINT_GROUP),
        importlib.metadata.EntryPoint("notentry", "os:sep", hands.ENTRY_POINT_GROUP),
    ]
    monkeypatch.setattr(importlib.metadata, "entry_points", lambda group: points)
    monkeypatch.setattr(hands, "_discovered", False)
    monkeypatch.setattr(hands, "_broken", {})
    assert hand_entry("unrelated") is None
    with pytest.raises(HandModelError, match=r"'nowhere'.*does not load: ModuleNotFoundError"):
        load_hand("nowhere")
    with pytest.raises(HandModelError, match=r"'notentry'.*not a HandEntry named 'notentry'"):
        load_hand("notentry")
