"""JSON Lines targets and results files (sahgrasp.stream), without solving."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sahgrasp.contacts import GraspTarget, InvalidProblem
from sahgrasp.errors import InvalidSettingsError, InvalidTargetError
from sahgrasp.hand import load_hand
from sahgrasp.ik import IKSettings, default_sequence, random_problem
from sahgrasp.stream import MAX_LINE_BYTES, ResultsWriter, open_targets, settings_header

GOOD = random_problem(load_hand("sah"), 5151, 0).to_dict()


def _write(path: Path, lines: list[bytes]) -> Path:
    path.write_bytes(b"\n".join(lines) + b"\n")
    return path


def test_lines_are_problems_and_bad_lines_are_invalid_in_place(tmp_path: Path) -> None:
    lines = [
        json.dumps({"hand": "allegro"}).encode(),
        json.dumps(GOOD).encode(),
        b"",
        b"\xff\xfe not utf-8",
        b"[1, 2",
        b"x" * (MAX_LINE_BYTES + 10),
        json.dumps({"contacts": GOOD["contacts"]}).encode(),
    ]
    targets = open_targets(_write(tmp_path / "t.jsonl", lines))
    assert (targets.hand, targets.total) == ("allegro", 6)
    problems = list(targets.problems)
    assert isinstance(problems[0], GraspTarget) and problems[0].name == GOOD["name"]
    details = [p.detail for p in problems[1:5] if isinstance(p, InvalidProblem)]
    assert len(details) == 4
    assert "not a JSON value" in details[0] and "not UTF-8" in details[1]
    assert "not a JSON value" in details[2] and "longer than" in details[3]
    assert problems[5].name == "problem-5"


def test_a_header_with_unknown_keys_is_refused(tmp_path: Path) -> None:
    path = _write(tmp_path / "t.jsonl", [b'{"hand": "sah", "seed": 3}'])
    with pytest.raises(InvalidTargetError, match=r"unknown key\(s\) \['seed'\]"):
        open_targets(path)


def _header(seed: int = 0) -> dict[str, object]:
    hand = load_hand("sah")
    return settings_header(hand, IKSettings(seed=seed), default_sequence(hand).to_dict(), "t")


def test_a_resumed_file_keeps_its_complete_lines_only(tmp_path: Path) -> None:
    out = tmp_path / "r.jsonl"
    writer = ResultsWriter(out, _header(), resume=False)
    writer.write([{"name": "a"}, {"name": "b"}])
    writer.close(complete=False)
    part = tmp_path / "r.jsonl.part"
    assert not out.exists() and part.read_text().count("\n") == 3
    with part.open("ab") as stream:
        stream.write(b'{"name": "c", "succ')
    again = ResultsWriter(out, _header(), resume=True)
    assert [e["name"] for e in again.finished()] == ["a", "b"]
    again.write([{"name": "c"}])
    again.close(complete=True)
    assert not part.exists()
    assert [json.loads(line).get("name") for line in out.read_text().splitlines()[1:]] == list(
        "abc"
    )


def test_resume_refuses_other_settings_and_other_files(tmp_path: Path) -> None:
    out = tmp_path / "r.jsonl"
    writer = ResultsWriter(out, _header(seed=1), resume=False)
    writer.close(complete=True)
    with pytest.raises(InvalidSettingsError, match="other settings"):
        ResultsWriter(out, _header(seed=2), resume=True)
    assert out.exists()
    out.write_text('{"name": "not a header"}\n')
    with pytest.raises(InvalidSettingsError, match="not a JSON Lines results file"):
        ResultsWriter(out, _header(), resume=True)
