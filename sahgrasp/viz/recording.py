"""A meshcat window without a server: commands are kept in-process and exported as static HTML.

``meshcat.Visualizer(window=RecordingWindow())`` accepts every meshcat command (and so Pinocchio's
``MeshcatVisualizer``) without starting meshcat's zmq server subprocess or opening a port. The
window keeps the scene tree as meshcat's server does (the latest object, transform, properties and
animation of each path) and ``meshcat.Visualizer.static_html()`` returns the same standalone page
the server's ``get_scene`` would: meshcat's viewer script and one drawing command per entry.
:func:`scene_commands` reads those commands back from a page.
"""

from __future__ import annotations

import base64
import re
from pathlib import Path
from typing import Any

import umsgpack
from meshcat.servers.tree import SceneTree, find_node, walk
from meshcat.servers.zmqserver import VIEWER_ROOT, create_command

__all__ = ["RecordingWindow", "scene_commands"]

_COMMAND = re.compile(r'fetch\("data:application/octet-binary;base64,([A-Za-z0-9+/=]+)"\)')

_PAGE = """<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>{title}</title></head>
<body>
<div id="meshcat-pane"></div>
<script>{viewer_js}</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
{commands}
</script>
<style>body {{margin: 0;}} #meshcat-pane {{width: 100vw; height: 100vh; overflow: hidden;}}</style>
</body>
</html>
"""


class RecordingWindow:
    """Stands in for ``meshcat.visualizer.ViewerWindow``: records instead of sending to a server.

    Args:
        title: Title of the exported HTML page.
    """

    web_url = None
    """No URL: nothing is served."""

    def __init__(self, title: str = "sahgrasp") -> None:
        self.title = title
        self._tree = SceneTree()

    def send(self, command: Any) -> None:
        """Apply a meshcat command (``SetObject``, ``SetTransform``, ...) to the recorded tree."""
        data = command.lower()
        kind = data["type"]
        path = [p for p in data["path"].split("/") if p]
        packed = umsgpack.packb(data)
        if kind == "delete":
            self._delete(path)
            return
        node = find_node(self._tree, path)
        if kind == "set_object":
            node.object, node.properties = packed, []
        elif kind == "set_transform":
            node.transform = packed
        elif kind == "set_property":
            node.properties.append(packed)
        elif kind == "set_animation":
            node.animation = packed
        else:
            raise ValueError(f"meshcat command {kind!r} cannot be recorded")

    def _delete(self, path: list[str]) -> None:
        if not path:
            self._tree = SceneTree()
            return
        parent = find_node(self._tree, path[:-1])
        parent.pop(path[-1], None)

    def get_scene(self) -> str:
        """Return the recorded scene as a standalone HTML page (meshcat's viewer inlined)."""
        commands = []
        for node in walk(self._tree):
            for packed in (node.object, *node.properties, node.transform, node.animation):
                if packed is not None:
                    commands.append(create_command(packed))
        viewer_js = (Path(VIEWER_ROOT) / "main.min.js").read_text(encoding="utf-8")
        return _PAGE.format(title=self.title, viewer_js=viewer_js, commands="".join(commands))


def scene_commands(html: str) -> list[dict[str, Any]]:
    """The meshcat commands of an exported page, decoded (``type``, ``path``, ...), in order."""
    return [umsgpack.unpackb(base64.b64decode(data)) for data in _COMMAND.findall(html)]
