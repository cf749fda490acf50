"""The search's checkpoint: what is done, on disk, so that a killed search loses only what ran.

``DIR/checkpoint/`` holds

* ``header.json`` -- the hand (name and digest), the settings that determine the result, and the
  PCA basis the lambdas refer to; written once when the search starts;
* ``round-NNN.json`` -- one per round started: the round's problems (as found so far by screening)
  and every grid cell finished, with its number of solved problems. It is rewritten, atomically,
  each time a screening wave or a cell finishes.

Every file carries the digest of the hand and settings, so a file from another search is refused,
as is anything malformed (the message names the file and the field), with
:class:`SequenceFileError`: bad JSON, NaN or infinite numbers, fields of the wrong type, a basis of
the wrong shape or not orthonormal, counts out of range, problems out of order, a missing round
file. Nothing is trusted because it parses.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sahgrasp.core.errors import SequenceFileError
from sahgrasp.core.fileio import write_json_atomic
from sahgrasp.ik import PoseBasis
from sahgrasp.sequence.folder import CHECKPOINT, HEADER, RESULTS

__all__ = ["CellOutcome", "Checkpoint", "RoundState", "refuse_leftovers"]

FORMAT = "sahgrasp-search-checkpoint-1"


@dataclass(frozen=True)
class CellOutcome:
    """A finished grid cell: how many of the round's problems its initial pose solved.

    Attributes:
        solved: Problems solved with that single initial configuration.
        seconds: Worker time spent on it [s].
    """

    solved: int
    seconds: float


@dataclass(frozen=True)
class RoundState:
    """What is known of one round of the greedy search.

    Attributes:
        index: Round ``i``, from 1.
        start: First problem index screened in this round.
        scanned: Problems ``start .. scanned - 1`` have been screened.
        problems: Those of them the sequence chosen so far does not solve, in order (the round's
            problems once there are ``M``).
        cells: Finished grid cells by flat index ``j * N + k``.
        screen_runs: Initial configurations tried while screening.
        screen_seconds: Worker time spent screening [s].
    """

    index: int
    start: int
    scanned: int
    problems: tuple[int, ...] = ()
    cells: Mapping[int, CellOutcome] = field(default_factory=dict)
    screen_runs: int = 0
    screen_seconds: float = 0.0

    def with_cell(self, cell: int, outcome: CellOutcome) -> RoundState:
        """This state with ``cell`` finished."""
        return replace(self, cells={**self.cells, cell: outcome})

    def to_dict(self) -> dict[str, Any]:
        """JSON form (without the identity fields the checkpoint adds)."""
        return {
            "round": self.index,
            "start": self.start,
            "scanned": self.scanned,
            "problems": list(self.problems),
            "cells": {str(c): [o.solved, o.seconds] for c, o in sorted(self.cells.items())},
            "screen_runs": self.screen_runs,
            "screen_seconds": self.screen_seconds,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], cells: int, problems: int) -> RoundState:
        """Parse and check the JSON form for a grid of ``cells`` cells and ``problems`` M.

        Raises:
            ValueError: The data is not a consistent round (the message names the field).
        """
        chosen = _field(data, "problems", list)
        finished = _field(data, "cells", dict)
        state = cls(
            index=_int(_field(data, "round"), "round", 1),
            start=_int(_field(data, "start"), "start", 0),
            scanned=_int(_field(data, "scanned"), "scanned", 0),
            problems=tuple(_int(p, "problems[]", 0) for p in chosen),
            cells=dict(_cell(key, value, cells, problems) for key, value in finished.items()),
            screen_runs=_int(_field(data, "screen_runs"), "screen_runs", 0),
            screen_seconds=_seconds(_field(data, "screen_seconds"), "screen_seconds"),
        )
        state._check(problems)
        return state

    def _check(self, problems: int) -> None:
        chosen = self.problems
        if chosen and (
            chosen[0] < self.start
            or chosen[-1] >= self.scanned
            or any(a >= b for a, b in itertools.pairwise(chosen))
        ):
            raise ValueError("field 'problems' must increase strictly, within start .. scanned - 1")
        if self.scanned < self.start or len(chosen) > problems:
            raise ValueError(
                f"field 'problems' holds more than {problems} problems, or scanned < start"
            )
        if self.cells and len(chosen) != problems:
            raise ValueError(
                "field 'cells' has cells finished before the round's problems are complete"
            )


def _field(data: dict[str, Any], name: str, kind: type | None = None) -> Any:
    """``data[name]``, which must exist (and be a ``kind``)."""
    if name not in data:
        raise ValueError(f"field {name!r} is missing")
    value = data[name]
    if kind is not None and not isinstance(value, kind):
        raise ValueError(f"field {name!r} must be a JSON {_JSON_NAMES[kind]}, got {_show(value)}")
    return value


_JSON_NAMES: dict[type, str] = {list: "array", dict: "object", str: "string"}


def _show(value: Any, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 3]}..."


def _int(value: Any, name: str, lower: int, upper: int | None = None) -> int:
    if (
        not isinstance(value, int)
        or isinstance(value, bool)
        or value < lower
        or (upper is not None and value > upper)
    ):
        valid = f">= {lower}" if upper is None else f"in {lower} .. {upper}"
        raise ValueError(f"field {name!r} must be an integer {valid}, got {_show(value)}")
    return value


def _seconds(value: Any, name: str) -> float:
    if not _finite(value) or value < 0:
        raise ValueError(f"field {name!r} must be a time >= 0 s, got {_show(value)}")
    return float(value)


def _cell(key: str, value: Any, cells: int, problems: int) -> tuple[int, CellOutcome]:
    """One entry ``"flat index": [solved, seconds]`` of a round's ``cells``."""
    name = f"cells.{key}"
    if not (key.isdigit() and str(int(key)) == key and int(key) < cells):
        raise ValueError(f"field {name!r}: cell indices are 0 .. {cells - 1}, written plainly")
    if not isinstance(value, list) or len(value) != 2:
        raise ValueError(f"field {name!r} must be [solved, seconds], got {_show(value)}")
    return int(key), CellOutcome(_int(value[0], name, 0, problems), _seconds(value[1], name))


