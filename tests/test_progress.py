"""Progress bars: drawn on a terminal, never written into a log or a pipe."""

from __future__ import annotations

import io

from sahgrasp.core.progress import StderrProgress


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_no_bar_and_no_carriage_return_off_a_terminal() -> None:
    log = io.StringIO()
    with StderrProgress(log) as bar:
        for done in range(1, 4):
            bar("stage", done, 3)
        bar("open-ended", 5, None)
    assert log.getvalue() == ""


def test_bars_on_a_terminal() -> None:
    screen = _Terminal()
    with StderrProgress(screen) as bar:
        bar("stage", 3, 3)
    assert "stage: 100%" in screen.getvalue() and "\r" in screen.getvalue()
