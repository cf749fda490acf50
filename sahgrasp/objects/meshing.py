"""Triangle meshes for display: tessellation of patches, concatenation, placement."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sahgrasp.core.frames import FloatArray, transform_points
from sahgrasp.objects.patches import Patch

__all__ = ["Mesh", "tessellate"]


@dataclass(frozen=True, eq=False)
class Mesh:
    """A triangle mesh.

    Attributes:
        vertices_m: Vertex positions [m], shape (N, 3).
        faces: Vertex indices of each triangle, counter-clockwise seen from outside, shape (M, 3).
    """

    vertices_m: FloatArray
    faces: NDArray[np.int64]

    @staticmethod
    def concatenate(meshes: Iterable[Mesh]) -> Mesh:
        """Return one mesh holding all ``meshes``."""
        vertices, faces, offset = [], [], 0
        for mesh in meshes:
            vertices.append(mesh.vertices_m)
            faces.append(mesh.faces + offset)
            offset += len(mesh.vertices_m)
        return Mesh(np.concatenate(vertices), np.concatenate(faces))

    def transformed(self, T: FloatArray) -> Mesh:
        """Return the mesh moved by placement ``T``."""
        return Mesh(transform_points(T, self.vertices_m), self.faces)


def tessellate(patch: Patch, counts: tuple[int, int]) -> Mesh:
    """Return a grid mesh of ``patch`` with ``counts = (n_u, n_v)`` cells, faces facing outward.

    Triangles of zero area (at a pole or on the axis) are dropped.
    """
    u = np.linspace(*patch.u_range, counts[0] + 1)
    v = np.linspace(*patch.v_range, counts[1] + 1)
    jet = patch.surface.jet(u[:, None], v[None, :]).transformed(patch.placement)
    vertices = jet.point.reshape(-1, 3)
    normals = jet.normal.reshape(-1, 3)
    index = np.arange(vertices.shape[0]).reshape(len(u), len(v))
    a, b = index[:-1, :-1].ravel(), index[1:, :-1].ravel()
    c, d = index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    corners = vertices[faces]
    area_normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    outward = np.einsum("ij,ij->i", area_normal, normals[faces].sum(axis=1))
    faces = np.where((outward < 0)[:, None], faces[:, ::-1], faces)
    keep = np.linalg.norm(area_normal, axis=1) > 1e-14
    return Mesh(vertices, faces[keep].astype(np.int64))
