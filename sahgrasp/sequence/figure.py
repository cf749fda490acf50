"""Fig. 4 of Claret & Suárez: the success-rate maps ``E_i`` of the search, one per round."""

from __future__ import annotations

import io
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

__all__ = ["success_maps_png"]


def success_maps_png(
    maps: Sequence[NDArray[np.float64]], chosen: Sequence[tuple[float, float]], title: str
) -> bytes:
    """A PNG with a grid of heat maps ``E_i[j, k]``, lambda^1 across and lambda^2 up.

    Each map has its own colour scale (dark red: that round's highest rate, as in the paper),
    and a cross marks the cell chosen in that round.

    Args:
        maps: ``E_i`` per round, each (N, N) with ``[j, k]`` for ``(lambda^1_j, lambda^2_k)``.
        chosen: The chosen ``(lambda^1, lambda^2)`` per round.
        title: Figure title.
    """
    from matplotlib.figure import Figure  # imported here: workers never draw, and it is slow

    columns = min(len(maps), 4)
    rows = math.ceil(len(maps) / columns)
    fig = Figure(figsize=(3.2 * columns, 2.9 * rows + 0.4), layout="constrained")
    fig.suptitle(title)
    axes = fig.subplots(rows, columns, squeeze=False)
    for ax in axes.flat[len(maps) :]:
        ax.set_axis_off()
    for i, (rates, (l1, l2), ax) in enumerate(zip(maps, chosen, axes.flat, strict=False), 1):
        half = 0.5 / (rates.shape[0] - 1)
        image = ax.imshow(
            100.0 * rates.T, origin="lower", cmap="jet", interpolation="nearest",
            extent=(-half, 1.0 + half, -half, 1.0 + half),
        )  # fmt: skip
        ax.plot([l1], [l2], marker="x", color="white", markersize=8, markeredgewidth=2)
        ax.set_title(f"$E_{{{i}}}$, best {100.0 * rates.max():.1f} %", fontsize=10)
        ax.set_xlabel(r"$\lambda^1$")
        ax.set_ylabel(r"$\lambda^2$")
        fig.colorbar(image, ax=ax, label="solved [%]", shrink=0.85)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    return buffer.getvalue()
