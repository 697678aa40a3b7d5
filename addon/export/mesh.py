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
        uvs: (T, 3, 2) float32 per-corner UVs of the active render UV map, or None.
        tangents: (T, 3, 4) float32 per-corner object-space unit tangent + bitangent
            sign (MikkTSpace, ``calc_tangents``), or None.
        notes: things that could not be read (for one warning per mesh).
    """

    positions: np.ndarray
    triangles: np.ndarray
    normals: np.ndarray
    smooth: np.ndarray
    slots: np.ndarray
    uvs: np.ndarray | None = None
    tangents: np.ndarray | None = None
    notes: tuple = ()

    @property
    def n_triangles(self) -> int:
        return int(self.triangles.shape[0])


def _get(collection, attr: str, count: int, width: int, dtype) -> np.ndarray:
    out = np.empty(count * width, dtype)
    if count:
        collection.foreach_get(attr, out)
    return out.reshape(count, width) if width > 1 else out


def read_mesh(mesh, uvs: bool = False, tangents: bool = False, uv_maps=()) -> LocalMesh:
    """Triangles, normals, smooth flags and material slots of an (evaluated) mesh.

    ``uvs``/``tangents``: also read per-corner UVs of the active render UV map and MikkTSpace
    tangents (only when a material of the object reads them: they cost 8 + 16 bytes per
    corner). ``uv_maps``: UV map names the materials ask for; any other than the active
    render map is noted (the active render map is used).
    """
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
    local = LocalMesh(positions, triangles, normals.astype(np.float32), smooth, slots)
    if (uvs or tangents) and n_tri:
        _read_uvs(mesh, local, tris, tangents, uv_maps)
    return local


def _read_uvs(mesh, local: LocalMesh, tris, want_tangents: bool, uv_maps) -> None:
    """Fill ``local.uvs`` (and ``local.tangents``) from the active render UV map."""
    n_tri = local.n_triangles
    notes = []
    layer = compat.active_render_uv_layer(mesh)
    if layer is None:  # Cycles: UV (0, 0) everywhere (and no usable tangent frame)
        notes.append("no UV map: UV (0, 0) used")
        local.uvs = np.zeros((n_tri, 3, 2), np.float32)
        if want_tangents:
            local.tangents = _fallback_tangents(local, local.uvs)
        local.notes = tuple(notes)
        return
    for name in sorted(m for m in uv_maps if m and m != layer.name):
        notes.append(f"UV map '{name}' asked for by a node: the active render map '{layer.name}' used")
    tri_l = _get(tris, "loops", n_tri, 3, np.int32).reshape(-1)
    corner_uv = compat.uv_layer_corners(layer, len(mesh.loops))
    local.uvs = np.ascontiguousarray(corner_uv[tri_l].reshape(n_tri, 3, 2))
    if want_tangents:
        try:
            corner_t = compat.corner_tangents(mesh, layer.name)
            local.tangents = np.ascontiguousarray(corner_t[tri_l].reshape(n_tri, 3, 4))
        except RuntimeError as exc:
            notes.append(f"MikkTSpace tangents failed ({str(exc).strip()}): per-triangle UV tangents used")
            local.tangents = _fallback_tangents(local, local.uvs)
    local.notes = tuple(notes)


def _fallback_tangents(local: LocalMesh, uvs: np.ndarray) -> np.ndarray:
    """Per-triangle tangents from the UV gradient, orthogonalised against each corner's
    normal (used when ``calc_tangents`` fails, e.g. on n-gons, or without UVs)."""
    p = local.positions[local.triangles]  # (T, 3, 3)
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    uv = uvs.astype(np.float64)
    d1, d2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    ok = np.abs(det) > 1e-20
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)[:, None]
    t = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * inv
    b = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * inv
    face_n = np.cross(e1, e2)
    t = np.where(ok[:, None], t, e1)  # degenerate UVs: along the first edge
    n = local.normals[local.triangles].astype(np.float64)  # (T, 3, 3)
    tc = t[:, None, :] - np.sum(t[:, None, :] * n, axis=2, keepdims=True) * n
    length = np.linalg.norm(tc, axis=2, keepdims=True)
    tc = np.where(length > 1e-20, tc / np.where(length > 1e-20, length, 1.0), 0.0)
    sign = np.where(np.sum(np.cross(face_n, t) * b, axis=1) < 0, -1.0, 1.0)
    out = np.empty((local.n_triangles, 3, 4), np.float32)
    out[..., :3] = tc
    out[..., 3] = sign[:, None]
    return out


@dataclass
class WorldMesh:
    """A :class:`LocalMesh` placed in the world by one instance transform."""

    positions: np.ndarray  # (V, 3) float64
    triangles: np.ndarray  # (T, 3) int32, winding fixed for mirroring transforms
    normals: np.ndarray  # (V, 3) float32 unit
    uvs: np.ndarray | None = None  # (T, 3, 2) float32, corners in ``triangles`` order
    tangents: np.ndarray | None = None  # (T, 3, 4) float32 world-space unit tangent + sign


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
    uvs, tangents = local.uvs, local.tangents
    if tangents is not None:
        # Tangents transform like vectors; a mirroring transform flips the bitangent
        # (cross(M⁻ᵀn, Mt) = det(M)·…), as Blender's own evaluation does.
        t = tangents[..., :3].astype(np.float64) @ linear.T
        length = np.linalg.norm(t, axis=-1, keepdims=True)
        t = np.where(length > 0, t / np.where(length > 0, length, 1.0), 0.0)
        sign = tangents[..., 3:] * (-1.0 if det < 0 else 1.0)
        tangents = np.concatenate([t, sign], axis=-1).astype(np.float32)
    if det < 0:
        triangles = triangles[:, ::-1]
        uvs = None if uvs is None else uvs[:, ::-1]
        tangents = None if tangents is None else tangents[:, ::-1]
    return WorldMesh(positions, np.ascontiguousarray(triangles), normals.astype(np.float32),
                     None if uvs is None else np.ascontiguousarray(uvs),
                     None if tangents is None else np.ascontiguousarray(tangents))
