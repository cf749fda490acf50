"""Atomic writes, write-through to devices, early output checks and the JSON reader."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import pytest

from sahgrasp.core.errors import InvalidTargetError
from sahgrasp.core.fileio import (
    OutputLockedError,
    OutputPathError,
    OutputWriteError,
    atomic_path,
    check_output_path,
    is_temporary,
    lock_output,
    read_json,
    side_files,
    write_bytes_atomic,
    write_json_atomic,
)


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if is_temporary(p.name))


def test_replaces_a_file_and_keeps_its_permissions(tmp_path: Path) -> None:
    out = tmp_path / "out.json"
    out.write_text("old")
    out.chmod(0o640)
    write_json_atomic(out, {"a": 1})
    assert json.loads(out.read_text()) == {"a": 1}
    assert stat.S_IMODE(out.stat().st_mode) == 0o640
    assert _leftovers(tmp_path) == []


def test_new_file_gets_the_umask_permissions(tmp_path: Path) -> None:
    old = os.umask(0o027)
    try:
        write_bytes_atomic(tmp_path / "new.bin", b"x")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "new.bin").stat().st_mode) == 0o640


def test_creates_missing_folders(tmp_path: Path) -> None:
    write_bytes_atomic(tmp_path / "a" / "b" / "c.bin", b"x")
    assert (tmp_path / "a" / "b" / "c.bin").read_bytes() == b"x"


def test_follows_a_symlink_and_keeps_it(tmp_path: Path) -> None:
    target = tmp_path / "real.json"
    target.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    write_bytes_atomic(link, b"new")
    assert link.is_symlink()
    assert target.read_bytes() == b"new"


def test_writes_through_to_a_device() -> None:
    devnull = Path(os.devnull)
    before = devnull.stat()
    write_bytes_atomic(devnull, b"discarded")
    with atomic_path(devnull) as tmp:
        tmp.write_bytes(b"discarded too")
    after = devnull.stat()
    assert stat.S_ISCHR(after.st_mode)
    assert (after.st_ino, after.st_rdev) == (before.st_ino, before.st_rdev)
    assert not tmp.exists()


def test_writes_through_to_a_fifo(tmp_path: Path) -> None:
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    try:
        write_bytes_atomic(fifo, b"through")
        assert os.read(reader, 100) == b"through"
    finally:
        os.close(reader)
    assert stat.S_ISFIFO(fifo.stat().st_mode)


def test_refuses_a_folder(tmp_path: Path) -> None:
    with pytest.raises(OutputPathError, match="is a folder"):
        write_bytes_atomic(tmp_path, b"x")
    with pytest.raises(OutputPathError, match="is a folder"):
        check_output_path(tmp_path)


def test_temporary_file_removed_when_the_rename_fails(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "out.json"
    out.write_text("old")

    def fail(src: str, dst: str) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(OutputWriteError, match=f"cannot write {out}: No space"):
        write_bytes_atomic(out, b"new")
    assert out.read_text() == "old"
    assert _leftovers(tmp_path) == []


def test_temporary_file_removed_when_the_writer_fails(tmp_path: Path) -> None:
    out = tmp_path / "plot.png"
    with pytest.raises(RuntimeError), atomic_path(out) as tmp:
        assert tmp.name.endswith(".tmp.png") and tmp.parent == tmp_path
        tmp.write_bytes(b"half")
        raise RuntimeError("writer died")
    assert not out.exists()
    assert _leftovers(tmp_path) == []


def test_atomic_path_renames_on_success(tmp_path: Path) -> None:
    out = tmp_path / "plot.png"
    out.write_bytes(b"old")
    out.chmod(0o600)
    with atomic_path(out) as tmp:
        assert tmp.read_bytes() == b""  # a fresh file, not a copy of the old one
        tmp.write_bytes(b"new")
    assert out.read_bytes() == b"new"
    assert stat.S_IMODE(out.stat().st_mode) == 0o600
    assert _leftovers(tmp_path) == []


def test_exclusive_create_never_reuses_a_stale_temporary(tmp_path: Path) -> None:
    out = tmp_path / "out.json"
    stale = tmp_path / f".out.json.{os.getpid()}.tmp"
    stale.write_text("someone else's")
    write_bytes_atomic(out, b"mine")
    assert out.read_bytes() == b"mine"
    assert stale.read_text() == "someone else's"


def test_temporary_names() -> None:
    assert is_temporary(".round-002.json.999-0123abcd.sahgrasp.tmp")
    assert is_temporary(".fig.png.12-ffffffff.sahgrasp.tmp.png")
    assert not is_temporary(".notes.tmp")
    assert not is_temporary(".round-002.json.999.tmp")  # a user's file, not ours
    assert not is_temporary(".x.1-0123ABCD.sahgrasp.tmp")
    assert not is_temporary("out.json")


def test_check_refuses_the_input_also_through_a_link(tmp_path: Path) -> None:
    data = tmp_path / "io.json"
    data.write_text("{}")
    link = tmp_path / "link.json"
    link.symlink_to(data)
    for out in (data, link):
        with pytest.raises(OutputPathError, match="is the input file"):
            check_output_path(out, inputs=[data])
    assert (
        check_output_path(tmp_path / "other.json", inputs=[data, None, "sah"]).name == "other.json"
    )


def test_check_refuses_unwritable_places(tmp_path: Path) -> None:
    afile = tmp_path / "afile"
    afile.write_text("")
    with pytest.raises(OutputPathError, match="is not a folder"):
        check_output_path(afile / "out.json")
    with pytest.raises(OutputPathError, match="empty"):
        check_output_path("")
    with pytest.raises(OutputPathError, match="not a folder"):
        check_output_path(afile, folder=True)
    assert check_output_path(tmp_path / "new" / "dir", folder=True) == tmp_path / "new" / "dir"
    assert not (tmp_path / "new").exists(), "a check must not create anything"


@pytest.mark.parametrize(
    ("payload", "match"),
    [
        (b"\xff\xfe{\x00}\x00", "not UTF-8"),
        (b"\x7fELF\x02\x01\x01\x00\xd0", "not UTF-8"),
        (b"[" * 100_000 + b"]" * 100_000, "too deeply"),
        (b"{not json", "not valid JSON"),
        (b"[" + b"9" * 5000 + b"]", "not valid JSON"),
    ],
    ids=["utf16", "binary", "deep", "truncated", "huge-integer"],
)
def test_read_json_typed_errors(tmp_path: Path, payload: bytes, match: str) -> None:
    path = tmp_path / "f.json"
    path.write_bytes(payload)
    with pytest.raises(InvalidTargetError, match=match):
        read_json(path, "targets file", InvalidTargetError)


def test_read_json_missing_file_folder_and_bom(tmp_path: Path) -> None:
    with pytest.raises(InvalidTargetError, match=r"cannot read targets file .*No such file"):
        read_json(tmp_path / "nope.json", "targets file", InvalidTargetError)
    with pytest.raises(InvalidTargetError, match="Is a directory"):
        read_json(tmp_path, "targets file", InvalidTargetError)
    bom = tmp_path / "bom.json"
    bom.write_bytes(b"\xef\xbb\xbf[1]")
    assert read_json(bom, "targets file", InvalidTargetError) == [1]


def test_an_output_lock_refuses_a_second_writer_and_is_removed(tmp_path: Path) -> None:
    out = tmp_path / "r.jsonl"
    with lock_output(out) as lock:
        assert lock == tmp_path / "r.jsonl.lock"
        assert lock.read_text().strip() == str(os.getpid())
        held = rf"being written by .*process {os.getpid()}"
        with pytest.raises(OutputLockedError, match=held), lock_output(out):
            pass
        link = tmp_path / "link.jsonl"  # another name of the same output: the same lock
        link.symlink_to(out)
        out.write_text("")
        with pytest.raises(OutputLockedError), lock_output(link):
            pass
    assert not lock.exists()
    with lock_output(out):  # released: the next run takes it
        pass


def test_a_stale_lock_file_is_taken_over(tmp_path: Path) -> None:
    (tmp_path / "r.jsonl.lock").write_text("12345\n")  # left by a killed run: not locked
    with lock_output(tmp_path / "r.jsonl"):
        pass
    assert not (tmp_path / "r.jsonl.lock").exists()


def test_a_lock_file_that_is_a_link_is_refused(tmp_path: Path) -> None:
    precious = tmp_path / "precious.txt"
    precious.write_text("keep")
    (tmp_path / "r.jsonl.lock").symlink_to(precious)
    with pytest.raises(OutputPathError, match="symbolic link"), lock_output(tmp_path / "r.jsonl"):
        pass
    assert precious.read_text() == "keep"


def test_side_files_that_are_inputs_are_refused(tmp_path: Path) -> None:
    source = tmp_path / "r.jsonl.part"
    source.write_text("{}")
    out = tmp_path / "r.jsonl"
    with pytest.raises(OutputPathError, match=r"r\.jsonl\.part, which is the input"):
        check_output_path(out, [source], side=side_files(out))
    other = tmp_path / "t.jsonl"
    other.write_text("{}")
    (tmp_path / "o.jsonl.part").symlink_to(other)
    with pytest.raises(OutputPathError, match="which is the input file"):
        check_output_path(tmp_path / "o.jsonl", [other], side=side_files(tmp_path / "o.jsonl"))
    assert other.read_text() == "{}"


def test_a_failed_write_names_the_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def full(fd: int) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    out = tmp_path / "big.json"
    with pytest.raises(OutputWriteError, match=rf"cannot write {out}: No space left on device"):
        write_bytes_atomic(out, b"x")
    assert not out.exists() and _leftovers(tmp_path) == []
