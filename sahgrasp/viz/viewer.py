"""A meshcat scene: offline (recorded in-process) or live (meshcat's server), exported as HTML.

``Viewer()`` records the scene in-process: no server, no port, nothing left running; ``save_html``
writes the standalone page. ``Viewer(live=True)`` starts meshcat's zmq/web server subprocess
(:mod:`sahgrasp.viz.meshcat_server`, listening on ``127.0.0.1`` unless another ``host`` is given)
so that a browser can watch the scene while it is built. The server ends with the viewer: on
:meth:`Viewer.close` (or leaving the ``with`` block, also on an exception), at interpreter exit, on
SIGTERM or SIGHUP (the viewer's handlers close it, then hand the signal to the handlers they
replaced), and on its own when the process that started it dies, even by SIGKILL. Either way
``meshcat.Visualizer.static_html()`` gives the page.

The scene shows metres in the ``world`` frame, z up, on a light background without meshcat's grid
and axes. One meshcat animation holds every keyframe added with :meth:`Viewer.keyframe`.
"""

from __future__ import annotations

import atexit
import math
import os
import signal
import subprocess
import sys
import tempfile
import threading
import webbrowser
from contextlib import suppress
from pathlib import Path
from types import FrameType, TracebackType
from typing import IO, Any

import meshcat
import meshcat.animation
import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp.core.errors import SahGraspError
from sahgrasp.core.fileio import write_bytes_atomic
from sahgrasp.viz.recording import RecordingWindow

__all__ = ["CAMERA_FOV_DEG", "CLEANUP_SIGNALS", "Viewer", "ViewerError", "translation"]

_CAMERA = "/Cameras/default/rotated/<object>"
_BACKGROUND_TOP = [1.0, 1.0, 1.0]
_BACKGROUND_BOTTOM = [0.86, 0.87, 0.9]
CAMERA_FOV_DEG = 35.0
"""Vertical field of view of the camera (meshcat's default 75 deg distorts close scenes)."""
_HALF_FOV_RAD = math.radians(0.5 * CAMERA_FOV_DEG)
_VIEW_DIRECTION = (1.0, -1.2, 0.8)
_MIN_FRAME_DISTANCE_M = 0.1
_FRAME_MARGIN = 1.15
_SERVER_SCRIPT = Path(__file__).with_name("meshcat_server.py")

CLEANUP_SIGNALS: tuple[signal.Signals, ...] = tuple(
    getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name)
)
"""Signals on which a live viewer stops its server before the previous handler runs."""


class ViewerError(SahGraspError):
    """The live viewer's server could not start (bad host, no free port)."""


def translation(offset_m: ArrayLike) -> NDArray[np.float64]:
    """The 4x4 placement translating by ``offset_m`` [m]."""
    T = np.eye(4)
    T[:3, 3] = np.asarray(offset_m, dtype=np.float64)
    return T


def _spawn_server(host: str, errors: IO[bytes]) -> subprocess.Popen[bytes]:
    """Start the meshcat server on ``host``, its stderr into ``errors``.

    It runs in its own session (a Ctrl-C at the terminal reaches the script, which closes the
    viewer, not the server directly) and exits by itself when this process dies.
    """
    command = [sys.executable, "-u", str(_SERVER_SCRIPT), host, str(os.getpid())]
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=errors, start_new_session=True)


def _server_address(server: subprocess.Popen[bytes], errors: IO[bytes], host: str) -> str:
    """The zmq address the server prints once it listens.

    Raises:
        ViewerError: The server exited before giving its address (the message has its last line).
    """
    assert server.stdout is not None  # stdout=PIPE
    first = server.stdout.readline().decode("utf-8", "replace").strip()
    server.stdout.readline()  # web_url=..., asked from the server itself later
    if first.startswith("zmq_url="):
        return first.removeprefix("zmq_url=")
    errors.seek(0)
    lines = errors.read().decode("utf-8", "replace").strip().splitlines() or ["no output"]
    raise ViewerError(f"the meshcat server did not start on host {host!r}: {lines[-1][:200]}")


