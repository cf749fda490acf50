"""The offline search for the initial-pose sequence: determinism, resumption, refusals."""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sahgrasp.cli import sequence as sequence_cli
from sahgrasp.core.errors import InvalidSettingsError, SequenceFileError
from sahgrasp.core.fileio import write_bytes_atomic
from sahgrasp.ik import IKSettings, Sequence, pose_basis
from sahgrasp.model.hand import Hand, load_hand
from sahgrasp.sequence import (
    Chunk,
    Progress,
    SearchResult,
    SearchSettings,
    search_sequence,
    solve_chunk,
)
from sahgrasp.sequence.folder import LOCK_NAME, locked_folder

ROOT = Path(__file__).resolve().parents[1]

SMALL = SearchSettings(grid=3, problems=20, rounds=2, seed=3, ik=IKSettings(max_iterations=30))
CELLS = SMALL.cells * SMALL.rounds


class InterruptError(Exception):
    """Raised from the progress callback to kill a search in the middle of a round."""


def _signature(result: SearchResult) -> list[Any]:
    """Everything that must not depend on the executor: lambdas, problems, E maps."""
    return [(r.lambdas, r.problem_indices, r.scanned, r.solved.tolist()) for r in result.rounds]


def _assert_clean(out: Path) -> None:
    """Every file is complete: JSON parses, the PNG is whole, no temporary file is left."""
    files = [p for p in out.rglob("*") if p.is_file()]
    assert not [p for p in files if p.name.endswith(".tmp")]
    for path in files:
        if path.suffix == ".json":
            json.loads(path.read_text())
        if path.suffix == ".png":
            assert path.read_bytes().endswith(b"IEND\xaeB`\x82")


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> tuple[SearchResult, Path]:
    out = tmp_path_factory.mktemp("reference")
    return search_sequence("sah", SMALL, out, workers=1), out


def test_reference_run_outputs(reference: tuple[SearchResult, Path], sah: Hand) -> None:
    result, out = reference
    assert result.cells_computed == CELLS
    assert {p.name for p in out.iterdir()} == {
        "checkpoint", "sequence.json", "search.json", "fig4.png", LOCK_NAME,
    }  # fmt: skip
    _assert_clean(out)
    seq = Sequence.load(out / "sequence.json")
    seq.check_hand(sah)
    assert seq.source == "search"
    assert seq.lambdas == tuple(r.lambdas for r in result.rounds)
    assert seq.meta is not None
    assert (seq.meta["grid"], seq.meta["problems"], seq.meta["rounds"]) == (3, 20, 2)
    assert (seq.meta["seed"], seq.meta["method"]) == (3, "auto")
    report = json.loads((out / "search.json").read_text())
    assert len(report["rounds"]) == 2
    assert np.array(report["rounds"][0]["solved"]).shape == (3, 3)
    for r in result.rounds:
        values = SMALL.lambda_values()
        j, k = r.cell
        assert r.lambdas == (values[j], values[k])
        assert r.solved[j, k] == r.solved.max()
        assert len(r.problem_indices) == SMALL.problems
    # Round 2's problems are not solved by lambda_1, so lambda_1's cell solves none of them.
    first, second = result.rounds
    assert second.solved[first.cell] == 0
    assert first.problem_indices == tuple(range(20))
    assert second.problem_indices[0] > first.problem_indices[-1]


@pytest.mark.slow
def test_two_local_workers_give_the_same_sequence(
    reference: tuple[SearchResult, Path], tmp_path: Path
) -> None:
    result = search_sequence("sah", SMALL, tmp_path, workers=2, chunk_size=7)
    assert _signature(result) == _signature(reference[0])
    assert (tmp_path / "sequence.json").read_bytes() == (
        reference[1] / "sequence.json"
    ).read_bytes()


@pytest.mark.slow
def test_dask_cluster_gives_the_same_sequence_despite_a_dead_worker(
    reference: tuple[SearchResult, Path], tmp_path: Path
) -> None:
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    )
    with cluster, distributed.Client(cluster) as client:
        killed: list[int] = []

        def kill_one_worker(p: Progress) -> None:
            if not killed and p.stage == "cells" and p.cells_done >= 2:
                victim = sorted(client.run(os.getpid).values())[0]
                os.kill(victim, signal.SIGKILL)
                killed.append(victim)

        # Round 1 through a scheduler address (the search opens its own client, as the CLI
        # does), round 2 through the caller's client, with a worker killed in the middle.
        address = cluster.scheduler_address
        search_sequence("sah", replace(SMALL, rounds=1), tmp_path, executor=address)
        result = search_sequence(
            "sah", SMALL, tmp_path, executor=client, resume=True, progress=kill_one_worker
        )
    assert killed
    assert result.cells_computed == SMALL.cells
    assert _signature(result) == _signature(reference[0])


