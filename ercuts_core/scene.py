"""The built scene: tracer, per-triangle tables, lights and camera derived from a clean description.

:class:`BuiltScene` is immutable after construction and never changes the description.
:meth:`BuiltScene.surface` turns embreex hits into float64 surface interactions
(positions from barycentrics, geometric and shading normals, material rows, emission).
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

from .arrays import take_rows
from .bsdf import DELTA_ALPHA, Bsdf, bsdf_max_value
from .camera import Camera
from .description import SceneDescription
from .lights import LightSet
from .shading.alpha import AlphaTracer
from .shading.materials import SceneShading
from .tracer import Hit, Tracer
from .vecmath import dot


@dataclass
class Surface:
    """Surface interactions of N rays (only meaningful where ``valid``).

    Attributes:
        valid: (N,) the ray hit something.
        p: (N, 3) float64 hit position [m].
        ng: (N, 3) unit geometric normal (triangle winding; not flipped toward the ray).
        ns: (N, 3) unit shading normal, in the same hemisphere as ``ng``.
        prim: (N,) triangle index (−1 on misses).
        mat: (N,) shading key: the material row, or for materials whose program changes the
            BSDF, M + prim (:mod:`ercuts_core.shading.materials`); build BSDFs with
            :meth:`BuiltScene.bsdf`.
        t: (N,) distance along the ray.
    """

    valid: NDArray
    p: NDArray
    ng: NDArray
    ns: NDArray
    prim: NDArray
    mat: NDArray
    t: NDArray

    def arrays(self) -> tuple[NDArray, ...]:
        """The per-ray arrays in field order."""
        return tuple(getattr(self, f.name) for f in fields(self))

    @staticmethod
    def concat(parts: list["Surface"]) -> "Surface":
        """The interactions of ``parts`` one after another (ray batches traced in chunks)."""
        return Surface(*(np.concatenate(column) for column in zip(*(p.arrays() for p in parts))))

    def subset(self, idx) -> "Surface":
        """The interactions selected by an index array or a boolean mask (N,)."""
        return Surface(*(take_rows(a, idx) for a in self.arrays()))


class BuiltScene:
    """Everything an integrator needs, derived from a *validated* description."""

    def __init__(self, desc: SceneDescription, threads: int = 0):
        self.desc = desc
        mesh = desc.mesh
        self.materials = desc.materials
        self.tracer = Tracer(mesh.positions, mesh.triangles, threads=threads)
        pos = mesh.positions.astype(np.float64)
        self.tri_p = pos[mesh.triangles] if mesh.n_triangles else np.zeros((0, 3, 3))   # (T, 3, 3)
        cross = np.cross(self.tri_p[:, 1] - self.tri_p[:, 0], self.tri_p[:, 2] - self.tri_p[:, 0])
        length = np.linalg.norm(cross, axis=1)
        self.tri_area = 0.5 * length                                                     # (T,) m²
        self.tri_ng = cross / np.maximum(length, 1e-300)[:, None]                        # (T, 3)
        self.tri_mat = mesh.material_ids.astype(np.int64)
        self.has_normals = mesh.normals is not None
        if self.has_normals:
            self.tri_vn = mesh.normals.astype(np.float64)[mesh.triangles]                # (T, 3, 3)
            self.tri_smooth = np.ones(mesh.n_triangles, bool) if mesh.smooth is None else mesh.smooth
        # Shading programs (issue 14): inactive — and never consulted — without programs
        self.shading = SceneShading(desc, self.tri_p, self.tri_mat, self.tri_ng)
        self.textured = self.shading.active
        #: ns may differ from ng somewhere: interpolated normals, or a program's normal output
        self.has_shading_normals = self.has_normals or bool(self.shading.row_normal.any())
        tri_emission = self.shading.triangle_emission(desc.materials.emission) \
            if self.textured else None
        self.lights = LightSet(desc, self.tri_p, self.tri_ng, self.tri_area, tri_emission,
                               self.shading.emission_at if self.textured else None,
                               self.shading.row_emission[self.tri_mat] if self.textured else None)
        if self.textured and self.shading.row_alpha.any():
            # Stochastic transparency for camera, bounce and shadow rays (alpha scenes only)
            self.tracer = AlphaTracer(self.tracer, self.shading.alpha, self.shading.row_alpha[self.tri_mat])
        self.camera = Camera(desc.camera)
        self.scene_radius = self.lights.radius
        self.has_delta = _has_delta(desc.materials, self.tri_mat)
        #: Some triangle's material may be a mirror, glass or a metal (``Bsdf.is_specular_or_glass``;
        #: conservative: any transmission or metal, programmed or not): ERCUTS's gather follows
        #: the camera through them.
        self.has_specular_or_glass = self.has_delta or _maybe_specular_or_glass(desc.materials, self.tri_mat)

    def intersect(self, o: NDArray, d: NDArray, tmax=None) -> Surface:
        """Trace rays and return their surface interactions."""
        return self.surface(self.tracer.intersect(o, d, tmax))

    def surface(self, hit: Hit) -> Surface:
        """Surface interactions from embreex hits (positions from barycentrics, float64)."""
        valid = hit.valid
        prim = np.where(valid, hit.prim, 0)
        n = len(prim)
        if self.tri_p.shape[0] == 0:
            z = np.zeros((n, 3))
            return Surface(valid, z, z, z, hit.prim, np.zeros(n, np.int64), hit.t)
        b = np.stack([1.0 - hit.u - hit.v, hit.u, hit.v], axis=1)                        # (N, 3)
        p = np.einsum("nk,nkj->nj", b, take_rows(self.tri_p, prim))
        ng = take_rows(self.tri_ng, prim)
        ns = self._smooth_normals(prim, b, ng)
        mat = take_rows(self.tri_mat, prim)
        if self.textured:
            ns = self.shading.shading_normals(valid, prim, b, mat, ng, ns)
            mat = self.shading.keys(valid, prim, mat)
        return Surface(valid, p, ng, ns, hit.prim, mat, hit.t)

    def _smooth_normals(self, prim: NDArray, b: NDArray, ng: NDArray) -> NDArray:
        """(N, 3) interpolated vertex normals at barycentrics b (N, 3) of triangles prim, on
        the side of ``ng``; ng itself on flat faces and meshes without normals."""
        if not self.has_normals:
            return ng
        interp = np.einsum("nk,nkj->nj", b, take_rows(self.tri_vn, prim))
        ln = np.linalg.norm(interp, axis=1)
        use = take_rows(self.tri_smooth, prim) & (ln > 1e-8)
        interp = interp / np.maximum(ln, 1e-300)[:, None]
        # Keep the shading normal on the geometric normal's side.
        flip = dot(interp, ng) < 0
        interp[flip] *= -1.0
        return np.where(use[:, None], interp, ng)

    def bsdf(self, mat: NDArray, ns: NDArray, ng: NDArray, p: NDArray) -> Bsdf:
        """The BSDF at N vertices from their shading keys ``mat`` (see :class:`Surface`),
        positions p and normals (N, 3). Without programs: ``Bsdf.from_table`` exactly.

        Keys of materials with a normal map and a bump-shadowing model
        (:mod:`ercuts_core.bump_shadowing`) carry their triangle: the smooth normal before
        the map is interpolated again at p for the diffuse shadowing term."""
        if not self.textured:
            return Bsdf.from_table(self.materials, mat, ns, ng)
        prm = self.shading.bsdf_params(mat, p, ns, ng)
        model = self.shading.shadowing(mat)
        n_smooth = None
        if model is not None:
            n_smooth = np.array(ns, np.float64, copy=True).reshape(-1, 3)
            lanes = np.flatnonzero(model)
            prim = np.asarray(mat, np.int64)[lanes] - self.shading.n_rows
            b = self.shading.mesh.barycentrics(prim, np.asarray(p, np.float64).reshape(-1, 3)[lanes])
            n_smooth[lanes] = self._smooth_normals(prim, b, self.tri_ng[prim])
        return Bsdf.from_params(prm["base_color"], prm["roughness"], prm["metallic"], prm["specular"],
                                ns, ng, n_smooth, model, prm["transmission"], prm["ior"],
                                prm["translucency"])

    def bsdf_max_value(self, mat: NDArray, p: NDArray) -> NDArray:
        """(N, 3) :func:`ercuts_core.bsdf.bsdf_max_value` at shading keys ``mat`` and positions p."""
        if not self.textured:
            return bsdf_max_value(self.materials, mat)
        up = np.tile([0.0, 0.0, 1.0], (len(mat), 1))
        prm = self.shading.bsdf_params(mat, p, up, up)
        table = self.materials.__class__(
            ("",) * len(mat), prm["base_color"], prm["roughness"], prm["metallic"], prm["specular"],
            np.zeros((len(mat), 3)), (), prm["transmission"], prm["ior"], prm["translucency"])
        return bsdf_max_value(table, np.arange(len(mat)))

    def roughness(self, mat: NDArray, p: NDArray) -> NDArray:
        """(N,) Principled roughness at shading keys ``mat`` and positions p."""
        if not self.textured:
            return np.asarray(self.materials.roughness)[mat]
        up = np.tile([0.0, 0.0, 1.0], (len(mat), 1))
        return self.shading.bsdf_params(mat, p, up, up)["roughness"]

    def emission(self, surf: Surface) -> NDArray:
        """(N, 3) radiance emitted by the hit triangles (two-sided; 0 for misses)."""
        out = self.lights.tri_radiance(np.where(surf.valid, surf.prim, 0), surf.p)
        out[~surf.valid] = 0.0
        return out

    def close(self) -> None:
        self.tracer.close()


def _maybe_specular_or_glass(mats, tri_mat: NDArray) -> bool:
    """True when some triangle's material may be glass or a metal (conservative: it transmits
    or is metallic, a program's output of those counting as such)."""
    used = np.unique(tri_mat)
    used = used[(used >= 0) & (used < mats.n_materials)]
    prog = [mats.programs[i] if mats.has_programs else "" for i in used]
    glass = (np.asarray(mats.transmission)[used] > 0) | np.array(['"transmission"' in p for p in prog], bool)
    metal = (np.asarray(mats.metallic)[used] > 0) | np.array(['"metallic"' in p for p in prog], bool)
    return bool((glass | metal).any())


def _has_delta(mats, tri_mat: NDArray) -> bool:
    """True when some triangle's material can have a delta lobe (:mod:`ercuts_core.bsdf`):
    roughness ≤ 0.01778 with a specular, metallic or glass lobe, or a transmission program
    output (conservative). Textured roughness is judged by the row's constant: a roughness map
    that reaches 0 renders that lobe as GGX at α = 10⁻³ in ERCUTS's VPL part, not as a mirror.
    Rough glass is a continuous lobe: ERCUTS carries it like a glossy one."""
    used = np.unique(tri_mat)
    used = used[(used >= 0) & (used < mats.n_materials)]
    r = np.asarray(mats.roughness, np.float64)[used]
    smooth = r * r <= DELTA_ALPHA
    smooth_spec = smooth & ((np.asarray(mats.specular)[used] > 0) | (np.asarray(mats.metallic)[used] > 0))
    glass = smooth & (np.asarray(mats.transmission)[used] > 0)
    programs = [mats.programs[i] for i in used] if mats.has_programs else []
    return bool(smooth_spec.any() or glass.any() or any('"transmission"' in p for p in programs))

