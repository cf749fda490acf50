"""Fuzzing the targets input: random JSON documents and random edits of a valid targets file.

Whatever the input, ``load_targets``/``read_problems`` return or raise ``InvalidTargetError``, and
``sahgrasp solve`` exits 0, 1 or 2 with no traceback and, unless it refused the whole file,
writes strict JSON with one result per problem. Timeouts catch hangs.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sahgrasp.core.errors import InvalidTargetError
from sahgrasp.ik import random_problems
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import load_hand
from sahgrasp.objects.targets import InvalidProblem, load_targets, read_problems, save_targets

ROOT = Path(__file__).resolve().parent.parent
KEYS = ("hand", "problems", "name", "contacts", "finger", "point", "normal", "thumb", "index",
        "object", "mesh", "scale", "xyz", "quat", "can", "t.json", "..", "/")  # fmt: skip

leaves = (
    st.none()
    | st.booleans()
    | st.floats()
    | st.integers(min_value=-(10**400), max_value=10**400)
    | st.text(max_size=12)
    | st.sampled_from(KEYS)
)
json_values = st.recursive(
    leaves,
    lambda children: (
        st.lists(children, max_size=4)
        | st.dictionaries(st.sampled_from(KEYS) | st.text(max_size=6), children, max_size=4)
    ),
    max_leaves=12,
)


@pytest.fixture(scope="module")
def valid() -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "t.json"
        save_targets(path, "sah", random_problems(load_hand("sah"), 2, 0))
        document: dict[str, Any] = json.loads(path.read_text())
    return document


def _paths(value: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every place in a JSON value, the root included."""
    found = [prefix]
    if isinstance(value, dict):
        for key, item in value.items():
            found += _paths(item, (*prefix, key))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            found += _paths(item, (*prefix, index))
    return found


def _mutate(document: Any, data: st.DataObject) -> Any:
    """``document`` with one random place replaced, deleted or doubled."""
    document = json.loads(json.dumps(document))
    path = data.draw(st.sampled_from(_paths(document)))
    if not path:
        return data.draw(json_values)
    parent = document
    for key in path[:-1]:
        parent = parent[key]
    action = data.draw(st.sampled_from(["replace", "delete", "double"]))
    if action == "replace":
        parent[path[-1]] = data.draw(json_values)
    elif action == "delete":
        del parent[path[-1]]
    elif isinstance(parent, list):
        parent.insert(path[-1], parent[path[-1]])
    else:
        parent[path[-1]] = [parent[path[-1]]] * 2
    return document


def _check_loaders(path: Path) -> None:
    try:
        hand, problems = read_problems(path)
    except InvalidTargetError:
        return
    assert isinstance(hand, str)
    for problem in problems:
        assert isinstance(problem, GraspTarget | InvalidProblem)
        problem.name.encode("utf-8")  # no lone surrogate left
    try:
        load_targets(path)
    except InvalidTargetError:
        assert any(isinstance(p, InvalidProblem) for p in problems)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(document=json_values)
def test_random_json_documents(document: Any) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "t.json"
        path.write_text(json.dumps(document))
        _check_loaders(path)


@settings(
    max_examples=100,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(data=st.data())
def test_random_edits_of_a_valid_file(valid: dict[str, Any], data: st.DataObject) -> None:
    document = valid
    for _ in range(data.draw(st.integers(1, 3))):
        document = _mutate(document, data)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "t.json"
        path.write_text(json.dumps(document))
        _check_loaders(path)


@settings(max_examples=100, deadline=None)
@given(payload=st.binary(max_size=200))
def test_random_bytes(payload: bytes) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "t.json"
        path.write_bytes(payload)
        _check_loaders(path)


@pytest.mark.slow
@settings(
    max_examples=6,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(data=st.data())
def test_solve_on_random_edits(valid: dict[str, Any], data: st.DataObject) -> None:
    document = _mutate(valid, data)
    with tempfile.TemporaryDirectory() as folder:
        (Path(folder) / "t.json").write_text(json.dumps(document))
        done = subprocess.run(
            [sys.executable, "-m", "sahgrasp", "solve", "t.json", "--inits", "1",
             "--json", "out.json"],
            capture_output=True, encoding="utf-8", errors="strict", cwd=folder, timeout=120,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
        )  # fmt: skip
        assert "Traceback" not in done.stderr, done.stderr
        assert done.returncode in (0, 1, 2), done.stderr
        if done.returncode == 2:
            assert done.stderr.startswith("sahgrasp: error: ")
            return
        text = (Path(folder) / "out.json").read_text(encoding="utf-8")
        results = json.loads(text, parse_constant=pytest.fail)["results"]
        assert len(results) == len(read_problems(Path(folder) / "t.json")[1])