class Viewer:
    """A meshcat scene with HTML export; a context manager that stops any server it started.

    Args:
        live: Start meshcat's server subprocess (watch at :attr:`url`); otherwise record offline.
        title: Title of the exported HTML page.
        animation_fps: Keyframes per second of the scene's animation.
        host: Interface the live server listens on; ``127.0.0.1`` (this machine only) unless
            another one is asked for, e.g. ``0.0.0.0`` for every interface.

    Attributes:
        meshcat: The ``meshcat.Visualizer`` at the scene root (``/meshcat``).
        animation: The scene's animation; :meth:`keyframe` adds to it.

    Raises:
        ViewerError: The live server could not start.
    """

    def __init__(
        self,
        live: bool = False,
        title: str = "sahgrasp",
        animation_fps: float = 4.0,
        host: str = "127.0.0.1",
    ) -> None:
        self._closed = False
        self._server: subprocess.Popen[bytes] | None = None
        self._previous_handlers: dict[int, Any] = {}
        self._window: Any = RecordingWindow(title)
        if live:
            self._window = meshcat.visualizer.ViewerWindow(self._start(host), False, [])
        self.meshcat = meshcat.Visualizer(window=self._window)
        self.animation = meshcat.animation.Animation(default_framerate=animation_fps)
        self.meshcat["/Background"].set_property("top_color", _BACKGROUND_TOP)
        self.meshcat["/Background"].set_property("bottom_color", _BACKGROUND_BOTTOM)
        self.meshcat["/Grid"].set_property("visible", False)
        self.meshcat["/Axes"].set_property("visible", False)
        self.meshcat[_CAMERA].set_property("fov", CAMERA_FOV_DEG)

    # ----- lifetime -----------------------------------------------------------------------------
    @property
    def url(self) -> str | None:
        """Address of the live viewer, None when offline."""
        return self._window.web_url

    @property
    def server_pid(self) -> int | None:
        """Process id of meshcat's server subprocess, None when offline."""
        return None if self._server is None else self._server.pid

    def close(self) -> None:
        """Terminate the server subprocess (if any) and release its socket; idempotent."""
        if self._closed:
            return
        self._closed = True
        if self._server is None:
            return
        self._server.kill()
        self._server.wait()  # killed: returns at once
        if self._server.stdout is not None:
            self._server.stdout.close()
        if isinstance(self._window, meshcat.visualizer.ViewerWindow):  # else it failed to start
            self._window.zmq_socket.close(linger=0)
        self._unwatch_exit()

    def _start(self, host: str) -> str:
        """Start the server, watched from the start (its startup takes a second); its address."""
        with tempfile.TemporaryFile() as errors:
            self._server = _spawn_server(host, errors)
            self._watch_exit()
            try:
                return _server_address(self._server, errors, host)
            except ViewerError:
                self.close()
                raise

    def _watch_exit(self) -> None:
        """Close at interpreter exit and on :data:`CLEANUP_SIGNALS` (main thread only).

        A signal the process ignores (``nohup`` ignores SIGHUP) stays ignored.
        """
        atexit.register(self.close)
        if threading.current_thread() is threading.main_thread():
            for sig in CLEANUP_SIGNALS:
                if signal.getsignal(sig) != signal.SIG_IGN:
                    self._previous_handlers[sig] = signal.signal(sig, self._on_signal)

    def _unwatch_exit(self) -> None:
        """Put back the handlers replaced by :meth:`_watch_exit` if ours are still in place."""
        atexit.unregister(self.close)
        if threading.current_thread() is not threading.main_thread():
            return  # only the main thread may set handlers; ours then just delegate
        for sig, previous in self._previous_handlers.items():
            if signal.getsignal(sig) == self._on_signal:
                signal.signal(sig, previous)

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        """Kill the server, then let the signal do what it did before this viewer.

        Only the kill happens here: the handler may interrupt the main thread inside a read of
        the server's pipe, a zmq call or :meth:`close` itself, so the rest of the cleanup is left
        to :meth:`close` (the ``with`` block, ``atexit``) or to the end of the process.
        """
        if self._server is not None and not self._closed:
            with suppress(ProcessLookupError):
                os.kill(self._server.pid, signal.SIGKILL)
        previous = self._previous_handlers.get(signum, signal.SIG_DFL)
        if callable(previous):
            previous(signum, frame)
        else:  # SIG_DFL, or a handler not set from Python: end as the signal would have
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)

    def __enter__(self) -> Viewer:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def open(self) -> None:
        """Open the live viewer in the web browser (a live viewer only)."""
        if self.url is None:
            raise RuntimeError("an offline viewer has no URL; use save_html() and open the file")
        webbrowser.open(self.url, new=2)

    # ----- scene-wide settings ------------------------------------------------------------------
    def look_at(self, target_m: ArrayLike, eye_m: ArrayLike) -> None:
        """Place the camera at ``eye_m`` looking at (and orbiting about) ``target_m`` [m].

        meshcat 0.3.2 orbits about the origin of its scene, so the scene content (everything
        under ``/meshcat``) is shifted by ``-target_m`` and the camera placed at the offset.
        """
        target = np.asarray(target_m, dtype=np.float64)
        offset = np.asarray(eye_m, dtype=np.float64) - target
        self.meshcat.set_transform(translation(-target))
        # meshcat's camera node is y-up: world (x, y, z) is (x, z, -y) there.
        position = [float(offset[0]), float(offset[2]), float(-offset[1])]
        self.meshcat[_CAMERA].set_property("position", position)

    def frame(
        self, points_m: ArrayLike, direction: ArrayLike = _VIEW_DIRECTION, aspect: float = 1.0
    ) -> None:
        """Aim the camera from ``direction`` at ``points_m`` (N, 3), close enough to fill the view.

        Args:
            points_m: Points the view must hold [m].
            direction: From the points' centre towards the camera.
            aspect: Smallest width/height ratio of the window the view must fit.
        """
        points = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
        centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
        back = np.asarray(direction, dtype=np.float64)
        back = back / np.linalg.norm(back)
        right = np.cross([0.0, 0.0, 1.0], back)
        right = right / np.linalg.norm(right) if np.linalg.norm(right) > 1e-9 else np.eye(3)[0]
        up = np.cross(back, right)
        rel = points - centre
        tan_v = math.tan(_HALF_FOV_RAD)
        # Depth along the view axis that puts every point inside the horizontal and vertical fov.
        across = np.maximum(np.abs(rel @ right) / (aspect * tan_v), np.abs(rel @ up) / tan_v)
        need = rel @ back + across
        distance = max(_FRAME_MARGIN * float(need.max()), _MIN_FRAME_DISTANCE_M)
        self.look_at(centre, centre + distance * back)

    def keyframe(self, frame: int) -> meshcat.animation.AnimationFrameVisualizer:
        """Return a recorder of transforms at animation ``frame``; :meth:`play` sends them.

        ``viewer.keyframe(i)["hand/visuals/palm_0"].set_transform(T)`` moves that node at frame
        ``i`` (frames are ``1 / animation_fps`` seconds apart).
        """
        return self.animation.at_frame(self.meshcat, frame)

    def play(self) -> None:
        """Send the scene's animation (every keyframe so far); it plays once when loaded."""
        self.meshcat.set_animation(self.animation, play=True, repetitions=1)

    # ----- export -------------------------------------------------------------------------------
    def html(self) -> str:
        """The scene as a standalone HTML page (meshcat's ``static_html``)."""
        return str(self.meshcat.static_html())

    def save_html(self, path: str | os.PathLike[str]) -> Path:
        """Write :meth:`html` to ``path`` atomically; returns the path."""
        out = Path(path)
        write_bytes_atomic(out, self.html().encode("utf-8"))
        return out