@pytest.mark.slow
def test_resume_after_the_first_round(reference: tuple[SearchResult, Path], tmp_path: Path) -> None:
    with ThreadPoolExecutor(2) as pool:
        first = search_sequence("sah", replace(SMALL, rounds=1), tmp_path, executor=pool)
        assert first.cells_computed == SMALL.cells
        _assert_clean(tmp_path)
        resumed = search_sequence("sah", SMALL, tmp_path, executor=pool, resume=True)
    assert resumed.cells_computed == SMALL.cells  # round 1 is read back, not recomputed
    assert _signature(resumed) == _signature(reference[0])


@pytest.mark.slow
def test_resume_after_a_kill_in_the_middle_of_a_round(
    reference: tuple[SearchResult, Path], tmp_path: Path
) -> None:
    def die(p: Progress) -> None:
        if p.round == 2 and p.cells_done == 4:
            raise InterruptError

    with ThreadPoolExecutor(2) as pool:
        with pytest.raises(InterruptError):
            search_sequence("sah", SMALL, tmp_path, executor=pool, progress=die)
        _assert_clean(tmp_path)
        assert not (tmp_path / "sequence.json").exists()
        saved = json.loads((tmp_path / "checkpoint" / "round-002.json").read_text())
        assert len(saved["cells"]) == 4
        killed_write = tmp_path / "checkpoint" / ".round-002.json.999-0123abcd.sahgrasp.tmp"
        killed_write.write_text('{"half": ')
        resumed = search_sequence("sah", SMALL, tmp_path, executor=pool, resume=True)
    assert resumed.cells_computed == SMALL.cells - 4
    assert _signature(resumed) == _signature(reference[0])
    _assert_clean(tmp_path)


def test_resume_does_no_work_when_finished(
    reference: tuple[SearchResult, Path], tmp_path: Path
) -> None:
    shutil.copytree(reference[1], tmp_path, dirs_exist_ok=True)
    with ThreadPoolExecutor(1) as pool:
        again = search_sequence("sah", SMALL, tmp_path, executor=pool, resume=True)
    assert (again.cells_computed, again.ik_runs_computed) == (0, 0)
    assert _signature(again) == _signature(reference[0])


@pytest.fixture
def finished(reference: tuple[SearchResult, Path], tmp_path: Path) -> Path:
    shutil.copytree(reference[1], tmp_path, dirs_exist_ok=True)
    return tmp_path


def _resume(out: Path, settings: SearchSettings = SMALL, hand: str = "sah") -> SearchResult:
    with ThreadPoolExecutor(1) as pool:
        return search_sequence(hand, settings, out, executor=pool, resume=True)


def test_existing_search_is_not_overwritten(finished: Path) -> None:
    with pytest.raises(SequenceFileError, match="already holds a search"):
        search_sequence("sah", SMALL, finished, workers=1)


@pytest.mark.parametrize(
    ("hand", "settings", "message"),
    [
        ("allegro", SMALL, "hand_digest"),
        ("sah", replace(SMALL, seed=4), "seed"),
        ("sah", replace(SMALL, ik=IKSettings(method="paper", max_iterations=30)), "paper"),
    ],
)
def test_foreign_checkpoint_is_refused(
    finished: Path, hand: str, settings: SearchSettings, message: str
) -> None:
    with pytest.raises(SequenceFileError, match=message):
        _resume(finished, settings, hand)


def _break_header(folder: Path) -> None:
    path = folder / "header.json"
    path.write_text(path.read_text()[:100])


def _break_basis(folder: Path) -> None:
    path = folder / "header.json"
    data = json.loads(path.read_text())
    data["basis"]["directions"] = [[1.0]]
    path.write_text(json.dumps(data))


def _break_cells(folder: Path) -> None:
    path = folder / "round-001.json"
    data = json.loads(path.read_text())
    data["cells"]["0"] = [SMALL.problems + 1, 0.1]  # more solved than problems
    path.write_text(json.dumps(data))


def _break_order(folder: Path) -> None:
    path = folder / "round-002.json"
    data = json.loads(path.read_text())
    data["problems"] = data["problems"][::-1]
    path.write_text(json.dumps(data))


