"""Parametrised surfaces ``(u, v) -> (point, outward unit normal)`` with exact first derivatives.

Every surface evaluates on arrays (broadcast ``u`` against ``v``) and returns a :class:`SurfaceJet`
in its own frame; patches place it (see :mod:`sahgrasp.objects.patches`, :func:`placed_jet`).
Surfaces of revolution also take a scalar path for float ``u`` and ``v`` (plain ``math`` and one
small array): the grasp equations evaluate one point at a time, where numpy's per-call overhead
outweighs the arithmetic. Three families cover the catalog: surfaces of revolution of one
profile piece (cylinders, cones, discs, spheres, tori, fillets), triaxial ellipsoids, and planar
rectangles (box faces).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from sahgrasp.core.frames import FloatArray
from sahgrasp.objects.profiles import ProfilePiece

__all__ = [
    "EllipsoidSurface",
    "RectangleSurface",
    "RevolvedSurface",
    "Surface",
    "SurfaceJet",
    "placed_jet",
]


@dataclass(frozen=True, eq=False)
class SurfaceJet:
    """Point and outward unit normal with their derivatives w.r.t. the parameters.

    Attributes:
        point: Surface point [m], shape (..., 3).
        normal: Outward unit normal, shape (..., 3).
        point_jacobian: d point / d params, shape (..., 3, k) (units of the point per parameter).
        normal_jacobian: d normal / d params, shape (..., 3, k).
    """

    point: FloatArray
    normal: FloatArray
    point_jacobian: FloatArray
    normal_jacobian: FloatArray

    @classmethod
    def from_columns(cls, columns: FloatArray) -> SurfaceJet:
        """The jet of one point from its columns ``[point, normal, d point, d normal]``.

        Args:
            columns: Shape (3, 2 + 2k): the point, the normal, the k point derivatives and the
                k normal derivatives; the jet's arrays are views of it.
        """
        k = (columns.shape[1] - 2) // 2
        return cls(columns[:, 0], columns[:, 1], columns[:, 2 : 2 + k], columns[:, 2 + k :])

    def transformed(self, T: FloatArray) -> SurfaceJet:
        """Return the jet expressed through placement ``T`` (rotate everything, move the point)."""
        rotation = T[:3, :3]
        return SurfaceJet(
            self.point @ rotation.T + T[:3, 3],
            self.normal @ rotation.T,
            np.einsum("ij,...jk->...ik", rotation, self.point_jacobian),
            np.einsum("ij,...jk->...ik", rotation, self.normal_jacobian),
        )

    def parameter_columns(self, columns: list[int]) -> SurfaceJet:
        """Return the jet with only the derivative ``columns`` kept (a curve keeps ``[0]``)."""
        return SurfaceJet(
            self.point,
            self.normal,
            self.point_jacobian[..., columns],
            self.normal_jacobian[..., columns],
        )


class Surface(Protocol):
    """A parametrised surface in its own frame."""

    def jet(self, u: ArrayLike, v: ArrayLike) -> SurfaceJet:
        """Return the point, outward normal and their ``(u, v)`` derivatives."""
        ...


def _parameters(u: ArrayLike, v: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """``u`` and ``v`` as float arrays broadcast to a common shape."""
    u_arr, v_arr = np.broadcast_arrays(np.asarray(u, np.float64), np.asarray(v, np.float64))
    return u_arr, v_arr


def _scalars(u: ArrayLike, v: ArrayLike) -> tuple[float, float] | None:
    """``u`` and ``v`` as floats if both are plain numbers (numpy's float64 included), else None."""
    if isinstance(u, float | int) and isinstance(v, float | int):
        return float(u), float(v)
    return None


def _stack(*columns: FloatArray | float, shape: tuple[int, ...]) -> FloatArray:
    """Stack broadcast scalar fields into a trailing vector axis."""
    return np.stack([np.broadcast_to(c, shape) for c in columns], axis=-1)


def _jacobian(d_du: FloatArray, d_dv: FloatArray) -> FloatArray:
    return np.stack([d_du, d_dv], axis=-1)


@dataclass(frozen=True)
class RevolvedSurface:
    """One profile piece revolved about ``z``.

    ``u`` is the angle [rad] from ``+x`` towards ``+y``, ``v`` the arc length [m] along the piece.
    With ``(r, z)(v)`` parametrised by arc length, the point is ``(r cos u, r sin u, z)`` and the
    outward normal ``(z' cos u, z' sin u, -r')`` is unit by construction (profiles.py).
    """

    piece: ProfilePiece

    def jet(self, u: ArrayLike, v: ArrayLike) -> SurfaceJet:
        """Return the point, outward normal and their ``(u, v)`` derivatives.

        Float ``u`` and ``v`` take the scalar path (:meth:`columns`), arrays the broadcast one;
        both compute the same expressions.
        """
        scalars = _scalars(u, v)
        if scalars is not None:
            return SurfaceJet.from_columns(self.columns(*scalars))
        u_arr, v_arr = _parameters(u, v)
        (r, z), (dr, dz), (ddr, ddz) = (np.moveaxis(a, -1, 0) for a in self.piece.evaluate(v_arr))
        c, s, shape = np.cos(u_arr), np.sin(u_arr), u_arr.shape
        return SurfaceJet(
            _stack(r * c, r * s, z, shape=shape),
            _stack(dz * c, dz * s, -dr, shape=shape),
            _jacobian(
                _stack(-r * s, r * c, 0.0, shape=shape), _stack(dr * c, dr * s, dz, shape=shape)
            ),
            _jacobian(
                _stack(-dz * s, dz * c, 0.0, shape=shape),
                _stack(ddz * c, ddz * s, -ddr, shape=shape),
            ),
        )

    def columns(self, u: float, v: float) -> FloatArray:
        """:meth:`jet` at one ``(u, v)`` in plain floats, as ``SurfaceJet.from_columns`` takes it.

        Returns:
            Shape (3, 6): point, normal, d point / d(u, v), d normal / d(u, v).
        """
        r, z, dr, dz, ddr, ddz = self.piece.evaluate_scalar(v)
        c, s = math.cos(u), math.sin(u)
        return np.array(
            [
                [r * c, dz * c, -r * s, dr * c, -dz * s, ddz * c],
                [r * s, dz * s, r * c, dr * s, dz * c, ddz * s],
                [z, -dr, 0.0, dz, 0.0, -ddr],
            ]
        )


@dataclass(frozen=True)
class EllipsoidSurface:
    """Ellipsoid with semi-axes ``radii_m`` along x, y, z, centred at the origin.

    ``u`` is the longitude [rad] from ``+x`` towards ``+y``, ``v`` the latitude [rad] in
    ``[-pi/2, pi/2]``: point ``(a cos v cos u, b cos v sin u, c sin v)``. The normal is the
    normalised gradient ``m = (x/a^2, y/b^2, z/c^2)``, smooth at the poles.
    """

    radii_m: tuple[float, float, float]

    def jet(self, u: ArrayLike, v: ArrayLike) -> SurfaceJet:
        """Return the point, outward normal and their ``(u, v)`` derivatives."""
        u_arr, v_arr = _parameters(u, v)
        a, b, c = self.radii_m
        cu, su, cv, sv, shape = (
            np.cos(u_arr),
            np.sin(u_arr),
            np.cos(v_arr),
            np.sin(v_arr),
            u_arr.shape,
        )
        point = _stack(a * cv * cu, b * cv * su, c * sv, shape=shape)
        point_jac = _jacobian(
            _stack(-a * cv * su, b * cv * cu, 0.0, shape=shape),
            _stack(-a * sv * cu, -b * sv * su, c * cv, shape=shape),
        )
        gradient = _stack(cv * cu / a, cv * su / b, sv / c, shape=shape)
        gradient_jac = _jacobian(
            _stack(-cv * su / a, cv * cu / b, 0.0, shape=shape),
            _stack(-sv * cu / a, -sv * su / b, cv / c, shape=shape),
        )
        norm = np.linalg.norm(gradient, axis=-1, keepdims=True)
        normal = gradient / norm
        projector = np.eye(3) - normal[..., :, None] * normal[..., None, :]
        return SurfaceJet(point, normal, point_jac, projector @ gradient_jac / norm[..., None])


@dataclass(frozen=True)
class RectangleSurface:
    """Planar surface ``origin + u * u_axis + v * v_axis`` (u, v in metres).

    ``u_axis`` and ``v_axis`` must be orthonormal; the outward normal is ``u_axis x v_axis``.
    """

    origin_m: tuple[float, float, float]
    u_axis: tuple[float, float, float]
    v_axis: tuple[float, float, float]

    def jet(self, u: ArrayLike, v: ArrayLike) -> SurfaceJet:
        """Return the point, outward normal and their ``(u, v)`` derivatives."""
        u_arr, v_arr = _parameters(u, v)
        e_u, e_v, shape = np.asarray(self.u_axis), np.asarray(self.v_axis), (*u_arr.shape, 3)
        point = np.asarray(self.origin_m) + u_arr[..., None] * e_u + v_arr[..., None] * e_v
        jacobian = np.broadcast_to(np.stack([e_u, e_v], axis=-1), (*shape, 2)).copy()
        return SurfaceJet(
            point,
            np.broadcast_to(np.cross(e_u, e_v), shape).copy(),
            jacobian,
            np.zeros((*shape, 2)),
        )


_CURVE_COLUMNS = np.array([0, 1, 2, 4])
"""Of the (3, 6) columns of a surface point, those of a curve ``u -> surface(u, v_fixed)``."""


def placed_jet(
    surface: Surface, u: ArrayLike, v: ArrayLike, T: FloatArray, *, curve: bool = False
) -> SurfaceJet:
    """``surface.jet(u, v)`` through placement ``T``; only the ``u`` derivatives if ``curve``.

    One point of a surface of revolution takes the scalar path: its (3, 6) columns are rotated by
    one matrix product (the patches of the grasp equations are evaluated one point at a time).

    Args:
        surface: The surface, in its own frame.
        u: First parameter(s).
        v: Second parameter(s).
        T: Placement (4x4) of the surface frame.
        curve: Keep only the ``u`` derivatives (a curve at fixed ``v``).
    """
    scalars = _scalars(u, v)
    if isinstance(surface, RevolvedSurface) and scalars is not None:
        columns = surface.columns(*scalars)
        moved = T[:3, :3] @ (columns[:, _CURVE_COLUMNS] if curve else columns)
        moved[:, 0] += T[:3, 3]
        return SurfaceJet.from_columns(moved)
    jet = surface.jet(u, v)
    return (jet.parameter_columns([0]) if curve else jet).transformed(T)
