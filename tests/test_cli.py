"""The ``sahgrasp`` command as a user runs it: a subprocess, its exit status and its stderr."""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import socket
import stat
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import psutil
import pytest

from sahgrasp.ik import IKSettings, random_problems
from sahgrasp.model.hand import load_hand
from sahgrasp.objects.targets import save_targets

ROOT = Path(__file__).resolve().parent.parent
HEAVY = ("numpy", "pinocchio", "coal", "scipy", "matplotlib", "meshcat", "dask", "trimesh", "tqdm")


def sahgrasp(*args: object, cwd: Path, **kwargs: Any) -> subprocess.CompletedProcess[str]:
    """Run ``python -m sahgrasp ARGS`` on this checkout."""
    return subprocess.run(
        [sys.executable, "-m", "sahgrasp", *map(str, args)],
        capture_output=True, encoding="utf-8", errors="strict", cwd=cwd,
        env={**os.environ, "PYTHONPATH": str(ROOT)}, **{"timeout": 300, **kwargs},
    )  # fmt: skip


def start(*args: object, cwd: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "sahgrasp", *map(str, args)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, encoding="utf-8", cwd=cwd,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip


def one_line_error(done: subprocess.CompletedProcess[str], pattern: str) -> None:
    """Exit status 2 and exactly one line on stderr, matching ``pattern``."""
    assert "Traceback" not in done.stderr, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert re.search(pattern, lines[0]), lines[0]
    assert done.returncode == 2


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder with ``one.json`` (1 problem, solvable) and ``many.json`` (60 problems)."""
    folder = tmp_path_factory.mktemp("cli")
    hand = load_hand("sah")
    save_targets(folder / "one.json", "sah", random_problems(hand, 1, 0))
    save_targets(folder / "many.json", "sah", random_problems(hand, 6, 1) * 10)
    return folder


def test_help_version_and_lazy_parser(tmp_path: Path) -> None:
    done = sahgrasp("--help", cwd=tmp_path)
    assert done.returncode == 0
    for command in ("info", "solve", "bench", "atlas", "sequence", "demo"):
        assert command in done.stdout
    version = sahgrasp("--version", cwd=tmp_path)
    assert version.returncode == 0 and re.fullmatch(r"sahgrasp \S+\n", version.stdout)
    # Building the parser (and importing the package) imports no heavy module.
    probe = (
        "import sys; from sahgrasp.cli import _parser; _parser(); "
        f"print(sorted(m for m in sys.modules if m.split('.')[0] in {HEAVY!r}))"
    )
    loaded = subprocess.run(
        [sys.executable, "-c", probe],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert loaded.stdout.strip() == "[]", loaded.stderr


def _every_parser() -> list[argparse.ArgumentParser]:
    from sahgrasp.cli import _parser

    found, todo = [], [_parser()]
    while todo:
        parser = todo.pop()
        found.append(parser)
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                todo.extend(action.choices.values())
    return found


def test_every_option_has_help_and_shows_its_default() -> None:
    parsers = _every_parser()
    commands = ("info", "solve", "atlas", "sequence", "demo", "bench")
    benches = ("kinematics", "ik", "atlas", "sequence", "grasps")
    expected = {"sahgrasp", *(f"sahgrasp {c}" for c in commands)}
    assert expected | {f"sahgrasp bench {b}" for b in benches} <= {p.prog for p in parsers}
    for parser in parsers:
        formatter = parser._get_formatter()
        for action in parser._actions:
            assert action.help, f"{parser.prog} {action.dest} has no help"
            shown = formatter._get_help_string(action)  # type: ignore[attr-defined]
            if not action.option_strings or action.default in (None, argparse.SUPPRESS):
                continue
            if action.nargs == 0 and not isinstance(action, argparse.BooleanOptionalAction):
                assert "%(default)" not in shown, f"{parser.prog} {action.dest}: a flag's default"
            else:
                assert "%(default)s" in shown, f"{parser.prog} {action.dest} hides its default"
    demo = next(p for p in parsers if p.prog.endswith(" demo"))
    assert "(default: sah; with --targets, the file's hand)" in " ".join(demo.format_help().split())
    sequence = next(p for p in parsers if p.prog.endswith(" sequence"))
    assert "about 10 minutes on 2 cores (SAH)" in " ".join(sequence.format_help().split())


def test_cli_defaults_are_the_library_defaults() -> None:
    import inspect

    from sahgrasp.bench import atlas, ik, kinematics
    from sahgrasp.bench import sequence as bench_sequence
    from sahgrasp.cli import sequence as sequence_cli
    from sahgrasp.experiments.arguments import INDEX_CHOICES
    from sahgrasp.quality.ellipsoids import INDICES
    from sahgrasp.sequence import SearchSettings

    assert INDEX_CHOICES == INDICES
    settings = SearchSettings()
    assert {
        "grid": settings.grid, "problems": settings.problems, "rounds": settings.rounds,
        "seed": settings.seed, "method": settings.method,
    } == sequence_cli.SEARCH_DEFAULTS  # fmt: skip
    from sahgrasp.cli.learn import LEARN_DEFAULTS
    from sahgrasp.ik.learned import LEARN_SEED

    assert LEARN_DEFAULTS["seed"] == LEARN_SEED
    parsers = {p.prog: p for p in _every_parser()}
    ik_defaults = IKSettings()
    solve = parsers["sahgrasp solve"]
    assert (solve.get_default("inits"), solve.get_default("method"), solve.get_default("init")) == (
        ik_defaults.max_inits,
        ik_defaults.method,
        ik_defaults.init,
    )
    for module in (atlas, ik, kinematics, bench_sequence):
        name = module.__name__.rsplit(".", 1)[1]
        parser = parsers[f"sahgrasp bench {name}"]
        params = inspect.signature(module.run).parameters
        options = {a.dest for a in parser._actions if a.option_strings} - {"help", "json"}
        assert options <= set(params), (name, options - set(params))
        for param in params.values():
            if parser.get_default(param.name) is not None:
                expected = param.default
                got = parser.get_default(param.name)
                assert type(expected)(got) == expected, (name, param.name)


@pytest.mark.parametrize(
    ("args", "pattern"),
    [
        (["solve", "one.json", "--seed", "-1"], r"--seed: -1 is out of range: must be .* >= 0"),
        (["solve", "one.json", "--inits", "1001"], r"--inits: 1001 .* in 1\.\.1000"),
        (["solve", "one.json", "--inits", "0"], r"--inits: 0 .* in 1\.\.1000"),
        (["solve", "one.json", "--workers", "0"], r"--workers: 0 .* >= 1"),
        (["solve", "one.json", "--seed", "x"], r"--seed: 'x' is not an integer"),
        (["sequence", "--out", "d", "--seed", "-1"], r"--seed: -1 .* >= 0"),
        (["sequence", "--out", "d", "--workers", "0"], r"--workers: 0 .* >= 1"),
        (["sequence", "--out", "d", "--grid", "1"], r"--grid: 1 .* >= 2"),
        (["atlas", "planar", "--r", "0"], r"--r: 0 .* finite number > 0"),
        (["atlas", "can", "--eps", "0"], r"--eps: 0 .* finite number > 0"),
        (["atlas", "can", "--r", "nan"], r"--r: nan .* finite number > 0"),
        (["atlas", "can", "--max-charts", "0"], r"--max-charts: 0 .* >= 1"),
        (["bench", "kinematics", "--calls", "0"], r"--calls: 0 .* >= 1"),
        (["bench", "kinematics", "--calls", "-1"], r"--calls: -1 .* >= 1"),
        (["bench", "atlas", "--repeats", "0"], r"--repeats: 0 .* >= 1"),
        (["bench", "ik", "--problems", "0"], r"--problems: 0 .* >= 1"),
        (["demo", "--inits", "5000"], r"--inits: 5000 .* in 1\.\.1000"),
        (["info", "--bogus"], r"unrecognized arguments: --bogus"),
        (["solve", "one.json", "--scheduler", "bogus"], r"--scheduler: 'bogus' is not a Dask sch"),
        (["solve", "one.json", "--scheduler", ""], r"--scheduler: '' is not a Dask scheduler"),
        (["solve", "one.json", "--scheduler", "tcp://"], r"--scheduler: 'tcp://' is not a Dask"),
        (
            ["solve", "one.json", "--scheduler", "http://h:80"],
            r"--scheduler: .*give tcp://HOST:PORT or HOST",
        ),
        (
            ["solve", "one.json", "--scheduler", "inproc://x"],
            r"--scheduler: .*'inproc://x' is not supp",
        ),
        (
            ["sequence", "--out", "d", "--scheduler", "tls://h:1"],
            r"--scheduler: .*'tls://h:1' is not supp",
        ),
        (["sequence", "--out", "d", "--scheduler", "bogus"], r"--scheduler: 'bogus' is not a Dask"),
        (
            ["learn", "--out", "d.npz", "--scheduler", "bogus"],
            r"--scheduler: 'bogus' is not a Dask",
        ),
        (
            ["bench", "ik", "--plot", "fig"],
            r"--plot: 'fig' is not an image file name \(no suffix\)",
        ),
        (["bench", "ik", "--plot", "fig.txt"], r"--plot: 'fig.txt' .*unknown suffix '\.txt'"),
        (["atlas", "planar", "--plot", "out"], r"--plot: 'out' is not an image file name"),
    ],
)
def test_usage_errors(files: Path, args: list[str], pattern: str) -> None:
    one_line_error(sahgrasp(*args, cwd=files), r"^sahgrasp[a-z ]*: error: (argument )?" + pattern)


@pytest.mark.parametrize(
    ("args", "pattern"),
    [
        (["solve", "one.json", "--json", "one.json"], r"output one\.json is the input file"),
        (["solve", "one.json", "--json", "."], r"output \. is a folder"),
        (["solve", "one.json", "--json", "one.json/out.json"], r"one\.json is not a folder"),
        (["info", "--json", "."], r"output \. is a folder"),
        (["atlas", "planar", "--plot", "one.json/p.png"], r"one\.json is not a folder"),
        (["atlas", "planar", "--plot", "o.png", "--json", "o.png"], r"o\.png is given twice"),
        (["bench", "ik", "--targets", "one.json", "--json", "one.json"], r"is the input file"),
        (["bench", "kinematics", "--json", "."], r"is a folder"),
        (["demo", "--html", "."], r"is a folder"),
        (["sequence", "--out", "one.json"], r"one\.json exists and is not a folder"),
    ],
)
def test_bad_output_paths_fail_before_the_work(files: Path, args: list[str], pattern: str) -> None:
    before = (files / "one.json").read_bytes()
    one_line_error(sahgrasp(*args, cwd=files), r"^sahgrasp: error: .*" + pattern)
    assert (files / "one.json").read_bytes() == before


@pytest.mark.parametrize(
    ("content", "pattern"),
    [
        (None, r"cannot read targets file missing\.json: No such file"),
        (b"\xff\xfe{\x00}\x00", r"is not UTF-8 text"),
        (b"\x7fELF\x02\x01\x01\x00\x00\xd0\xc3", r"is not UTF-8 text"),
        (b"[" * 100_000 + b"]" * 100_000, r"is nested too deeply"),
        (b'{"problems": ' + b"[" * 100_000 + b"]" * 100_000 + b"}", r"too deeply"),
        (b"{", r"is not valid JSON"),
        (b"[1, 2]", r"must be an object with 'hand' and a 'problems' list"),
        (b'{"hand": 5, "problems": []}', r"'hand' must be one of 'sah', 'allegro' or a hand-desc"),
        (b'{"hand": "nohand", "problems": []}', r"unknown hand 'nohand'"),
    ],
    ids=["missing", "utf16", "binary", "deep", "deep-problems", "truncated", "list", "hand-type",
         "hand-name"],
)  # fmt: skip
def test_unreadable_targets_files(tmp_path: Path, content: bytes | None, pattern: str) -> None:
    if content is not None:
        (tmp_path / "missing.json").write_bytes(content)
    one_line_error(
        sahgrasp("solve", "missing.json", cwd=tmp_path), r"^sahgrasp: error: .*" + pattern
    )


@pytest.mark.slow
def test_a_refused_scheduler_connection_is_one_line_at_once(files: Path) -> None:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]  # nothing listens there once closed
    for args in (["solve", "one.json"], ["sequence", "--out", "d"]):
        done = sahgrasp(*args, "--scheduler", f"127.0.0.1:{port}", cwd=files, timeout=20)
        one_line_error(done, rf"cannot reach the Dask scheduler at tcp://127\.0\.0\.1:{port}")
    assert not (files / "d").exists()


def test_a_folder_as_targets(tmp_path: Path) -> None:
    one_line_error(sahgrasp("solve", ".", cwd=tmp_path), r"cannot read targets file \.: Is a dir")


def _mixed(files: Path, folder: Path) -> Path:
    """``folder/mixed.json``: the solvable problem, then one invalid problem of each kind."""
    good = json.loads((files / "one.json").read_text())["problems"][0]

    def edit(name: str, **changes: Any) -> dict[str, Any]:
        problem = json.loads(json.dumps(good))
        problem["name"] = name
        problem["contacts"][0].update(changes)
        return problem

    missing = edit("missing")
    missing["contacts"].pop(0)  # the thumb: the other fingers may be left free, not the thumb
    problems = [
        good,
        edit("huge", point=[10**400, 0, 0]),
        edit("string", point=["0.1", 0, 0]),
        edit("boolean", normal=[True, 0, 0]),
        edit("short", point=[0, 0]),
        edit("nan", point=[float("nan"), 0, 0]),
        edit("pinky", finger="pinky"),
        missing,
        edit("lone\ud800surrogate\x1b[31m", finger="pinky"),
        42,
    ]
    path = folder / "mixed.json"
    path.write_text(json.dumps({"hand": "sah", "problems": problems}), encoding="utf-8")
    return path


def test_invalid_problems_are_reported_and_the_others_solved(files: Path, tmp_path: Path) -> None:
    targets = _mixed(files, tmp_path)
    done = sahgrasp("solve", targets, "--json", tmp_path / "out.json", cwd=tmp_path)
    assert done.returncode == 1, done.stderr
    assert "Traceback" not in done.stderr
    assert "\x1b" not in done.stdout and "\\x1b[31m" in done.stdout
    document = json.loads(
        (tmp_path / "out.json").read_text(encoding="utf-8"), parse_constant=pytest.fail
    )
    results = document["results"]
    assert results[0]["success"] and results[0]["reason"] == "converged"
    assert all(r["reason"] == "invalid_input" for r in results[1:])
    assert all(r["max_position_error_mm"] is None for r in results[1:])
    details = {r["name"]: r["detail"] for r in results[1:]}
    expected = {
        "huge": "too large for a float", "string": "must be 3 numbers",
        "boolean": "must be 3 numbers", "short": "3 components", "nan": "NaN or inf",
        "pinky": "unknown finger", "missing": "missing contact", "problem-9": "must be an object",
        "lone\ufffdsurrogate\x1b[31m": "unknown finger",
    }  # fmt: skip
    assert set(details) == set(expected)
    for name, reason in expected.items():
        assert reason in details[name]
        assert f"{name}: invalid input: " in done.stdout.replace("\\x1b", "\x1b")
    assert document["summary"] == {**document["summary"], "problems": 10, "solved": 1, "invalid": 9}


def test_json_to_stdout_is_strict_json_alone(files: Path, tmp_path: Path) -> None:
    done = sahgrasp(
        "solve", _mixed(files, tmp_path).name, "--inits", "1", "--json", "-", cwd=tmp_path
    )
    assert done.returncode == 1
    document = json.loads(done.stdout, parse_constant=pytest.fail)
    assert len(document["results"]) == 10
    assert "solved 0/10" in done.stderr or "solved 1/10" in done.stderr


def test_all_solved_exits_0_and_writes_through_a_link(files: Path, tmp_path: Path) -> None:
    real = tmp_path / "real.json"
    real.write_text("old")
    real.chmod(0o604)
    (tmp_path / "link.json").symlink_to(real)
    done = sahgrasp("solve", files / "one.json", "--json", "link.json", cwd=tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    assert (tmp_path / "link.json").is_symlink()
    assert json.loads(real.read_text())["summary"]["solved"] == 1
    assert stat.S_IMODE(real.stat().st_mode) == 0o604


def test_dev_null_stays_a_device(files: Path) -> None:
    done = sahgrasp("solve", "one.json", "--json", os.devnull, cwd=files)
    assert done.returncode == 0, done.stderr
    assert stat.S_ISCHR(Path(os.devnull).stat().st_mode)


@pytest.mark.slow
def test_relative_hand_path_is_read_from_the_targets_folder(files: Path, tmp_path: Path) -> None:
    sah = load_hand("sah").description
    hand = {
        "name": "mysah", "urdf": str(sah.urdf_path),
        "fingertip_radius_m": sah.fingertip_radius_m,
        "contact_pitch_limits_rad": list(sah.contact_pitch_limits_rad),
        "contact_yaw_limits_rad": list(sah.contact_yaw_limits_rad),
        "fingers": [{"name": f.name, "tip_link": f.tip_link, "tip_axis": list(f.tip_axis),
                     "pad_axis": list(f.pad_axis)} for f in sah.fingers],
    }  # fmt: skip
    sub = tmp_path / "sub"
    sub.mkdir()
    (sub / "mysah.json").write_text(json.dumps(hand))
    targets = json.loads((files / "one.json").read_text())
    (sub / "t.json").write_text(json.dumps({**targets, "hand": "mysah.json"}))
    done = sahgrasp(
        "solve", "sub/t.json", "--init", "random", "--inits", "1", "--json", "-", cwd=tmp_path
    )
    assert "Traceback" not in done.stderr
    assert json.loads(done.stdout)["hand"] == "mysah"


def _wait_for_workers(process: subprocess.Popen[str], count: int) -> list[psutil.Process]:
    """The worker processes once ``count`` are up (the signal handlers are installed by then)."""
    for _ in range(600):
        children = psutil.Process(process.pid).children(recursive=True)
        if len(children) >= count:
            return children
        if process.poll() is not None:
            pytest.fail(f"finished before its workers started: {process.communicate()}")
        time.sleep(0.1)
    pytest.fail("the workers never started")


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_signals_stop_solve_with_one_line_and_no_orphan(files: Path, signum: int) -> None:
    process = start("solve", "many.json", "--workers", "2", "--inits", "1000", cwd=files)
    workers = _wait_for_workers(process, 2)
    process.send_signal(signum)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 130
    assert err.strip().splitlines()[-1] == "sahgrasp: interrupted"
    assert "Traceback" not in err
    psutil.wait_procs(workers, timeout=30)
    assert not [w for w in workers if w.is_running() and w.status() != psutil.STATUS_ZOMBIE]


@pytest.mark.slow
def test_sighup_to_the_process_group_prints_no_traceback(files: Path) -> None:
    # As when the terminal closes: every process of the group gets SIGHUP, the workers and
    # multiprocessing's resource tracker too.
    process = subprocess.Popen(
        [sys.executable, "-m", "sahgrasp", "solve", "many.json", "--workers", "2", "--inits",
         "1000"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, encoding="utf-8", cwd=files,
        env={**os.environ, "PYTHONPATH": str(ROOT)}, start_new_session=True,
    )  # fmt: skip
    workers = _wait_for_workers(process, 2)
    os.killpg(process.pid, signal.SIGHUP)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 130, err
    assert "Traceback" not in err and "KeyError" not in err, err
    assert err.strip().splitlines()[-1] == "sahgrasp: interrupted"
    psutil.wait_procs(workers, timeout=30)


@pytest.mark.slow
def test_interrupted_sequence_prints_the_resume_command(tmp_path: Path) -> None:
    process = start("sequence", "--grid", "3", "--problems", "30", "--rounds", "2",
                    "--workers", "1", "--out", "out dir", cwd=tmp_path)  # fmt: skip
    for _ in range(1200):  # the search is under way once its checkpoint folder exists
        if (tmp_path / "out dir" / "checkpoint").is_dir() or process.poll() is not None:
            break
        time.sleep(0.1)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 130, err
    assert err.strip().splitlines()[-1] == (
        "sahgrasp: interrupted; continue from the last checkpoint with: sahgrasp sequence "
        "--hand sah --grid 3 --problems 30 --rounds 2 --seed 0 --method auto --out 'out dir' "
        "--workers 1 --resume"
    )


def test_a_closed_pipe_ends_quietly(tmp_path: Path) -> None:
    problems = [{"name": f"p{i}", "contacts": []} for i in range(5000)]
    (tmp_path / "t.json").write_text(json.dumps({"hand": "sah", "problems": problems}))
    process = start("solve", "t.json", cwd=tmp_path)
    assert process.stdout is not None and process.stderr is not None
    assert process.stdout.readline().startswith("p0: invalid input")
    process.stdout.close()
    err = process.stderr.read()
    assert process.wait(timeout=120) == 141
    assert err == ""


@pytest.mark.parametrize("unbuffered", ["", "1"], ids=["buffered", "PYTHONUNBUFFERED"])
def test_json_to_a_reader_that_closes_early_exits_141(tmp_path: Path, unbuffered: str) -> None:
    # A document far larger than a pipe's buffer: the reader closes while it is being written.
    problems = [{"name": f"p{i}", "contacts": []} for i in range(5000)]
    (tmp_path / "t.json").write_text(json.dumps({"hand": "sah", "problems": problems}))
    with (tmp_path / "err.txt").open("wb") as errors:  # a file: its 5000 lines block no pipe
        process = subprocess.Popen(
            [sys.executable, "-m", "sahgrasp", "solve", "t.json", "--quiet", "--json", "-"],
            stdout=subprocess.PIPE, stderr=errors, cwd=tmp_path,
            env={**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": unbuffered},
        )  # fmt: skip
        assert process.stdout is not None
        assert process.stdout.read(1) == b"{"
        process.stdout.close()
        code = process.wait(timeout=120)
    err = (tmp_path / "err.txt").read_text()
    assert code == 141, err[-2000:]
    assert "Traceback" not in err and "error:" not in err, err[-2000:]


@pytest.mark.parametrize(
    ("args", "pattern"),
    [
        (["info", "--hand", "deep.json"], r"hand description deep\.json is nested too deeply"),
        (["solve", "one.json", "--hand", "u16.json"], r"hand description u16\.json is not UTF-8"),
        (
            ["solve", "one.json", "--sequence", "deep.json"],
            r"sequence file deep\.json is nested too deeply",
        ),
        (["solve", "one.json", "--sequence", "u16.json"], r"sequence file u16\.json is not UTF"),
        (["info", "--hand", "h.urdf"], r"h\.urdf is a URDF, .*docs/how-to/add-a-hand\.md"),
        (["solve", "one.json", "--hand", "h.xml"], r"h\.xml is a URDF, .*hand-description JSON"),
    ],
)
def test_malformed_hand_and_sequence_files(
    files: Path, tmp_path: Path, args: list[str], pattern: str
) -> None:
    (tmp_path / "one.json").write_bytes((files / "one.json").read_bytes())
    (tmp_path / "deep.json").write_bytes(b"[" * 100_000 + b"]" * 100_000)
    (tmp_path / "u16.json").write_bytes('{"name": "x"}'.encode("utf-16"))
    urdf = (ROOT / "urdf" / "sah_right.urdf").read_bytes()
    (tmp_path / "h.urdf").write_bytes(urdf)
    (tmp_path / "h.xml").write_bytes(urdf)
    one_line_error(sahgrasp(*args, cwd=tmp_path), r"^sahgrasp: error: " + pattern)


def test_bench_json_to_stdout(tmp_path: Path) -> None:
    done = sahgrasp("bench", "kinematics", "--calls", "3", "--json", "-", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    document = json.loads(done.stdout, parse_constant=pytest.fail)
    assert document["calls"] == 3 and set(document["hands"]) == {"sah", "allegro"}


def test_bench_prints_its_table_and_writes_json_only_when_asked(tmp_path: Path) -> None:
    done = sahgrasp("bench", "kinematics", "--calls", "3", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("bench kinematics: 3 calls") and "{" not in done.stdout
    assert done.stderr == ""  # progress bars only on a terminal, not in a pipe or a log
    assert list(tmp_path.iterdir()) == []
    done = sahgrasp("bench", "kinematics", "--calls", "3", "--json", "k.json", cwd=tmp_path)
    assert done.returncode == 0 and "bench kinematics" in done.stdout
    assert json.loads((tmp_path / "k.json").read_text())["calls"] == 3


def test_bench_grasps_runs_from_the_command_line(tmp_path: Path) -> None:
    args = ("bench", "grasps", "--problems-per-object", "1", "--objects", "can", "--quiet")
    done = sahgrasp(*args, "--without-object", "--json", "g.json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "| can | without object |" in done.stdout and "with object |" not in done.stdout
    assert json.loads((tmp_path / "g.json").read_text())["problems_per_object"] == 1


@pytest.mark.slow
def test_bench_ik_reports_its_plot_under_the_users_name(tmp_path: Path) -> None:
    args = ("bench", "ik", "--problems", "2", "--peers", "--quiet", "--plot", "fig.png")
    done = sahgrasp(*args, "--json", "-", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout, parse_constant=pytest.fail)["plot"] == "fig.png"
    assert done.stderr.strip().splitlines() == ["wrote fig.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig.png"]


@pytest.mark.slow
def test_atlas_writes_its_plot_atomically(tmp_path: Path) -> None:
    done = sahgrasp("atlas", "planar", "--r", "0.3", "--plot", "p.png", "--json", "-", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout, parse_constant=pytest.fail)["radius"] == 0.3
    assert "wrote p.png" in done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.png"]
    assert (tmp_path / "p.png").read_bytes().startswith(b"\x89PNG")


def test_package_exports_load_lazily() -> None:
    code = (
        "import sys, sahgrasp; assert 'pinocchio' not in sys.modules; "
        "from sahgrasp import _EXPORTS; "
        "assert sorted(n for ns in _EXPORTS.values() for n in ns) == sahgrasp.__all__; "
        "assert all(getattr(sahgrasp, n) is not None for n in sahgrasp.__all__); "
        "assert 'pinocchio' in sys.modules"
    )
    subprocess.run(
        [sys.executable, "-c", code], check=True, env={**os.environ, "PYTHONPATH": str(ROOT)}
    )


# Losing or mis-reading files: every file a run reads is an input that no output may replace.


def _jsonl(files: Path, folder: Path, count: int = 3, name: str = "t.jsonl") -> Path:
    """``folder/NAME``: a JSON Lines targets file of ``count`` problems of ``many.json``."""
    problems = json.loads((files / "many.json").read_text())["problems"][:count]
    path = folder / name
    path.write_text("".join(json.dumps(p) + "\n" for p in problems))
    return path


def _my_hand(folder: Path) -> tuple[Path, Path]:
    """A hand description ``folder/mysah.json`` naming its own copy ``folder/mysah.urdf``."""
    sah = load_hand("sah").description
    urdf = folder / "mysah.urdf"
    urdf.write_bytes(sah.urdf_path.read_bytes())
    hand = {
        "name": "mysah", "urdf": str(urdf),
        "fingertip_radius_m": sah.fingertip_radius_m,
        "contact_pitch_limits_rad": list(sah.contact_pitch_limits_rad),
        "contact_yaw_limits_rad": list(sah.contact_yaw_limits_rad),
        "fingers": [{"name": f.name, "tip_link": f.tip_link, "tip_axis": list(f.tip_axis),
                     "pad_axis": list(f.pad_axis)} for f in sah.fingers],
    }  # fmt: skip
    (folder / "mysah.json").write_text(json.dumps(hand))
    return folder / "mysah.json", urdf


@pytest.mark.slow
def test_a_second_solve_writing_the_same_output_is_refused(files: Path, tmp_path: Path) -> None:
    """The first run reads a pipe, so it is still writing when the second one starts."""
    fifo = tmp_path / "pipe.jsonl"
    os.mkfifo(fifo)
    lines = _jsonl(files, tmp_path, 4).read_text().splitlines(keepends=True)
    first = start("solve", fifo, "--json", "r.jsonl", cwd=tmp_path)
    try:
        with fifo.open("w") as feed:
            feed.write(lines[0])
            feed.flush()
            for _ in range(600):  # the output is locked before the first problem is solved
                if (tmp_path / "r.jsonl.lock").exists():
                    break
                time.sleep(0.1)
            second = sahgrasp("solve", _jsonl(files, tmp_path, 2, "other.jsonl"), "--json",
                              "r.jsonl", cwd=tmp_path)  # fmt: skip
            one_line_error(second, r"r\.jsonl is being written by another sahgrasp run")
            feed.writelines(lines[1:])
        _, err = first.communicate(timeout=300)
    finally:
        first.kill()
    assert first.returncode == 0, err
    results = (tmp_path / "r.jsonl").read_text().splitlines()
    assert [json.loads(line)["name"] for line in results[1:]] == [
        json.loads(line)["name"] for line in lines
    ]
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("r.")) == ["r.jsonl"]


def test_side_files_never_replace_an_input(files: Path, tmp_path: Path) -> None:
    part = tmp_path / "r.jsonl.part"  # a JSON document, whatever its name
    part.write_bytes((files / "one.json").read_bytes())
    before = part.read_bytes()
    done = sahgrasp("solve", part, "--json", "r.jsonl", cwd=tmp_path)
    one_line_error(done, r"r\.jsonl\.part, which is the input file")
    assert part.read_bytes() == before
    source = _jsonl(files, tmp_path, 2)
    (tmp_path / "o.jsonl.part").symlink_to(source)
    done = sahgrasp("solve", source, "--json", "o.jsonl", cwd=tmp_path)
    one_line_error(done, r"o\.jsonl\.part, which is the input file")
    assert len(source.read_text().splitlines()) == 2


@pytest.mark.slow
def test_files_named_inside_the_inputs_are_inputs(files: Path, tmp_path: Path) -> None:
    import shutil

    shutil.copy(ROOT / "examples" / "meshes" / "mug.stl", tmp_path / "mybox.stl")
    mesh = (tmp_path / "mybox.stl").read_bytes()
    problem = json.loads((files / "one.json").read_text())["problems"][0]
    _, urdf = _my_hand(tmp_path)
    targets = {"hand": "mysah.json", "object": {"mesh": "mybox.stl"}, "problems": [problem]}
    (tmp_path / "tm.json").write_text(json.dumps(targets))
    done = sahgrasp("solve", "tm.json", "--json", "mybox.stl", cwd=tmp_path)
    one_line_error(done, r"output mybox\.stl is the input file .*mybox\.stl")
    assert (tmp_path / "mybox.stl").read_bytes() == mesh
    original = urdf.read_bytes()
    done = sahgrasp("solve", "tm.json", "--json", "mysah.urdf", cwd=tmp_path)
    one_line_error(done, r"output mysah\.urdf is the input file .*mysah\.urdf")
    assert urdf.read_bytes() == original
    # A JSON Lines targets file names its meshes line by line: a line naming the output is not
    # read, and the output is not published over it.
    line = {**problem, "object": {"mesh": "late.stl"}}
    shutil.copy(tmp_path / "mybox.stl", tmp_path / "late.stl")
    (tmp_path / "tm.jsonl").write_text(json.dumps(line) + "\n")
    done = sahgrasp("solve", "tm.jsonl", "--json", "late.stl", cwd=tmp_path)
    one_line_error(done, r"name the output late\.stl .* an input is never replaced")
    assert (tmp_path / "late.stl").read_bytes() == mesh


def test_a_fifo_of_problems_loses_none(files: Path, tmp_path: Path) -> None:
    fifo = tmp_path / "pipe.jsonl"
    os.mkfifo(fifo)
    text = json.dumps({"hand": "sah"}) + "\n" + _jsonl(files, tmp_path, 40).read_text()
    run = start("solve", fifo, "--init", "random", "--inits", "1", "--json", "r.jsonl",
                cwd=tmp_path)  # fmt: skip
    try:
        with fifo.open("w") as feed:
            feed.write(text)
        _, err = run.communicate(timeout=300)
    finally:
        run.kill()
    assert run.returncode in (0, 1) and "Traceback" not in err, err
    assert len((tmp_path / "r.jsonl").read_text().splitlines()) == 1 + 40


@pytest.mark.slow
def test_a_refused_resume_leaves_the_finished_output(files: Path, tmp_path: Path) -> None:
    targets = _jsonl(files, tmp_path, 2)
    done = sahgrasp("solve", targets, "--inits", "1", "--json", "r.jsonl", cwd=tmp_path)
    assert done.returncode in (0, 1), done.stderr
    before = (tmp_path / "r.jsonl").read_bytes()
    again = sahgrasp("solve", targets, "--inits", "2", "--json", "r.jsonl", "--resume",
                     cwd=tmp_path)  # fmt: skip
    one_line_error(again, "other settings")
    assert (tmp_path / "r.jsonl").read_bytes() == before
    # The same problems under another default object: another targets file, refused.
    other = tmp_path / "other.jsonl"
    other.write_text(json.dumps({"object": {"name": "can"}}) + "\n" + targets.read_text())
    again = sahgrasp("solve", other, "--inits", "1", "--json", "r.jsonl", "--resume",
                     cwd=tmp_path)  # fmt: skip
    one_line_error(again, "another hand or default object")
    assert (tmp_path / "r.jsonl").read_bytes() == before
    assert not (tmp_path / "r.jsonl.part").exists()


def _resumed(done: subprocess.CompletedProcess[str]) -> int:
    match = re.search(r"(\d+) resumed", done.stdout)
    assert match, done.stdout + done.stderr
    return int(match.group(1))


@pytest.mark.slow
def test_resume_matches_results_by_problem_not_by_name(files: Path, tmp_path: Path) -> None:
    targets = _jsonl(files, tmp_path, 3)
    solve = ("solve", targets, "--inits", "1", "--json", "r.jsonl")
    assert sahgrasp(*solve, cwd=tmp_path).returncode in (0, 1)
    problems = [json.loads(line) for line in targets.read_text().splitlines()]
    moved = problems[1]["contacts"][0]
    moved["point"] = [x + 0.002 for x in moved["point"]]  # same name, another problem
    targets.write_text("".join(json.dumps(p) + "\n" for p in problems))
    done = sahgrasp(*solve, "--resume", cwd=tmp_path)
    assert done.returncode in (0, 1) and _resumed(done) == 1, done.stdout + done.stderr
    assert "differs from the one" in done.stdout
    from sahgrasp.ik.stream import problem_digest
    from sahgrasp.objects.targets import problem_from_json

    lines = [json.loads(line) for line in (tmp_path / "r.jsonl").read_text().splitlines()[1:]]
    assert [e["problem_digest"] for e in lines] == [
        problem_digest(problem_from_json(p, i, tmp_path)) for i, p in enumerate(problems)
    ]
    # Another file of unnamed problems is not "resumed": its problems are solved.
    unnamed = [{"contacts": p["contacts"]} for p in json.loads(
        (files / "many.json").read_text())["problems"][3:6]]  # fmt: skip
    (tmp_path / "u.jsonl").write_text("".join(json.dumps(p) + "\n" for p in unnamed))
    assert sahgrasp("solve", "u.jsonl", "--inits", "1", "--json", "u_r.jsonl",
                    cwd=tmp_path).returncode in (0, 1)  # fmt: skip
    (tmp_path / "u.jsonl").write_text("".join(json.dumps(p) + "\n" for p in unnamed[::-1]))
    done = sahgrasp("solve", "u.jsonl", "--inits", "1", "--json", "u_r.jsonl", "--resume",
                    cwd=tmp_path)  # fmt: skip
    assert _resumed(done) == 0, done.stdout


def test_a_full_disk_names_the_file(files: Path) -> None:
    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full")
    done = sahgrasp("solve", "one.json", "--json", "/dev/full", cwd=files)
    one_line_error(done, r"cannot write /dev/full: No space left on device")


def test_a_jsonl_output_in_a_missing_folder_is_made_before_the_work(
    files: Path, tmp_path: Path
) -> None:
    done = sahgrasp("solve", files / "one.json", "--json", "new/sub/r.jsonl", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert len((tmp_path / "new" / "sub" / "r.jsonl").read_text().splitlines()) == 2


@pytest.mark.slow
def test_learn_refuses_its_inputs_and_a_locked_output(tmp_path: Path) -> None:
    from sahgrasp.core.fileio import lock_output

    description, _ = _my_hand(tmp_path)
    before = description.read_bytes()
    for out in ("mysah.json", "mysah.urdf"):
        done = sahgrasp("learn", "--hand", "mysah.json", "--samples", "1", "--grasps", "0",
                        "--workers", "1", "--out", out, cwd=tmp_path)  # fmt: skip
        one_line_error(done, rf"output {out} is the input file")
    assert description.read_bytes() == before
    with lock_output(tmp_path / "db.npz"):
        done = sahgrasp("learn", "--samples", "1", "--grasps", "0", "--workers", "1",
                        "--out", "db.npz", cwd=tmp_path)  # fmt: skip
        one_line_error(done, r"db\.npz is being written by another sahgrasp run")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mysah.json", "mysah.urdf"]


@pytest.mark.slow
def test_concurrent_learns_leave_one_database_and_no_parts(tmp_path: Path) -> None:
    args = ("learn", "--samples", "40", "--grasps", "0", "--workers", "1", "--out", "db.npz")
    runs = [start(*args, cwd=tmp_path) for _ in range(3)]
    outcomes = [(run.wait(timeout=300), run.communicate()[1]) for run in runs]
    assert all(code in (0, 2) for code, _ in outcomes), outcomes
    assert any(code == 0 for code, _ in outcomes)
    for code, err in outcomes:
        assert code == 0 or "being written by another sahgrasp run" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["db.npz"]


@pytest.mark.slow
def test_solve_uses_a_database_made_by_learn(files: Path, tmp_path: Path) -> None:
    from sahgrasp.ik.learned import default_database

    sah = default_database(load_hand("sah"))
    assert sah is not None
    from dataclasses import replace

    small = replace(sah, configurations=sah.configurations[:50], features=sah.features[:50],
                    grasp_entries=0)  # fmt: skip
    small.save(tmp_path / "db.npz")
    done = sahgrasp("solve", files / "one.json", "--database", "db.npz", "--json", "r.jsonl",
                    cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    header = json.loads((tmp_path / "r.jsonl").read_text().splitlines()[0])
    import hashlib

    assert (
        header["database_digest"] == hashlib.sha256((tmp_path / "db.npz").read_bytes()).hexdigest()
    )
    done = sahgrasp("solve", files / "one.json", "--hand", "allegro", "--database", "db.npz",
                    cwd=tmp_path)  # fmt: skip
    one_line_error(done, "made for")
    done = sahgrasp("solve", files / "one.json", "--init", "sequence", "--database", "db.npz",
                    cwd=tmp_path)  # fmt: skip
    one_line_error(done, "--database is the database of --init learned")


@pytest.mark.slow
def test_demo_and_solve_share_one_code_path(tmp_path: Path) -> None:
    """The same starts and solutions; a bad problem is marked invalid, the others are shown."""
    from sahgrasp.objects import paper_grasp

    can = paper_grasp("can").to_dict()
    problems = [{**can, "name": "can"}, {**can, "name": "bad", "contacts": can["contacts"][1:3]}]
    (tmp_path / "t.json").write_text(
        json.dumps({"hand": "sah", "object": {"name": "can"}, "problems": problems})
    )
    solved = sahgrasp("solve", "t.json", "--json", "r.json", cwd=tmp_path)
    assert solved.returncode == 1, solved.stderr
    entries = json.loads((tmp_path / "r.json").read_text())["results"]
    shown = sahgrasp("demo", "--targets", "t.json", "--html", "d.html", cwd=tmp_path)
    assert shown.returncode == 1 and "Traceback" not in shown.stderr, shown.stderr
    assert (tmp_path / "d.html").is_file()
    row = next(line.split() for line in shown.stdout.splitlines() if line.startswith("can "))
    assert row[2] == "yes" and entries[0]["success"]
    assert [int(row[3]), int(row[4])] == [entries[0]["inits_used"], entries[0]["iterations"]]
    assert "bad: invalid input: " in shown.stdout and entries[1]["reason"] == "invalid_input"


def test_time_ms_is_the_solve_and_setup_ms_the_object(
    files: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Building an object's collision pieces is set-up, reported apart from the solve."""
    from sahgrasp.cli.solve import results_document
    from sahgrasp.collision.hand_object import HandObjectClearance
    from sahgrasp.ik.batch import solve_chunks
    from sahgrasp.model.contacts import GraspTarget, ObjectSpec
    from sahgrasp.objects import paper_grasp

    built = HandObjectClearance.__init__

    def slow(self: HandObjectClearance, *args: Any, **kwargs: Any) -> None:
        time.sleep(0.4)
        built(self, *args, **kwargs)

    monkeypatch.setattr(HandObjectClearance, "__init__", slow)
    hand = load_hand("sah")
    spec = ObjectSpec("can", None, (0.0, 0.0, 0.123456))  # a placement no other test builds
    T = np.eye(4)
    T[:3, 3] = spec.xyz
    grasp = paper_grasp("can", T)
    problems = [GraspTarget(n, grasp.contacts, spec) for n in ("first", "second")]
    items = [(p, spec, spec.key()) for p in problems]
    entries = [e for chunk in solve_chunks(hand, items, IKSettings()) for e in chunk]
    assert isinstance(entries[0], dict) and isinstance(entries[1], dict)
    assert entries[0]["setup_ms"] >= 400.0 > entries[0]["time_ms"]
    assert entries[1]["setup_ms"] < 400.0  # the second problem reuses the object
    summary = results_document("sah", entries)["summary"]  # type: ignore[arg-type]
    assert summary["setup_ms"] == pytest.approx(entries[0]["setup_ms"] + entries[1]["setup_ms"])
    assert summary["median_time_ms"] < 400.0


@pytest.mark.slow
def test_solve_lines_and_its_bar_do_not_interleave_on_a_terminal(files: Path) -> None:
    """On a terminal each problem's line starts on a cleared line; off one, no bar at all."""
    import fcntl
    import pty
    import struct
    import termios

    leader, follower = pty.openpty()
    fcntl.ioctl(follower, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # 100 columns
    try:
        run = subprocess.Popen(
            [sys.executable, "-m", "sahgrasp", "solve", "many.json", "--inits", "1", "--json",
             os.devnull], stdout=follower, stderr=follower, cwd=files,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
        )  # fmt: skip
        os.close(follower)
        chunks = []
        while True:
            try:
                data = os.read(leader, 65536)
            except OSError:  # the other side is closed
                break
            if not data:
                break
            chunks.append(data)
        run.wait(timeout=300)
    finally:
        os.close(leader)
    screen = b"".join(chunks).decode("utf-8", "replace")
    names = {p["name"] for p in json.loads((files / "many.json").read_text())["problems"]}
    lines = [line for line in screen.split("\n") if re.search(r": (solved|FAILED)", line)]
    assert len(lines) == 60, screen[-2000:]
    for line in lines:  # what follows the last carriage return is the problem's line alone
        assert line.rstrip("\r").rsplit("\r", 1)[-1].split(":")[0] in names, repr(line)
    piped = sahgrasp("solve", "many.json", "--inits", "1", "--json", os.devnull, cwd=files)
    assert "\r" not in piped.stderr and "\r" not in piped.stdout


def test_the_sequence_summary_says_what_its_columns_are(capsys: pytest.CaptureFixture[str]) -> None:
    import numpy as np

    from sahgrasp.cli import sequence as command

    round_ = argparse.Namespace(
        index=1, lambdas=(0.444, 0.556), success_rates=np.array([0.5, 0.763]),
        prior_success_rate=0.0, scanned=300,
    )  # fmt: skip
    result = argparse.Namespace(
        rounds=[round_], cells_computed=9, ik_runs_computed=2700, wall_seconds=1.0
    )
    command._print_summary(result, "out")  # type: ignore[arg-type]
    header, row = capsys.readouterr().out.splitlines()[:2]
    for column in ("round", "chosen pose solves [%]", "earlier poses solved [%]", "scanned"):
        assert column in header
    assert "E_i" not in header and "SEQ" not in header
    assert row.split() == ["1", "0.444", "0.556", "76.3", "0.0", "300"]
