"""Evaluated Blender meshes → world-space triangle arrays.

Everything is read with ``foreach_get`` into numpy; there is no per-vertex Python
loop. Each distinct evaluated mesh is read once (:func:`read_mesh`) and then placed
once per instance (:func:`transform_mesh`). Meshes with smooth-shaded faces are
un-indexed per triangle corner so that split normals (sharp edges, custom normals,
flat faces next to smooth ones) are exact.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import compat

#: Object types that evaluate to a mesh (``Object.to_mesh()`` works on them).
GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "META", "FONT"}


@dataclass
class LocalMesh:
    """One evaluated mesh in object space.

    Attributes:
        positions: (V, 3) float64 vertex positions.
        triangles: (T, 3) int32 vertex indices, counter-clockwise around the face normal.
        normals: (V, 3) float32 unit shading normals (vertex normals when flat).
        smooth: (T,) bool, True for smooth-shaded triangles.
        slots: (T,) int32 material slot index of each triangle.
    """

    positions: np.ndarray
    triangles: np.ndarray
    normals: np.ndarray
    smooth: np.ndarray
    slots: np.ndarray

    @property
    def n_triangles(self) -> int:
        return int(self.triangles.shape[0])


def _get(collection, attr: str, count: int, width: int, dtype) -> np.ndarray:
    out = np.empty(count * width, dtype)
    if count:
        collection.foreach_get(attr, out)
    return out.reshape(count, width) if width > 1 else out


def read_mesh(mesh) -> LocalMesh:
    """Triangles, normals, smooth flags and material slots of an (evaluated) mesh."""
    tris = mesh.loop_triangles
    n_tri, n_vert = len(tris), len(mesh.vertices)
    co = _get(mesh.vertices, "co", n_vert, 3, np.float32).astype(np.float64)
    tri_v = _get(tris, "vertices", n_tri, 3, np.int32)
    slots = _get(tris, "material_index", n_tri, 1, np.int32)
    smooth = _get(tris, "use_smooth", n_tri, 1, bool)
    if n_tri and smooth.any():
        # Un-index per corner: each corner gets its own (split) normal.
        tri_l = _get(tris, "loops", n_tri, 3, np.int32)
        positions = co[tri_v.reshape(-1)]
        normals = compat.corner_normals(mesh)[tri_l.reshape(-1)]
        triangles = np.arange(3 * n_tri, dtype=np.int32).reshape(n_tri, 3)
    else:
        positions = co
        normals = _get(mesh.vertices, "normal", n_vert, 3, np.float32)
        triangles = tri_v
    return LocalMesh(positions, triangles, normals.astype(np.float32), smooth, slots)


@dataclass
class WorldMesh:
    """A :class:`LocalMesh` placed in the world by one instance transform."""

    positions: np.ndarray  # (V, 3) float64
    triangles: np.ndarray  # (T, 3) int32, winding fixed for mirroring transforms
    normals: np.ndarray  # (V, 3) float32 unit


def transform_mesh(local: LocalMesh, world_from_object: np.ndarray) -> WorldMesh | None:
    """Apply a 4×4 transform; None for a degenerate (zero-scale) transform.

    Normals use the inverse transpose; a negative determinant (mirroring, negative
    scale) reverses the winding so triangles stay counter-clockwise around the
    transformed face normal, as the core expects.
    """
    m = np.asarray(world_from_object, np.float64)
    linear, offset = m[:3, :3], m[:3, 3]
    det = float(np.linalg.det(linear))
    if not np.isfinite(det) or abs(det) < 1e-30:
        return None
    with np.errstate(invalid="ignore", over="ignore"):   # NaN/Inf vertices: dropped by validate
        positions = local.positions @ linear.T + offset
    normals = local.normals.astype(np.float64) @ np.linalg.inv(linear)  # (M⁻ᵀ n)ᵀ = nᵀ M⁻¹
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(length > 0, normals / np.where(length > 0, length, 1.0), 0.0)
    triangles = local.triangles
    if det < 0:
        triangles = triangles[:, ::-1]
    return WorldMesh(positions, np.ascontiguousarray(triangles), normals.astype(np.float32))
