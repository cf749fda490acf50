"""Progress reports of long computations, and a terminal bar that draws them on stderr.

Engines (the atlas builder, the benchmarks) take an optional :data:`ProgressCallback` and never
draw anything themselves; a front end passes :class:`StderrProgress` (tqdm bars on stderr, so that
stdout keeps only results) or its own callback, or nothing to stay quiet.
"""

from __future__ import annotations

import sys
from typing import IO, Any, Protocol

__all__ = ["ProgressCallback", "StderrProgress"]


class ProgressCallback(Protocol):
    """``progress(stage, done, total)``: ``done`` of ``total`` units (None: unknown) in ``stage``.

    ``stage`` names what is counted (``"atlas charts"``, ``"bench ik: problems"``); a new stage
    starts a new count. ``done`` only grows within a stage.
    """

    def __call__(self, stage: str, done: int, total: int | None) -> None:
        """Report ``done`` of ``total`` units in ``stage``."""


class StderrProgress:
    """A :data:`ProgressCallback` drawing one tqdm bar per stage on a stream (stderr by default).

    Bars are drawn on a terminal only: on a stream that is not one (a log file, a pipe) nothing
    is written, so that logs hold no carriage returns. Use it as a context manager, or call
    :meth:`close`, to end the last bar cleanly.

    Args:
        stream: Where the bars go.
    """

    def __init__(self, stream: IO[str] | None = None) -> None:
        self._stream = stream
        self._stage: str | None = None
        self._bar: Any = None

    def __call__(self, stage: str, done: int, total: int | None) -> None:
        """Move the stage's bar to ``done`` of ``total``; a new stage closes the previous bar."""
        if stage != self._stage:
            self.close()
            from tqdm import tqdm  # only front ends draw: imported when a bar is first needed

            self._stage = stage
            self._bar = tqdm(
                desc=stage, total=total, file=self._stream or sys.stderr, leave=True, disable=None
            )
        self._bar.total = total
        self._bar.update(done - self._bar.n)

    def close(self) -> None:
        """End the current bar (idempotent)."""
        if self._bar is not None:
            self._bar.close()
        self._bar, self._stage = None, None

    def __enter__(self) -> StderrProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