def _basis(data: Any, size: int) -> PoseBasis:
    """The PCA basis of a header: ``size`` values per pose, orthonormal directions, sigmas > 0."""
    if not isinstance(data, dict):
        raise ValueError(f"field 'basis' must be a JSON object, got {_show(data)}")
    mean = _array(data, "mean", (size,))
    directions = _array(data, "directions", (2, size))
    sigmas = _array(data, "sigmas", (2,))
    if not np.allclose(directions @ directions.T, np.eye(2), rtol=0.0, atol=1e-9):
        raise ValueError("field 'basis.directions' must hold 2 orthonormal directions")
    if not np.all(sigmas > 0.0):
        raise ValueError("field 'basis.sigmas' must be > 0")
    return PoseBasis(mean, directions, sigmas)


def _array(data: dict[str, Any], name: str, shape: tuple[int, ...]) -> NDArray[np.float64]:
    """``data[name]``: nested JSON arrays of finite numbers (no booleans, strings) of ``shape``."""
    values = np.asarray(data.get(name), dtype=object)  # ragged lists stay lists: refused below
    if values.shape != shape or not all(_finite(x) for x in values.flat):
        wanted = " x ".join(map(str, shape))
        raise ValueError(f"field 'basis.{name}' must be {wanted} finite numbers")
    return values.astype(np.float64)


def _finite(value: Any) -> bool:
    """Whether ``value`` is a JSON number that is a finite float."""
    if type(value) is int:  # bool is not int here; huge integers would not fit a float
        return abs(value) < 2**63
    return type(value) is float and math.isfinite(value)


class Checkpoint:
    """The checkpoint folder of one search (module docstring).

    Build it with :meth:`create` or :meth:`open`, while holding the output folder's lock
    (:func:`sahgrasp.sequence.folder.locked_folder`).

    Attributes:
        folder: ``DIR/checkpoint``.
        basis: The PCA basis of the search.
        rounds: The rounds recorded, in order.
    """

    def __init__(
        self,
        folder: Path,
        identity: dict[str, Any],
        basis: PoseBasis,
        shape: tuple[int, int],
        rounds: list[RoundState],
    ) -> None:
        self.folder = folder
        self.basis = basis
        self.rounds = rounds
        self._key = _key(identity)
        self._shape = shape

    @classmethod
    def create(
        cls, out_dir: Path, identity: dict[str, Any], basis: PoseBasis, shape: tuple[int, int]
    ) -> Checkpoint:
        """Start the checkpoint of a new search in ``out_dir``.

        Args:
            out_dir: The search's output folder.
            identity: What makes two searches the same (hand, digest, settings); JSON-able.
            basis: The PCA basis of the search.
            shape: ``(N^2 cells, M problems)``, to check the rounds against.

        Raises:
            SequenceFileError: ``out_dir`` already holds a search, or what is left of one.
        """
        refuse_leftovers(out_dir)
        checkpoint = cls(out_dir / CHECKPOINT, identity, basis, shape, [])
        header = {"format": FORMAT, **identity, "key": checkpoint._key, "basis": basis.to_dict()}
        checkpoint.folder.mkdir(exist_ok=True)
        write_json_atomic(checkpoint.folder / HEADER, header)
        return checkpoint

    @classmethod
    def open(
        cls, out_dir: Path, identity: dict[str, Any], shape: tuple[int, int], basis_size: int
    ) -> Checkpoint:
        """Read the checkpoint in ``out_dir`` of a search with this ``identity``.

        Args:
            out_dir: The search's output folder.
            identity: As for :meth:`create`.
            shape: As for :meth:`create`.
            basis_size: Values per pose of the hand's PCA basis (the length of ``Q``).

        Raises:
            SequenceFileError: Missing, corrupted, or made by a search with another identity.
        """
        path = out_dir / CHECKPOINT / HEADER
        header = _read(path)
        stored = {k: header.get(k) for k in identity}
        if header.get("format") == FORMAT and stored != identity:
            raise SequenceFileError(
                f"{out_dir} holds a search of another hand or settings: {path} has "
                f"{_differences(stored, identity)}; use the same settings or another --out"
            )
        try:
            if _field(header, "format") != FORMAT:
                raise ValueError(f"field 'format' must be {FORMAT!r}")
            if _field(header, "key") != _key(identity):
                raise ValueError("field 'key' is not the digest of the hand and settings")
            basis = _basis(_field(header, "basis"), basis_size)
        except ValueError as exc:
            raise _corrupted(path, exc) from exc
        checkpoint = cls(path.parent, identity, basis, shape, [])
        checkpoint.rounds = checkpoint._read_rounds()
        return checkpoint

    def save(self, state: RoundState) -> None:
        """Record ``state`` (a new round, or progress in the last one), atomically."""
        if state.index <= len(self.rounds):
            self.rounds[state.index - 1] = state
        else:
            self.rounds.append(state)
        data = {"format": FORMAT, "key": self._key, **state.to_dict()}
        write_json_atomic(self.folder / _round_name(state.index), data)

    def _read_rounds(self) -> list[RoundState]:
        rounds: list[RoundState] = []
        cells, problems = self._shape
        for index, path in enumerate(_round_files(self.folder), start=1):
            data = _read(path)
            try:
                if data.get("format") != FORMAT or data.get("key") != self._key:
                    raise ValueError("it belongs to another search (fields 'format', 'key')")
                state = RoundState.from_dict(data, cells, problems)
                if path.name != _round_name(state.index):
                    raise ValueError(f"field 'round' is {state.index}, not that of the file name")
                _check_follows(rounds[-1] if rounds else None, state, index, cells, problems)
            except ValueError as exc:
                raise _corrupted(path, exc) from exc
            rounds.append(state)
        return rounds


