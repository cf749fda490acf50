"""Planar profiles in the ``(r, z)`` half-plane, to be revolved about the ``z`` axis.

A profile is a chain of :class:`Segment` and :class:`Arc` pieces, each parametrised by arc length
``s`` [m] from its start. Profiles run with the solid's material on their left, so the outward
normal of the revolved surface is the right-hand normal ``(dz/ds, -dr/ds)`` of the profile: a
closed solid's profile runs from a point on the axis at the bottom, around the outside, back to
the axis at the top.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypeAlias

import numpy as np
from numpy.typing import ArrayLike

from sahgrasp.core.frames import FloatArray

__all__ = [
    "Arc",
    "ProfileJet",
    "ProfilePiece",
    "ScalarProfileJet",
    "Segment",
    "chord_count",
    "piece_chords",
    "rounded_polyline",
    "sample_profile",
]

ProfileJet: TypeAlias = tuple[FloatArray, FloatArray, FloatArray]
"""``(rz, d_rz/ds, d2_rz/ds2)``, each of shape (..., 2)."""

ScalarProfileJet: TypeAlias = tuple[float, float, float, float, float, float]
"""``(r, z, dr/ds, dz/ds, d2r/ds2, d2z/ds2)`` at one arc length, as plain floats."""

_LENGTH_TOLERANCE_M = 1e-12


@dataclass(frozen=True)
class Segment:
    """A straight piece from ``start_m`` to ``end_m``, both ``(r, z)`` [m]."""

    start_m: tuple[float, float]
    end_m: tuple[float, float]

    @property
    def length_m(self) -> float:
        """Length of the segment [m]."""
        return math.dist(self.start_m, self.end_m)

    def evaluate(self, s_m: ArrayLike) -> ProfileJet:
        """Return position, first and second derivative w.r.t. arc length at ``s_m`` [m]."""
        s = np.asarray(s_m, dtype=np.float64)[..., None]
        start = np.asarray(self.start_m)
        direction = (np.asarray(self.end_m) - start) / self.length_m
        shape = (*s.shape[:-1], 2)
        return start + s * direction, np.broadcast_to(direction, shape).copy(), np.zeros(shape)

    def evaluate_scalar(self, s_m: float) -> ScalarProfileJet:
        """:meth:`evaluate` at one arc length ``s_m`` [m], in plain floats (same operations).

        The contact regions evaluate one point at a time inside the atlas's Newton steps, where
        numpy's per-call overhead would cost several times the arithmetic.
        """
        (r0, z0), (r1, z1), length = self.start_m, self.end_m, self.length_m
        dr, dz = (r1 - r0) / length, (z1 - z0) / length
        return r0 + s_m * dr, z0 + s_m * dz, dr, dz, 0.0, 0.0


@dataclass(frozen=True)
class Arc:
    """A circular piece: centre ``(r, z)`` [m], radius [m], start angle and signed sweep [rad].

    Angles are measured in the ``(r, z)`` plane from the ``+r`` direction towards ``+z``; a positive
    sweep runs counter-clockwise (a convex bulge when the material is on the left), a negative
    one clockwise (a concave fillet).
    """

    centre_m: tuple[float, float]
    radius_m: float
    start_rad: float
    sweep_rad: float

    @property
    def length_m(self) -> float:
        """Length of the arc [m]."""
        return self.radius_m * abs(self.sweep_rad)

    def evaluate(self, s_m: ArrayLike) -> ProfileJet:
        """Return position, first and second derivative w.r.t. arc length at ``s_m`` [m]."""
        sign = math.copysign(1.0, self.sweep_rad)
        angle = self.start_rad + sign * np.asarray(s_m, dtype=np.float64) / self.radius_m
        radial = np.stack([np.cos(angle), np.sin(angle)], axis=-1)
        tangent = sign * np.stack([-np.sin(angle), np.cos(angle)], axis=-1)
        return np.asarray(self.centre_m) + self.radius_m * radial, tangent, -radial / self.radius_m

    def evaluate_scalar(self, s_m: float) -> ScalarProfileJet:
        """:meth:`evaluate` at one arc length ``s_m`` [m], in plain floats (same operations)."""
        sign = math.copysign(1.0, self.sweep_rad)
        angle = self.start_rad + sign * s_m / self.radius_m
        c, s = math.cos(angle), math.sin(angle)
        (r0, z0), radius = self.centre_m, self.radius_m
        return r0 + radius * c, z0 + radius * s, sign * -s, sign * c, -c / radius, -s / radius


ProfilePiece: TypeAlias = Segment | Arc


def rounded_polyline(
    points_m: Sequence[tuple[float, float]], corner_radii_m: Sequence[float]
) -> tuple[ProfilePiece, ...]:
    """Return the polyline through ``points_m`` with its interior corners rounded.

    Args:
        points_m: Polyline vertices ``(r, z)`` [m], at least two.
        corner_radii_m: One fillet radius [m] per interior vertex (``len(points_m) - 2``); 0 keeps
            the corner sharp.

    Returns:
        Tangent-continuous segments and arcs, in order.

    Raises:
        ValueError: Wrong number of radii, repeated points, or fillets too large for their segments.
    """
    pts = [np.asarray(p, dtype=np.float64) for p in points_m]
    if len(pts) < 2 or len(corner_radii_m) != len(pts) - 2:
        raise ValueError(
            f"need >= 2 points and one radius per interior vertex, got {len(pts)} points "
            f"and {len(corner_radii_m)} radii"
        )
    lengths = [float(np.linalg.norm(b - a)) for a, b in itertools.pairwise(pts)]
    if min(lengths) <= _LENGTH_TOLERANCE_M:
        raise ValueError("consecutive profile points must differ")
    directions = [(b - a) / n for a, b, n in zip(pts[:-1], pts[1:], lengths, strict=True)]
    arcs: list[Arc | None] = []
    trims = [0.0] * (2 * len(lengths))
    for i, radius in enumerate(corner_radii_m):
        d_in, d_out = directions[i], directions[i + 1]
        turn = math.atan2(d_in[0] * d_out[1] - d_in[1] * d_out[0], float(d_in @ d_out))
        if radius <= 0.0 or abs(turn) < 1e-12:
            arcs.append(None)
            continue
        tangent_m = radius * math.tan(abs(turn) / 2.0)
        trims[2 * i + 1] = trims[2 * i + 2] = tangent_m
        arcs.append(_fillet(pts[i + 1] - tangent_m * d_in, d_in, radius, turn))
    pieces: list[ProfilePiece] = []
    for i, (a, d, n) in enumerate(zip(pts[:-1], directions, lengths, strict=True)):
        start_trim, end_trim = trims[2 * i], trims[2 * i + 1]
        if start_trim + end_trim > n + _LENGTH_TOLERANCE_M:
            raise ValueError(f"fillets at both ends of segment {i} overlap; use smaller radii")
        if n - start_trim - end_trim > _LENGTH_TOLERANCE_M:
            start, end = a + start_trim * d, a + (n - end_trim) * d
            pieces.append(Segment(_pair(start), _pair(end)))
        arc = arcs[i] if i < len(arcs) else None
        if arc is not None:
            pieces.append(arc)
    return tuple(pieces)


def _fillet(tangent_point: FloatArray, d_in: FloatArray, radius_m: float, turn_rad: float) -> Arc:
    left = np.array([-d_in[1], d_in[0]])
    centre = tangent_point + math.copysign(radius_m, turn_rad) * left
    offset = tangent_point - centre
    return Arc(
        _pair(centre),
        radius_m,
        math.atan2(offset[1], offset[0]),
        turn_rad,
    )


def _pair(point: FloatArray) -> tuple[float, float]:
    return float(point[0]), float(point[1])


def chord_count(angle_rad: float, radius_m: float, sagitta_m: float) -> int:
    """Chords needed over ``angle_rad`` of a circle of ``radius_m`` to stay within ``sagitta_m``."""
    step = 2.0 * math.acos(max(-1.0, 1.0 - sagitta_m / radius_m))
    return max(1, math.ceil(abs(angle_rad) / step))


def piece_chords(piece: ProfilePiece, sagitta_m: float) -> int:
    """Chords approximating ``piece`` within ``sagitta_m``: one for a segment."""
    if isinstance(piece, Arc):
        return chord_count(piece.sweep_rad, piece.radius_m, sagitta_m)
    return 1


def sample_profile(pieces: Sequence[ProfilePiece], sagitta_m: float) -> FloatArray:
    """Return the profile as a polyline ``(K, 2)`` within ``sagitta_m`` of the exact pieces."""
    samples = [pieces[0].evaluate(0.0)[0][None]]
    for piece in pieces:
        s = np.linspace(0.0, piece.length_m, piece_chords(piece, sagitta_m) + 1)[1:]
        samples.append(piece.evaluate(s)[0])
    polyline = np.concatenate(samples)
    keep = np.ones(len(polyline), dtype=bool)
    keep[1:] = np.linalg.norm(np.diff(polyline, axis=0), axis=1) > _LENGTH_TOLERANCE_M
    return np.asarray(polyline[keep])
