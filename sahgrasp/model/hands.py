"""The registry of hands: the one place that knows which hands exist and what each one brings.

An entry (:class:`HandEntry`) names a hand and gives everything hand-specific that generic code
needs: how to build its :class:`~sahgrasp.model.hand.HandDescription`, the data files the package
ships for it (the IK's sequence, the learned start's grasp database), its reach for the contact
sampler (or none: then it is derived from the model), the sizes of the database ``sahgrasp learn``
builds for it, and its contact-marker colours. ``load_hand(name)``, the command line's ``--hand``
help, the shipped-data lookups, ``learn``'s defaults, the samplers and the scenes all read this
registry; adding a hand is one :func:`register_hand` call (docs/how-to/add-a-hand.md).
An installed package can add hands without being imported by the user: each object it declares
in the entry-point group ``sahgrasp.hands`` (a :class:`HandEntry`) is registered the first time a
name is not found (:func:`discover_hands`).

Only the standard library is imported here, so that a parser can list the hands without loading
Pinocchio: a built-in hand's description is built by a function named ``"module:function"``,
imported on first use.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any

from sahgrasp.core.errors import HandModelError
from sahgrasp.core.registry import Registry

__all__ = [
    "DEFAULT_HAND",
    "ENTRY_POINT_GROUP",
    "HANDS",
    "HandEntry",
    "LearnDefaults",
    "SamplerReach",
    "data_file",
    "discover_hands",
    "hand_entry",
    "hand_help",
    "register_hand",
]

RGBA = tuple[float, float, float, float]


@dataclass(frozen=True)
class SamplerReach:
    """A hand's reach for the contact sampler, measured rather than derived from its model.

    Attributes:
        finger_spacing_m: Range of the distance between neighbouring finger contacts [m].
        span_m: Range of the thumb-to-middle contact distance [m].
        fingertip_radius_m: Radius of the fingertip spheres [m].
    """

    finger_spacing_m: tuple[float, float]
    span_m: tuple[float, float]
    fingertip_radius_m: float


@dataclass(frozen=True)
class LearnDefaults:
    """The sizes and seed of the database ``sahgrasp learn`` builds for a hand by default.

    Attributes:
        samples: Random entries (collision-free configurations).
        grasp_sets: Contact sets drawn on primitive solids and solved (the grasp entries); 0 for a
            hand whose reach is not calibrated.
        seed: The build's seed.
    """

    samples: int = 2_500
    grasp_sets: int = 0
    seed: int = 61803398


@dataclass(frozen=True)
class HandEntry:
    """Everything hand-specific about one hand.

    Attributes:
        name: The hand's name (``--hand NAME``, a targets file's ``"hand"``); the name of the
            description it builds.
        description: Builds its :class:`~sahgrasp.model.hand.HandDescription`: a function of no
            arguments, or ``"module:function"`` naming one (imported on first use).
        sequence: The hand's IK sequence file: an absolute path, or one relative to the installed
            ``sahgrasp`` package (None: the paper's Table 1 lambdas on the hand's own principal
            motions).
        database: The hand's grasp database of the learned start, a path as ``sequence``
            (None: the learned start falls back to the sequence).
        reach: The contact sampler's reach (None: derived from the model).
        learn: What ``sahgrasp learn`` builds by default.
        finger_colors: Contact-marker colour per finger (RGBA in [0, 1]); fingers not named get
            the scenes' default colours.
    """

    name: str
    description: Callable[[], Any] | str
    sequence: str | None = None
    database: str | None = None
    reach: SamplerReach | None = None
    learn: LearnDefaults = field(default_factory=LearnDefaults)
    finger_colors: Mapping[str, RGBA] = field(default_factory=dict)

    def build(self) -> Any:
        """The hand's :class:`~sahgrasp.model.hand.HandDescription`, built anew.

        Raises:
            HandModelError: The builder cannot be found or does not build a description.
        """
        builder = self.description
        if isinstance(builder, str):
            module, _, function = builder.partition(":")
            try:
                builder = getattr(importlib.import_module(module), function)
            except (ImportError, AttributeError) as exc:
                raise HandModelError(
                    f"hand {self.name!r}: its description builder {self.description!r} is not "
                    f"importable ({exc})"
                ) from None
        assert callable(builder)
        return builder()


HANDS: Registry[HandEntry] = Registry("hand", HandModelError)
"""The hands ``load_hand`` knows by name, in registration order."""


def register_hand(entry: HandEntry) -> HandEntry:
    """Add ``entry`` to :data:`HANDS` and return it.

    Raises:
        HandModelError: The name is empty, taken, or ``entry`` is not a :class:`HandEntry`.
    """
    if not isinstance(entry, HandEntry):
        raise HandModelError(f"a hand is registered as a HandEntry, got {type(entry).__name__}")
    return HANDS.register(entry.name, entry)


ENTRY_POINT_GROUP = "sahgrasp.hands"
"""The entry-point group in which installed packages declare their :class:`HandEntry` objects."""

_discovered = False
_broken: dict[str, str] = {}
"""Declared hands that did not load, by name: the reason, raised when that name is asked for."""


def discover_hands() -> None:
    """Register the hands installed packages declare in :data:`ENTRY_POINT_GROUP`, once.

    Called when a name is not found, so that listing or loading the built-in hands never scans
    the installed packages. A declared hand that does not load (its module fails, it is not a
    :class:`HandEntry` of the entry point's name, or the name is taken) is not registered; asking
    for that name then raises the reason (:func:`hand_entry`), other names are not affected.
    """
    # Imported here: scanning the installed packages is needed only for a name not registered,
    # and importlib.metadata would slow every `sahgrasp --help`.
    import importlib.metadata

    global _discovered
    if _discovered:
        return
    _discovered = True
    for point in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        if point.name in HANDS:
            continue
        try:
            entry = point.load()
        except Exception as exc:  # a plug-in's own failure, whatever it is: kept in one line
            _broken[point.name] = f"{type(exc).__name__}: {exc}"
            continue
        if not isinstance(entry, HandEntry) or entry.name != point.name:
            _broken[point.name] = f"it is {entry!r:.80}, not a HandEntry named {point.name!r}"
            continue
        register_hand(entry)


def hand_entry(name: str) -> HandEntry | None:
    """The registry's entry of the hand named ``name``, None for a hand it does not list.

    A name not registered yet is looked up among the installed plug-ins (:func:`discover_hands`).

    Raises:
        HandModelError: ``name`` is declared by an installed package but does not load.
    """
    if not isinstance(name, str):
        return None
    if name not in HANDS:
        discover_hands()
        if name in _broken:
            raise HandModelError(
                f"hand {name!r}, declared in the entry points {ENTRY_POINT_GROUP!r} of an "
                f"installed package, does not load: {_broken[name]}"
            )
    return HANDS.get(name)


def data_file(path: str) -> Traversable:
    """The file an entry's ``sequence`` or ``database`` names (see :class:`HandEntry`)."""
    if os.path.isabs(path):
        return Path(path)
    return resources.files("sahgrasp").joinpath(path)


def hand_help() -> str:
    """The ``--hand`` help: the registered names, or a description JSON."""
    return f"{', '.join(HANDS)}, or the path of a hand-description JSON (not a URDF)"


# The built-in hands. Their descriptions are in sahgrasp.model.hand; the SAH's reach was measured
# with solve_ik on flat antipodal grasps (docs/results.md, "The SAH's reach"): thumb on one face of
# a plate, index,
# middle and ring in a line on the other, all solved for every thickness from 0.5 to 146 mm, and
# for finger spacings from 28 mm up (26 mm puts neighbouring fingers, 26 mm wide, into each other).
register_hand(
    HandEntry(
        name="sah",
        description="sahgrasp.model.hand:sah_description",
        sequence="data/sequences/sah.json",
        database="data/grasps/sah.npz",
        reach=SamplerReach((0.028, 0.040), (0.001, 0.146), 0.01),
        learn=LearnDefaults(samples=2_500, grasp_sets=1_600, seed=61803398),
    )
)
register_hand(
    HandEntry(
        name="allegro",
        description="sahgrasp.model.hand:allegro_description",
        sequence="data/sequences/allegro.json",
        database="data/grasps/allegro.npz",
        learn=LearnDefaults(samples=2_500, grasp_sets=0, seed=61803398),
    )
)

DEFAULT_HAND: str = next(iter(HANDS))
"""The hand used when none is named: the first registered."""