def refuse_leftovers(out_dir: Path) -> None:
    """Raise :class:`SequenceFileError` if a new search in ``out_dir`` would overwrite one.

    A header means a search to resume. Round files or results without a header are what is left
    of a search whose header was deleted: its PCA basis is lost, so that search can be neither
    trusted nor continued, and a new one must not overwrite it either.
    """
    folder = out_dir / CHECKPOINT
    if (folder / HEADER).exists():
        raise SequenceFileError(
            f"{out_dir} already holds a search; resume it (--resume) or choose another --out"
        )
    left = [p.name for p in _round_files(folder)] + [n for n in RESULTS if (out_dir / n).exists()]
    if left:
        raise SequenceFileError(
            f"{out_dir} holds files of a search ({', '.join(left[:4])}) but no "
            f"{CHECKPOINT}/{HEADER}: its settings and PCA basis are lost, so it cannot be "
            f"resumed; restore {HEADER}, delete those files, or choose another --out"
        )


def _round_name(index: int) -> str:
    return f"round-{index:03d}.json"


def _round_files(folder: Path) -> list[Path]:
    """Every ``round-*.json`` in ``folder``, in round order (misnamed ones first: refused)."""
    return sorted(folder.glob("round-*.json"), key=lambda p: (len(p.name), p.name))


def _key(identity: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()


def _check_follows(
    previous: RoundState | None, state: RoundState, index: int, cells: int, problems: int
) -> None:
    """Raise ValueError unless ``state`` is round ``index``, the round after ``previous``."""
    if state.index != index:
        raise ValueError(f"field 'round' is {state.index} but round {index} is missing")
    if previous is None:
        if state.start != 0:
            raise ValueError("field 'start' of round 1 must be 0")
        return
    if len(previous.cells) != cells or len(previous.problems) != problems:
        raise ValueError(f"round {previous.index} is unfinished but round {state.index} exists")
    if state.start != previous.problems[-1] + 1:
        raise ValueError(f"field 'start' does not follow round {previous.index}'s last problem")


def _read(path: Path) -> dict[str, Any]:
    if path.exists() and not path.is_file():  # a folder, or a FIFO that would block the read
        raise _corrupted(path, ValueError("not a regular file"))
    try:
        data = json.loads(path.read_bytes().decode("utf-8"), parse_constant=_no_constant)
    except FileNotFoundError as exc:
        raise SequenceFileError(f"checkpoint file {path} is missing; {_START_OVER}") from exc
    except (OSError, ValueError, RecursionError) as exc:  # JSON and UTF-8 errors are ValueErrors
        raise _corrupted(path, exc) from exc
    if not isinstance(data, dict):
        raise _corrupted(path, ValueError("not a JSON object"))
    return data


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number a checkpoint can hold")


def _corrupted(path: Path, exc: BaseException) -> SequenceFileError:
    reason = str(exc) if type(exc) is ValueError else f"{type(exc).__name__}: {exc}"
    return SequenceFileError(f"checkpoint file {path} is unusable ({reason}); {_START_OVER}")


_START_OVER = "restore it, or start the search over in another --out (or in an emptied folder)"


def _differences(stored: dict[str, Any], wanted: dict[str, Any]) -> str:
    diffs = [
        f"{key} {_show(stored.get(key), 400)} (this run: {wanted[key]!r})"
        for key in wanted
        if stored.get(key) != wanted[key]
    ]
    return "; ".join(diffs)
