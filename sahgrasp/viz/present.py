"""How a script shows a scene: write standalone HTML, or serve it live until the user is done.

Scripts (the examples, ``sahgrasp demo``) build their scene in a function of a :class:`Viewer` and
call :func:`present` (``--html`` is :func:`sahgrasp.experiments.arguments.add_html_argument`);
it owns the viewer, so no meshcat server outlives the call.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from sahgrasp.viz.viewer import Viewer

__all__ = ["present"]


def present(
    build: Callable[[Viewer], None],
    html: str | None,
    title: str = "sahgrasp",
    host: str = "127.0.0.1",
) -> None:
    """Build a scene and show it.

    Args:
        build: Draws the scene into the viewer it is given.
        html: Write the scene to this HTML file (offline, no server). If None, start meshcat's
            server, open the browser, and stop the server when the user presses Enter (or the
            script ends, or gets SIGTERM or SIGHUP).
        title: Title of the HTML page.
        host: Interface the live server listens on (this machine only by default).
    """
    if html is not None:
        with Viewer(title=title) as viewer:
            build(viewer)
            out = viewer.save_html(Path(html))
        print(f"wrote {out} (open it in a web browser)")
        return
    with Viewer(live=True, host=host) as viewer:
        build(viewer)
        viewer.open()
        try:
            input(f"scene at {viewer.url} -- press Enter to stop the viewer ")
        except EOFError:
            print("no terminal input: stopping the viewer (use --html OUT to keep the scene)")
