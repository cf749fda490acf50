"""The search's checkpoint: what is done, on disk, so that a killed search loses only what ran.

``DIR/checkpoint/`` holds

* ``header.json`` -- the hand (name and digest), the settings that determine the result, and the
  PCA basis the lambdas refer to; written once when the search starts;
* ``round-NNN.json`` -- one per round started: the round's problems (as found so far by screening)
  and every grid cell finished, with its number of solved problems. It is rewritten, atomically,
  each time a screening wave or a cell finishes.

Every file carries the digest of the hand and settings, so a file from another search is refused,
as is anything malformed, with :class:`SequenceFileError`.
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

from sahgrasp.errors import SequenceFileError
from sahgrasp.fileio import write_json_atomic
from sahgrasp.ik import PoseBasis

__all__ = ["CellOutcome", "Checkpoint", "RoundState", "remove_stale_temporaries"]

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
            ValueError: The data is not a consistent round.
        """
        state = cls(
            index=_int(data["round"], 1),
            start=_int(data["start"], 0),
            scanned=_int(data["scanned"], 0),
            problems=tuple(_int(p, 0) for p in data["problems"]),
            cells={
                _int(int(c), 0, cells - 1): CellOutcome(_int(s, 0, problems), _seconds(t))
                for c, (s, t) in data["cells"].items()
            },
            screen_runs=_int(data["screen_runs"], 0),
            screen_seconds=_seconds(data["screen_seconds"]),
        )
        chosen = state.problems
        if chosen and (
            chosen[0] < state.start
            or chosen[-1] >= state.scanned
            or any(a >= b for a, b in itertools.pairwise(chosen))
        ):
            raise ValueError("problems must increase strictly, within start .. scanned - 1")
        if state.scanned < state.start or len(chosen) > problems:
            raise ValueError(f"at most {problems} problems between start and scanned")
        if state.cells and len(state.problems) != problems:
            raise ValueError("cells are finished before the round's problems are complete")
        return state


def _int(value: Any, lower: int, upper: int | None = None) -> int:
    if not isinstance(value, int) or isinstance(value, bool):
        raise ValueError(f"expected an integer, got {value!r}")
    if value < lower or (upper is not None and value > upper):
        raise ValueError(f"{value} is outside {lower} .. {upper}")
    return value


def _seconds(value: Any) -> float:
    seconds = float(value)
    if not math.isfinite(seconds) or seconds < 0.0:
        raise ValueError(f"expected a time >= 0 s, got {value!r}")
    return seconds


def remove_stale_temporaries(folder: Path) -> None:
    """Delete temporary files left in ``folder`` by an atomic write that was killed."""
    for tmp in folder.glob(".*.tmp"):
        tmp.unlink(missing_ok=True)


class Checkpoint:
    """The checkpoint folder of one search (module docstring).

    Build it with :meth:`create` or :meth:`open`.

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
        self._identity = identity
        self._key = hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()
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
            SequenceFileError: ``out_dir`` already holds a search.
        """
        folder = out_dir / "checkpoint"
        if (folder / "header.json").exists():
            raise SequenceFileError(
                f"{out_dir} already holds a search; resume it (--resume) or choose another --out"
            )
        checkpoint = cls(folder, identity, basis, shape, [])
        header = {"format": FORMAT, **identity, "key": checkpoint._key, "basis": basis.to_dict()}
        write_json_atomic(folder / "header.json", header)
        return checkpoint

    @classmethod
    def open(cls, out_dir: Path, identity: dict[str, Any], shape: tuple[int, int]) -> Checkpoint:
        """Read the checkpoint in ``out_dir`` of a search with this ``identity``.

        Raises:
            SequenceFileError: Missing, corrupted, or made by a search with another identity.
        """
        folder = out_dir / "checkpoint"
        header = _read(folder / "header.json")
        try:
            if header["format"] != FORMAT:
                raise ValueError(f"format is not {FORMAT}")
            stored = {k: header[k] for k in identity}
            basis = PoseBasis.from_dict(header["basis"])
            if basis.directions.shape != (2, basis.mean.size) or basis.sigmas.shape != (2,):
                raise ValueError("the basis needs a mean, 2 directions and 2 sigmas")
        except (KeyError, TypeError, ValueError) as exc:
            raise _corrupted(folder / "header.json", exc) from exc
        if stored != identity:
            raise SequenceFileError(
                f"{out_dir} holds a search of another hand or settings: it has "
                f"{_differences(stored, identity)}; use the same settings or another --out"
            )
        remove_stale_temporaries(folder)
        checkpoint = cls(folder, identity, basis, shape, [])
        checkpoint.rounds = checkpoint._read_rounds()
        return checkpoint

    def save(self, state: RoundState) -> None:
        """Record ``state`` (a new round, or progress in the last one), atomically."""
        if state.index <= len(self.rounds):
            self.rounds[state.index - 1] = state
        else:
            self.rounds.append(state)
        data = {"format": FORMAT, "key": self._key, **state.to_dict()}
        write_json_atomic(self.folder / f"round-{state.index:03d}.json", data)

    def _read_rounds(self) -> list[RoundState]:
        rounds: list[RoundState] = []
        cells, problems = self._shape
        for path in sorted(self.folder.glob("round-*.json")):
            data = _read(path)
            try:
                if data.get("format") != FORMAT or data.get("key") != self._key:
                    raise ValueError("it belongs to another search")
                state = RoundState.from_dict(data, cells, problems)
                previous = rounds[-1] if rounds else None
                _check_follows(previous, state, cells, problems)
            except (AttributeError, KeyError, TypeError, ValueError) as exc:
                raise _corrupted(path, exc) from exc
            rounds.append(state)
        return rounds


def _check_follows(
    previous: RoundState | None, state: RoundState, cells: int, problems: int
) -> None:
    """Raise ValueError unless ``state`` is the round after ``previous``."""
    if previous is None:
        if (state.index, state.start) != (1, 0):
            raise ValueError("the first round must be round 1, starting at problem 0")
        return
    if len(previous.cells) != cells or len(previous.problems) != problems:
        raise ValueError(f"round {previous.index} is unfinished but round {state.index} exists")
    if (state.index, state.start) != (previous.index + 1, previous.problems[-1] + 1):
        raise ValueError(f"round {state.index} does not follow round {previous.index}")


def _read(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise _corrupted(path, exc) from exc
    if not isinstance(data, dict):
        raise _corrupted(path, ValueError("not a JSON object"))
    return data


def _corrupted(path: Path, exc: Exception) -> SequenceFileError:
    return SequenceFileError(
        f"checkpoint file {path} is unusable ({type(exc).__name__}: {exc}); delete "
        f"{path.parent} to start the search over"
    )


def _differences(stored: dict[str, Any], wanted: dict[str, Any]) -> str:
    diffs = [
        f"{key} {stored.get(key)!r} (this run: {wanted[key]!r})"
        for key in wanted
        if stored.get(key) != wanted[key]
    ]
    return "; ".join(diffs)
