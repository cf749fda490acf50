"""meshcat's zmq/web server bound to one interface, ending when the process that started it ends.

meshcat 0.3.2's server listens for browsers on every interface (``0.0.0.0:7000``) and outlives a
parent that is killed. This script runs the same server with the web port bound to ``HOST``
(``127.0.0.1`` unless asked) and exits as soon as its parent (``PARENT_PID``) is gone: at once on
Linux (``PR_SET_PDEATHSIG``), within half a second elsewhere (a poll of the parent process id).

:class:`sahgrasp.viz.Viewer` starts it by file path (``python -u meshcat_server.py HOST
PARENT_PID``), so the server imports meshcat only, not the toolkit. It prints ``zmq_url=...`` and
``web_url=...`` as meshcat's server does.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import sys
from collections.abc import Sequence
from typing import Any

_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
_PARENT_POLL_MS = 500


def _local_bridge(host: str) -> Any:
    """Meshcat's bridge with its web server listening on ``host`` only (upstream: all).

    meshcat and tornado are imported here, after the parent-death request: they take a second.
    """
    from meshcat.servers.zmqserver import ZMQWebSocketBridge

    class LocalBridge(ZMQWebSocketBridge):
        def make_app(self) -> Any:
            app = super().make_app()  # self.host is set before the app is made
            listen = app.listen
            app.listen = lambda port, **kwargs: listen(port, address=self.host, **kwargs)
            return app

    return LocalBridge(host=host)


def _die_with_parent(parent: int) -> None:
    """Ask the kernel (Linux) for SIGTERM when ``parent`` ends; exit if it already has."""
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    if os.getppid() != parent:  # the parent died before the request above took effect
        sys.exit(0)


def _poll_parent(parent: int) -> None:
    """End this process within ``_PARENT_POLL_MS`` of ``parent``'s end (where no kernel signal)."""
    from tornado.ioloop import PeriodicCallback

    def check() -> None:
        if os.getppid() != parent:
            os.kill(os.getpid(), signal.SIGTERM)

    PeriodicCallback(check, _PARENT_POLL_MS).start()


def main(argv: Sequence[str] | None = None) -> int:
    """Serve until the parent ends or a signal arrives (arguments: ``HOST PARENT_PID``)."""
    words = list(sys.argv[1:] if argv is None else argv)
    if len(words) != 2 or not words[1].isdigit():
        print("usage: meshcat_server.py HOST PARENT_PID", file=sys.stderr)
        return 2
    host, parent = words[0], int(words[1])
    _die_with_parent(parent)
    bridge = _local_bridge(host)
    _poll_parent(parent)
    print(f"zmq_url={bridge.zmq_url}")
    print(f"web_url={bridge.web_url}", flush=True)
    # Nobody reads the pipe after these lines: later output must not fill it and block us.
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    bridge.run()
    return 0


if __name__ == "__main__":
    sys.exit(main())
