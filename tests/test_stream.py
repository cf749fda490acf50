"""JSON Lines targets and results files (sahgrasp.ik.stream), without solving."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sahgrasp.core.errors import InvalidSettingsError, InvalidTargetError
from sahgrasp.ik import IKSettings, default_sequence, random_problem
from sahgrasp.ik.stream import MAX_LINE_BYTES, ResultsWriter, open_targets, settings_header
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import load_hand
from sahgrasp.objects.targets import InvalidProblem, problem_from_dict

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


def test_a_fifo_loses_no_problem(tmp_path: Path) -> None:
    """A pipe is read once: no counting pass drains it, the total is unknown (None)."""
    import os
    import threading

    fifo = tmp_path / "t.jsonl"
    os.mkfifo(fifo)
    lines = [json.dumps({**GOOD, "name": f"p{i}"}).encode() for i in range(5)]

    def feed() -> None:
        with fifo.open("wb") as stream:
            stream.write(b"\n".join(lines) + b"\n")

    writer = threading.Thread(target=feed)
    writer.start()
    targets = open_targets(fifo)
    names = [p.name for p in targets.problems]
    writer.join()
    assert targets.total is None
    assert names == [f"p{i}" for i in range(5)]


def test_a_byte_order_mark_before_the_first_line_is_accepted(tmp_path: Path) -> None:
    bom = b"\xef\xbb\xbf"
    lines = [bom + b'{"hand": "allegro"}', json.dumps(GOOD).encode()]
    with_header = _write(tmp_path / "h.jsonl", lines)
    targets = open_targets(with_header)
    assert targets.hand == "allegro"
    assert [type(p) for p in targets.problems] == [GraspTarget]
    plain = _write(tmp_path / "p.jsonl", [bom + json.dumps(GOOD).encode()])
    assert [type(p) for p in open_targets(plain).problems] == [GraspTarget]


def test_a_second_writer_of_the_same_output_is_refused(tmp_path: Path) -> None:
    from sahgrasp.core.fileio import OutputLockedError

    out = tmp_path / "r.jsonl"
    first = ResultsWriter(out, _header(), resume=False)
    first.write([{"name": "a"}])
    with pytest.raises(OutputLockedError, match="being written by another sahgrasp run"):
        ResultsWriter(out, _header(), resume=False)
    with pytest.raises(OutputLockedError):
        ResultsWriter(out, _header(), resume=True)
    first.write([{"name": "b"}])
    first.close(complete=True)
    names = [json.loads(line).get("name") for line in out.read_text().splitlines()[1:]]
    assert names == ["a", "b"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.jsonl"]


def test_a_refused_resume_leaves_the_finished_output_in_place(tmp_path: Path) -> None:
    out = tmp_path / "r.jsonl"
    writer = ResultsWriter(out, _header(seed=1), resume=False)
    writer.write([{"name": "a"}])
    writer.close(complete=True)
    before = out.read_bytes()
    with pytest.raises(InvalidSettingsError, match="other settings"):
        ResultsWriter(out, _header(seed=2), resume=True)
    again = ResultsWriter(out, _header(seed=1), resume=True)
    next(again.finished())
    again.close(complete=False)  # refused by its caller after reading: nothing may move
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.jsonl"]


def test_resume_keeps_the_results_of_unchanged_problems_only(tmp_path: Path) -> None:
    from sahgrasp.ik.stream import problem_digest

    problems = [problem_from_dict({**GOOD, "name": n}) for n in "abc"]
    digests = [problem_digest(p) for p in problems]
    assert len(set(digests)) == 3
    out = tmp_path / "r.jsonl"
    writer = ResultsWriter(out, _header(), resume=False)
    pairs = zip(problems, digests, strict=True)
    entries = [{"name": p.name, "problem_digest": d} for p, d in pairs]
    writer.write(entries)
    writer.close(complete=False)
    moved = {**GOOD, "name": "b"}
    moved["contacts"] = [{**c, "point": [x + 0.001 for x in c["point"]]} for c in GOOD["contacts"]]
    changed = problem_from_dict(moved)
    assert problem_digest(changed) != digests[1]  # same name, other contacts
    again = ResultsWriter(out, _header(), resume=True)
    kept = []
    for entry, digest in zip(again.finished(), [digests[0], problem_digest(changed)], strict=False):
        if entry["problem_digest"] != digest:
            break
        kept.append(entry["name"])
    assert kept == ["a"]
    again.write([{"name": "b", "problem_digest": problem_digest(changed)}])
    again.close(complete=True)
    lines = [json.loads(line) for line in out.read_text().splitlines()[1:]]
    assert [e["name"] for e in lines] == ["a", "b"]
    assert lines[1]["problem_digest"] == problem_digest(changed)