def _drop_round(folder: Path) -> None:
    (folder / "round-001.json").unlink()


def _foreign_round(folder: Path) -> None:
    path = folder / "round-002.json"
    data = json.loads(path.read_text())
    data["key"] = "0" * 64
    path.write_text(json.dumps(data))


@pytest.mark.parametrize(
    "damage", [_break_header, _break_basis, _break_cells, _break_order, _drop_round, _foreign_round]
)
def test_corrupted_checkpoint_is_refused(finished: Path, damage: Any) -> None:
    damage(finished / "checkpoint")
    with pytest.raises(SequenceFileError, match=r"checkpoint file .* is unusable"):
        _resume(finished)


def _edit(path: Path, change: Any) -> None:
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))  # json.dumps writes NaN as NaN, as a careless tool would


def _set(*keys: str, value: Any) -> Any:
    def change(data: Any) -> None:
        for key in keys[:-1]:
            data = data[key]
        data[keys[-1]] = value

    return change


@pytest.mark.parametrize(
    ("change", "field"),
    [
        (_set("basis", "mean", 0, value=float("nan")), "NaN"),
        (_set("basis", "sigmas", 1, value=float("inf")), "Infinity"),
        (lambda d: d["basis"]["mean"].pop(), "basis.mean"),
        (lambda d: [row.pop() for row in d["basis"]["directions"]], "basis.directions"),
        (_set("basis", "directions", 0, 0, value=2.0), "basis.directions"),
        (_set("basis", "sigmas", value=["1", 2]), "basis.sigmas"),
        (_set("basis", "sigmas", value=[1.0, 0.0]), "basis.sigmas"),
        (_set("basis", "sigmas", value=[True, 1.0]), "basis.sigmas"),
        (_set("basis", "sigmas", 0, value=10**400), "basis.sigmas"),
        (_set("basis", "mean", value=[[1.0], [1.0, 2.0]]), "basis.mean"),
        (_set("basis", value=[1.0]), "basis"),
        (lambda d: d.pop("basis"), "basis"),
        (_set("key", value="0" * 64), "key"),
        (_set("format", value="sahgrasp-search-checkpoint-0"), "format"),
    ],
)
def test_header_with_a_bad_field_is_refused(finished: Path, change: Any, field: str) -> None:
    header = finished / "checkpoint" / "header.json"
    _edit(header, change)
    with pytest.raises(
        SequenceFileError, match=rf"{re.escape(str(header))} is unusable \(.*{field}"
    ):
        _resume(finished)


@pytest.mark.parametrize(
    "content",
    [b"", b"\xff\xfe{\x00}", b"[" * 100_000, b"[1, 2]", b'{"format": "sahgrasp-search-chec'],
    ids=["empty", "utf16", "deep", "array", "truncated"],
)
def test_unreadable_header_is_refused(finished: Path, content: bytes) -> None:
    header = finished / "checkpoint" / "header.json"
    header.write_bytes(content)
    with pytest.raises(SequenceFileError, match=rf"{re.escape(str(header))} is unusable"):
        _resume(finished)


@pytest.mark.parametrize(
    ("change", "field"),
    [
        (_set("cells", "0", value="x"), "cells.0"),
        (_set("cells", "0", value=[3, float("nan")]), "NaN"),
        (_set("cells", "0", value=[3, True]), "cells.0"),
        (_set("cells", "0", value=[3, 10**400]), "cells.0"),
        (_set("cells", "0", value=[-1, 0.1]), "cells.0"),
        (lambda d: d["cells"].update({"00": d["cells"]["0"]}), "cells.00"),
        (_set("cells", value=[]), "cells"),
        (_set("problems", value="0-19"), "problems"),
        (_set("problems", 0, value=1.5), "problems"),
        (_set("screen_seconds", value="1"), "screen_seconds"),
        (lambda d: d.pop("scanned"), "scanned"),
        (_set("start", value=5), "problems"),
        (_set("round", value=2), "round"),
    ],
)
def test_round_file_with_a_bad_field_is_refused(finished: Path, change: Any, field: str) -> None:
    path = finished / "checkpoint" / "round-001.json"
    _edit(path, change)
    with pytest.raises(SequenceFileError, match=rf"{re.escape(str(path))} is unusable \(.*{field}"):
        _resume(finished)


