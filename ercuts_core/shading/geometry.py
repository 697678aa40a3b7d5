"""What shading programs read at a hit: position, normals, UV, tangent frame, generated
coordinates, interpolated from the triangle's corners with barycentrics.

A hit is (triangle ``prim``, barycentrics ``b`` = (1 − u − v, u, v)) with
p = Σ b_k P_k (embree's convention). Hits can also be re-located from a stored position p
(:meth:`MeshShading.barycentrics`): the integrators' path vertices store p, not b.

Tangents: ``MeshTable.tangents`` when given (MikkTSpace, as Cycles); otherwise the
per-triangle UV gradient ∂p/∂u (sign from the UV winding), and with no UVs an arbitrary
frame about the shading normal (normal maps are then orientation-less: a documented gap).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from ..sampling import coordinate_system

#: Bump offsets: barycentric step along the triangle edges, and the largest UV step.
BUMP_STEP = 1e-3
BUMP_MAX_DUV = 1e-4


class MeshShading:
    """Per-triangle tables for interpolating shading inputs (float64).

    Args:
        tri_p: (T, 3, 3) corner positions [m].
        uvs: (T, 3, 2) per-corner UVs or None (UV (0, 0) everywhere, as Cycles).
        tangents: (T, 3, 4) per-corner tangent xyz + sign, or None.
        object_ids: (T,) object of each triangle (for the Generated box).
        textures: the scene's :class:`~ercuts_core.shading.textures.TextureTable`.
    """

    def __init__(self, tri_p: NDArray, uvs, tangents, object_ids: NDArray, textures):
        self.tri_p = tri_p
        self.textures = textures
        self.tri_uv = None if uvs is None else uvs.astype(np.float64)
        self.tri_tan = None if tangents is None else tangents.astype(np.float64)
        e1, e2 = tri_p[:, 1] - tri_p[:, 0], tri_p[:, 2] - tri_p[:, 0]
        self.e1, self.e2 = e1, e2
        d11, d12, d22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
        det = d11 * d22 - d12 * d12
        inv = np.divide(1.0, det, out=np.zeros_like(det), where=det > 0)
        # Dual basis: b1 = (v·g1), b2 = (v·g2) for v = p − P0 in the triangle's plane
        self.g1 = (d22 * inv)[:, None] * e1 - (d12 * inv)[:, None] * e2
        self.g2 = (d11 * inv)[:, None] * e2 - (d12 * inv)[:, None] * e1
        # Generated coordinates: each object's world-space bounding box
        _, obj = np.unique(np.asarray(object_ids, np.int64), return_inverse=True)   # ids → 0..O−1
        obj = obj.reshape(-1)
        n_obj = int(obj.max()) + 1 if len(obj) else 0
        lo = np.full((n_obj, 3), np.inf)
        hi = np.full((n_obj, 3), -np.inf)
        np.minimum.at(lo, obj, tri_p.min(axis=1))
        np.maximum.at(hi, obj, tri_p.max(axis=1))
        self.tri_obj = obj
        self.obj_lo, self.obj_size = lo, hi - lo
        self._uv_frame = self._uv_tangents()

    def _uv_tangents(self):
        """(T, 3) ∂p/∂u per triangle, (T,) its bitangent sign, (T, 2) |Δuv| of e1 and e2."""
        T = len(self.tri_p)
        if self.tri_uv is None:
            return None, np.ones(T), np.zeros((T, 2))
        duv1 = self.tri_uv[:, 1] - self.tri_uv[:, 0]
        duv2 = self.tri_uv[:, 2] - self.tri_uv[:, 0]
        det = duv1[:, 0] * duv2[:, 1] - duv2[:, 0] * duv1[:, 1]
        inv = np.divide(1.0, det, out=np.zeros_like(det), where=det != 0)
        dpdu = (self.e1 * duv2[:, 1:2] - self.e2 * duv1[:, 1:2]) * inv[:, None]
        sign = np.where(det < 0, -1.0, 1.0)
        return dpdu, sign, np.stack([np.linalg.norm(duv1, axis=1), np.linalg.norm(duv2, axis=1)], 1)

    def barycentrics(self, prim: NDArray, p: NDArray) -> NDArray:
        """(N, 3) barycentrics of points p (N, 3) on triangles prim (N,) (projected onto the plane)."""
        v = p - self.tri_p[prim, 0]
        b1 = (v * self.g1[prim]).sum(1)
        b2 = (v * self.g2[prim]).sum(1)
        return np.stack([1.0 - b1 - b2, b1, b2], axis=1)

    def context(self, prim: NDArray, b: NDArray, ng: NDArray, ns: NDArray,
                lane_row: NDArray | None = None) -> "ShadingContext":
        """The shading inputs of N hits (``ns``: the smooth shading normal before maps)."""
        return ShadingContext(self, np.asarray(prim, np.int64), b, ng, ns, lane_row=lane_row)


@dataclass
class ShadingContext:
    """Shading inputs of N hits of one material (all (N, …) float64, computed on demand).

    ``bump_heights`` is set by the program evaluator for the BUMP node it is evaluating;
    ``lane_row`` (N,) is each hit's material index within a program family
    (:func:`ercuts_core.shading.program.merge`), None outside families.
    """

    mesh: MeshShading
    prim: NDArray
    b: NDArray
    ng: NDArray
    ns: NDArray
    bump_heights: tuple | None = field(default=None)
    lane_row: NDArray | None = field(default=None)

    @property
    def n(self) -> int:
        return len(self.prim)

    @property
    def textures(self):
        return self.mesh.textures

    @cached_property
    def p(self) -> NDArray:
        return np.einsum("nk,nkj->nj", self.b, self.mesh.tri_p[self.prim])

    @cached_property
    def uv(self) -> NDArray:
        """(N, 2) interpolated UV ((0, 0) without a UV map)."""
        if self.mesh.tri_uv is None:
            return np.zeros((self.n, 2))
        return np.einsum("nk,nkj->nj", self.b, self.mesh.tri_uv[self.prim])

    @cached_property
    def uv3(self) -> NDArray:
        return np.concatenate([self.uv, np.zeros((self.n, 1))], axis=1)

    @cached_property
    def generated(self) -> NDArray:
        """(N, 3) position normalised to the object's world-space bounding box [0, 1]³."""
        obj = self.mesh.tri_obj[self.prim]
        size = self.mesh.obj_size[obj]
        rel = self.p - self.mesh.obj_lo[obj]
        return np.divide(rel, size, out=np.full_like(rel, 0.5), where=size > 0)

    @cached_property
    def _frame(self) -> tuple[NDArray, NDArray]:
        mesh = self.mesh
        if mesh.tri_tan is not None:
            t4 = np.einsum("nk,nkj->nj", self.b, mesh.tri_tan[self.prim])
            return t4[:, :3], np.where(t4[:, 3] < 0, -1.0, 1.0)
        dpdu, sign, _ = mesh._uv_frame
        fallback = coordinate_system(self.ns)[0]
        if dpdu is None:
            return fallback, np.ones(self.n)
        t = dpdu[self.prim]
        # Gram–Schmidt against the shading normal; degenerate UVs → the arbitrary frame
        t = t - (t * self.ns).sum(1)[:, None] * self.ns
        length = np.linalg.norm(t, axis=1)
        ok = length > 1e-12
        t = np.where(ok[:, None], t / np.maximum(length, 1e-300)[:, None], fallback)
        return t, np.where(ok, sign[self.prim], 1.0)

    @property
    def tangent(self) -> NDArray:
        """(N, 3) tangent T of the normal-map frame."""
        return self._frame[0]

    @property
    def tangent_sign(self) -> NDArray:
        """(N,) bitangent sign: B = sign·(N × T)."""
        return self._frame[1]

    def bump_offsets(self) -> tuple["ShadingContext", "ShadingContext", NDArray, NDArray]:
        """Two nearby points along the triangle's edges for the BUMP finite differences:
        (context at p + dPdx, context at p + dPdy, dPdx (N, 3), dPdy (N, 3)).

        Step: BUMP_STEP of each edge, shortened so that UV moves at most BUMP_MAX_DUV
        (a fraction of a texel of a 4k texture); Cycles uses the ray differentials."""
        mesh = self.mesh
        duv = mesh._uv_frame[2][self.prim]                       # (N, 2)
        step = np.minimum(BUMP_STEP, np.divide(BUMP_MAX_DUV, duv, out=np.full_like(duv, BUMP_STEP),
                                               where=duv > 0))
        sx, sy = step[:, 0], step[:, 1]
        bx = self.b + sx[:, None] * np.array([-1.0, 1.0, 0.0])
        by = self.b + sy[:, None] * np.array([-1.0, 0.0, 1.0])
        dpdx = sx[:, None] * mesh.e1[self.prim]
        dpdy = sy[:, None] * mesh.e2[self.prim]
        return (replace(self, b=bx, bump_heights=None), replace(self, b=by, bump_heights=None), dpdx, dpdy)
