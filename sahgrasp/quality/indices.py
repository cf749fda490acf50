"""The registry of grasp quality indices: name, function, singularity threshold, description.

An index maps the manipulability ellipsoids of a batch of grasps (:class:`Ellipsoids`, that is
:class:`sahgrasp.quality.ellipsoids.Manipulability`) to one value per grasp, larger is better; a
grasp whose value is below the index's threshold is singular. The atlas paper's three indices
(Rosales, Porta and Ros, Section V, Fig. 9) are registered here; :func:`register_index` adds
another, and from then on ``Manipulability.index``, the optimization's ``index`` setting, the
reports and the ``--index`` choices of ``sahgrasp atlas`` all know it.

This module imports only the standard library, so that ``sahgrasp --help`` lists the indices
without loading numpy; :mod:`sahgrasp.quality.ellipsoids` re-exports its names.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from operator import attrgetter
from typing import TYPE_CHECKING, Protocol

from sahgrasp.core.errors import QualityError
from sahgrasp.core.registry import Registry

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

__all__ = [
    "PAPER_INDICES",
    "QUALITY_INDICES",
    "SINGULAR_THRESHOLDS",
    "Ellipsoids",
    "QualityIndex",
    "register_index",
]


class Ellipsoids(Protocol):
    """What an index reads: manipulability ellipsoids of a batch of grasps (leading axes ``...``).

    :class:`sahgrasp.quality.ellipsoids.Manipulability` is one; its docstring defines each field.
    """

    @property
    def semi_axes(self) -> NDArray[np.float64]:
        """Semi-axis lengths, decreasing, (..., o)."""
        ...

    @property
    def inverse_condition(self) -> NDArray[np.float64]:
        """Smallest over largest semi-axis, (...)."""
        ...

    @property
    def volume(self) -> NDArray[np.float64]:
        """Product of the semi-axes, (...)."""
        ...

    @property
    def min_semiaxis(self) -> NDArray[np.float64]:
        """Smallest semi-axis, (...)."""
        ...


@dataclass(frozen=True)
class QualityIndex:
    """A grasp quality index of the manipulability ellipsoid.

    Attributes:
        name: The name users give (``--index NAME``, ``OptimizationSettings.index``).
        function: Ellipsoids of a batch of grasps -> one value per grasp, shape (...); larger is
            better.
        singular_below: A grasp whose value is below this is singular.
        description: One line for users: what the index measures.
    """

    name: str
    function: Callable[[Ellipsoids], NDArray[np.float64]]
    singular_below: float
    description: str

    def __post_init__(self) -> None:
        if not callable(self.function):
            raise QualityError(f"quality index {self.name!r}: function must be callable")
        threshold = self.singular_below
        if isinstance(threshold, bool) or not isinstance(threshold, int | float):
            raise QualityError(
                f"quality index {self.name!r}: singular_below must be a number, got {threshold!r}"
            )


QUALITY_INDICES: Registry[QualityIndex] = Registry("quality index", QualityError)
"""Every quality index by name, the paper's three first (Fig. 9 (a)-(c))."""


def register_index(index: QualityIndex) -> QualityIndex:
    """Add ``index`` to :data:`QUALITY_INDICES` under its name and return it.

    Raises:
        QualityError: The name is empty or taken.
    """
    if not isinstance(index, QualityIndex):
        raise QualityError(f"register_index takes a QualityIndex, got {type(index).__name__}")
    return QUALITY_INDICES.register(index.name, index)


# The atlas paper's indices and thresholds (Section V): singular below 1e-3, 1e-4 and 1e-3.
register_index(
    QualityIndex(
        "inverse_condition",
        attrgetter("inverse_condition"),
        1e-3,
        "smallest over largest semi-axis: how evenly the hand moves the object in every direction",
    )
)
register_index(
    QualityIndex(
        "volume",
        attrgetter("volume"),
        1e-4,
        "product of the semi-axes: the ellipsoid's volume over the unit ball's",
    )
)
register_index(
    QualityIndex(
        "min_semiaxis",
        attrgetter("min_semiaxis"),
        1e-3,
        "smallest semi-axis: the object speed in the hand's weakest direction",
    )
)

PAPER_INDICES: tuple[str, ...] = tuple(QUALITY_INDICES)
"""The atlas paper's indices, in the order of Fig. 9 (a)-(c) (the figure plots these three)."""


class _Thresholds(Mapping[str, float]):
    """Index name -> its ``singular_below``, read from the registry when used."""

    def __getitem__(self, name: str) -> float:
        return QUALITY_INDICES[name].singular_below

    def __iter__(self) -> Iterator[str]:
        return iter(QUALITY_INDICES)

    def __len__(self) -> int:
        return len(QUALITY_INDICES)

    def __repr__(self) -> str:
        return repr(dict(self))


SINGULAR_THRESHOLDS: Mapping[str, float] = _Thresholds()
"""Index name -> the value below which a grasp is singular, of every registered index."""