def test_truncated_or_misnamed_round_file_is_refused(finished: Path) -> None:
    folder = finished / "checkpoint"
    text = (folder / "round-002.json").read_text()
    (folder / "round-002.json").write_text(text[: len(text) // 2])
    with pytest.raises(SequenceFileError, match=r"round-002\.json is unusable"):
        _resume(finished)
    (folder / "round-002.json").write_text(text)
    shutil.copy(folder / "round-002.json", folder / "round-003.json")  # round 2 again, as round 3
    with pytest.raises(SequenceFileError, match=r"round-003\.json is unusable .*field 'round'"):
        _resume(finished)
    (folder / "round-003.json").unlink()
    os.mkfifo(folder / "round-003.json")  # reading it would block
    with pytest.raises(SequenceFileError, match=r"round-003\.json is unusable .*regular file"):
        _resume(finished)


def _contents(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


@pytest.mark.parametrize("resume", [True, False])
def test_rounds_without_their_header_are_kept_and_refused(finished: Path, resume: bool) -> None:
    (finished / "checkpoint" / "header.json").unlink()
    before = _contents(finished)
    with (
        ThreadPoolExecutor(1) as pool,
        pytest.raises(
            SequenceFileError,
            match=r"round-001\.json, round-002\.json.* no checkpoint/header\.json",
        ),
    ):
        search_sequence("sah", SMALL, finished, executor=pool, resume=resume)
    assert _contents(finished) == before


def test_results_without_a_checkpoint_are_not_overwritten(finished: Path) -> None:
    shutil.rmtree(finished / "checkpoint")
    before = _contents(finished)
    with pytest.raises(SequenceFileError, match=r"sequence\.json, search\.json, fig4\.png"):
        _resume(finished)
    assert _contents(finished) == before


def test_resume_removes_its_own_stale_temporaries_and_nothing_else(finished: Path) -> None:
    ours = [
        finished / ".sequence.json.4242-0123abcd.sahgrasp.tmp",
        finished / "checkpoint" / ".round-002.json.7-ffffffff.sahgrasp.tmp",
    ]
    theirs = [
        finished / "checkpoint" / ".something.tmp",
        finished / "checkpoint" / ".round-002.json.999.tmp",
        finished / ".notes.1-0123abcd.tmp",
        finished / "my.sahgrasp.tmp",
        finished / ".x.1-0123ABCD.sahgrasp.tmp",
    ]
    for path in ours + theirs:
        path.write_text("{")
    (finished / ".dir.1-0123abcd.sahgrasp.tmp").mkdir()
    _resume(finished)
    assert not [p for p in ours if p.exists()]
    assert all(p.read_text() == "{" for p in theirs)
    assert (finished / ".dir.1-0123abcd.sahgrasp.tmp").is_dir()


def test_a_failed_write_leaves_the_old_file_and_no_temporary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "round-001.json"
    path.write_text("old")

    def fail(*args: Any) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", fail)
    from sahgrasp.core.fileio import OutputWriteError

    with pytest.raises(OutputWriteError, match=r"cannot write .*round-001\.json: disk full"):
        write_bytes_atomic(path, b"new")
    assert [p.name for p in tmp_path.iterdir()] == ["round-001.json"]
    assert path.read_text() == "old"


def test_a_locked_folder_is_refused_with_the_holder_pid(finished: Path) -> None:
    with locked_folder(finished):
        with pytest.raises(
            SequenceFileError, match=rf"{re.escape(str(finished))} is in use .*pid {os.getpid()}"
        ):
            _resume(finished)
        with pytest.raises(SequenceFileError, match="in use by another search"):
            search_sequence("sah", SMALL, finished, workers=1)  # a new search, same folder
    _resume(finished)  # released at the end of the block


def test_the_lock_of_a_killed_process_is_released(finished: Path) -> None:
    holder = subprocess.Popen(
        [sys.executable, "-c", _HOLD_LOCK, str(finished)],
        stdout=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip
    try:
        assert holder.stdout is not None
        assert holder.stdout.readline().strip() == "locked"
        with pytest.raises(
            SequenceFileError, match=rf"in use by another search \(pid {holder.pid}\)"
        ):
            _resume(finished)
    finally:
        holder.kill()
        holder.wait()
    assert _resume(finished).cells_computed == 0


_HOLD_LOCK = """
import sys, time
from pathlib import Path
from sahgrasp.sequence.folder import locked_folder
with locked_folder(Path(sys.argv[1])):
    print("locked", flush=True)
    time.sleep(600)
"""


@pytest.mark.slow
def test_two_searches_started_together_never_share_a_folder(tmp_path: Path) -> None:
    args = ["sequence", "--grid", "2", "--problems", "4", "--rounds", "1", "--workers", "1",
            "--out", str(tmp_path / "out")]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    pipes = {"stdout": subprocess.PIPE, "stderr": subprocess.PIPE, "text": True}
    runs = [subprocess.Popen([sys.executable, "-c", _CLI, *args], env=env, **pipes) for _ in "ab"]
    outcomes = sorted((run.wait(300), *run.communicate()) for run in runs)
    (ok, ok_out, _), (refused, _, message) = outcomes
    assert (ok, refused) == (0, 2)
    assert "wrote" in ok_out
    refusal = r"is in use by another search \(pid \d+\)|already holds a search"
    assert re.fullmatch(rf"sahgrasp: error: \S*out ({refusal}).*\n", message)
    Sequence.load(tmp_path / "out" / "sequence.json")


_CLI = "import sys; from sahgrasp.cli import main; sys.exit(main())"


def test_an_unusable_folder_is_refused(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("")
    with pytest.raises(SequenceFileError, match=r"cannot use .*file as the search folder"):
        search_sequence("sah", SMALL, tmp_path / "file", workers=1)
    (tmp_path / "dir").mkdir()
    (tmp_path / "dir" / LOCK_NAME).symlink_to(tmp_path / "elsewhere")
    with pytest.raises(SequenceFileError, match=r"cannot use .*dir as the search folder"):
        search_sequence("sah", SMALL, tmp_path / "dir", workers=1)
    assert not (tmp_path / "elsewhere").exists()


def test_corrupted_or_foreign_sequence_is_refused(finished: Path, allegro: Hand) -> None:
    path = finished / "sequence.json"
    with pytest.raises(SequenceFileError, match="made for hand 'sah'"):
        Sequence.load(path).check_hand(allegro)
    path.write_text(path.read_text()[:-40])
    with pytest.raises(SequenceFileError, match="cannot read sequence file"):
        Sequence.load(path)


def test_worker_refuses_another_hand_and_finds_a_moved_builtin_urdf(sah: Hand) -> None:
    basis = pose_basis(sah, samples=200)
    digest = sah.description.digest()
    moved = replace(sah.description, urdf_path=Path("/nowhere/sah_right.urdf"))
    chunk = Chunk(moved, digest, basis, ((0.5, 0.5),), (0, 1), 0, IKSettings(max_iterations=30))
    assert len(solve_chunk(chunk).solved) == 2
    with pytest.raises(SequenceFileError, match="install the same sahgrasp"):
        solve_chunk(replace(chunk, hand_digest="f" * 64))


def test_invalid_settings_are_refused(tmp_path: Path) -> None:
    with pytest.raises(InvalidSettingsError, match="grid"):
        SearchSettings(grid=1)
    with pytest.raises(InvalidSettingsError, match="init"):
        SearchSettings(ik=IKSettings(init="random"))
    with pytest.raises(InvalidSettingsError, match="workers"):
        search_sequence("sah", SMALL, tmp_path, workers=0)
    with pytest.raises(InvalidSettingsError, match="Dask scheduler"):
        search_sequence("sah", SMALL, tmp_path, executor=42)


@pytest.mark.slow
def test_cli_runs_a_tiny_search(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    parser = argparse.ArgumentParser()
    sequence_cli.add_parser(parser.add_subparsers())
    args = parser.parse_args(
        ["sequence", "--grid", "2", "--problems", "4", "--rounds", "1", "--workers", "1",
         "--method", "paper", "--out", str(tmp_path)]
    )  # fmt: skip
    assert args.run(args) == 0
    assert "wrote" in capsys.readouterr().out
    sequence = Sequence.load(tmp_path / "sequence.json")
    assert len(sequence.lambdas) == 1
    assert sequence.meta is not None
    assert sequence.meta["method"] == "paper"


@pytest.mark.parametrize("name", ["sah", "allegro"])
def test_shipped_sequence_is_a_search_for_this_hand(name: str) -> None:
    shipped = resources.files("sahgrasp") / "data" / "sequences" / f"{name}.json"
    if not shipped.is_file():
        pytest.skip(f"no shipped sequence for {name} yet")
    sequence = Sequence.from_dict(json.loads(shipped.read_text()), str(shipped))
    sequence.check_hand(load_hand(name))
    assert sequence.source == "search"
    assert len(sequence.lambdas) == 12
