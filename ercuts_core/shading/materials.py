"""Per-hit material parameters for the integrators: the scene's compiled programs, evaluated
over the hits one program family at a time (materials whose programs differ only in
constants share one evaluation, :func:`~ercuts_core.shading.program.merge`; no per-hit
Python loops).

Shading keys (how path vertices carry textured materials). Every integrator stores a
``mat`` integer per surface vertex next to its position p, ns and ng. :class:`SceneShading`
makes that integer a *shading key*:

* key < M (M = material rows): an untextured hit of material row ``key`` (unchanged: scenes
  without programs render bit-identically and never reach this module's evaluation);
* key ≥ M: a hit on triangle ``key − M`` whose material has a program. The parameters are
  re-evaluated from (triangle, p): barycentrics are recovered by projecting p on the
  triangle (:meth:`~ercuts_core.shading.geometry.MeshShading.barycentrics`), then UV etc.

The normal output (normal map / bump) is applied once, when the hit is made
(:meth:`SceneShading.shading_normals`), and travels in the vertex's ``ns``; the BSDF
parameters are re-evaluated whenever a BSDF is built (:meth:`SceneShading.bsdf_params`).

Emission programs: the emitted radiance is evaluated at each point (hits, light samples,
emitted subpaths: :meth:`SceneShading.emission_at`); the light *choice* by power uses each
triangle's mean over ``EMISSION_SAMPLES``² stratified points
(:meth:`SceneShading.triangle_emission`), which only changes the variance. A triangle whose
mean is 0 is not an emitter.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .geometry import MeshShading
from .program import BSDF_OUTPUTS, compile_program, merge, signature

#: Points per triangle (a 4×4 stratified barycentric grid) for textured emission.
EMISSION_SAMPLES = 4


def _compile_all(materials, n_textures: int) -> list:
    return [compile_program(text, name, n_textures)[0]
            for text, name in zip(materials.programs, materials.names)]


class SceneShading:
    """The compiled programs of a built scene.

    Args:
        desc: the clean scene description.
        tri_p: (T, 3, 3) float64 triangle corners; tri_mat: (T,) material rows;
        tri_ng: (T, 3) unit geometric normals.
    """

    def __init__(self, desc, tri_p: NDArray, tri_mat: NDArray, tri_ng: NDArray):
        mats = desc.materials
        self.n_rows = mats.n_materials
        self.programs = _compile_all(mats, len(desc.textures)) if mats.has_programs else [None] * self.n_rows
        self.active = any(p is not None for p in self.programs)
        self.tri_mat = tri_mat
        self.tri_ng = tri_ng
        self.row_program = np.array([p is not None for p in self.programs], bool)
        self.row_normal = np.array([p is not None and p.has("normal") for p in self.programs], bool)
        self.row_bsdf = np.array([p is not None and any(p.has(o) for o in BSDF_OUTPUTS)
                                  for p in self.programs], bool)
        self.row_emission = np.array([p is not None and p.has("emission") for p in self.programs], bool)
        self.row_alpha = np.array([p is not None and p.has("alpha") for p in self.programs], bool)
        self.row_shadowing = np.array([p.bump_shadowing if p is not None and p.has("normal") else 0
                                       for p in self.programs], np.int8)
        self._init_families()
        if self.active:
            m = desc.mesh
            self.mesh = MeshShading(tri_p, m.uvs, m.tangents, m.object_ids, desc.textures)
            self.table = {"base_color": mats.base_color.astype(np.float64),
                          "roughness": mats.roughness.astype(np.float64),
                          "metallic": mats.metallic.astype(np.float64),
                          "specular": mats.specular.astype(np.float64),
                          "transmission": mats.transmission.astype(np.float64),
                          "ior": mats.ior.astype(np.float64),
                          "translucency": mats.translucency.astype(np.float64)}

    def _init_families(self) -> None:
        """Group rows whose programs differ only in constants (:func:`program.signature`):
        ``family[f]`` is the merged program, ``row_family`` (M,) its index (−1: no
        program) and ``row_index`` (M,) the row's index in its family."""
        self.row_family = np.full(self.n_rows, -1, np.int64)
        self.row_index = np.zeros(self.n_rows, np.int64)
        groups: dict[str, list[int]] = {}
        for row, prog in enumerate(self.programs):
            if prog is not None:
                groups.setdefault(signature(prog), []).append(row)
        self.families = []
        for f, rows in enumerate(groups.values()):
            self.families.append(merge([self.programs[r] for r in rows]))
            self.row_family[rows] = f
            self.row_index[rows] = np.arange(len(rows))

    # -- keys ------------------------------------------------------------------------

    def keys(self, valid: NDArray, prim: NDArray, mat: NDArray) -> NDArray:
        """(N,) shading keys of hits (module docstring): M + prim where the row's program
        changes the BSDF or has a bump-shadowing model (which needs the triangle), else
        the material row."""
        textured = valid & (self.row_bsdf[mat] | (self.row_shadowing[mat] > 0))
        return np.where(textured, self.n_rows + prim, mat)

    def shadowing(self, key: NDArray) -> NDArray | None:
        """(N,) bump-shadowing model codes of shading keys (:mod:`ercuts_core.bump_shadowing`;
        only keys ≥ M can have one), or None when the scene has none."""
        if not self.row_shadowing.any():
            return None
        key = np.asarray(key, np.int64).reshape(-1)
        return np.where(key >= self.n_rows, self.row_shadowing[self.rows(key)], 0).astype(np.int8)

    def rows(self, key: NDArray) -> NDArray:
        """(N,) material rows of shading keys."""
        key = np.asarray(key, np.int64)
        return np.where(key >= self.n_rows, self.tri_mat[np.maximum(key - self.n_rows, 0)], key)

    # -- evaluation ------------------------------------------------------------------

    def _by_family(self, rows: NDArray, sel: NDArray):
        """Yield (merged program, lane indices, lane_row) for the lanes ``sel`` grouped by
        program family (one evaluation per family, not per material: families share the
        per-node Python overhead; ``lane_row`` selects each lane's constants)."""
        lanes = np.flatnonzero(sel)
        if not len(lanes):
            return
        fam = self.row_family[rows[lanes]]
        order = np.argsort(fam, kind="stable")
        fam, lanes = fam[order], lanes[order]
        cuts = np.flatnonzero(np.diff(fam)) + 1
        for group in np.split(np.arange(len(lanes)), cuts):
            mine = lanes[group]
            yield self.families[int(fam[group[0]])], mine, self.row_index[rows[mine]]

    def shading_normals(self, valid: NDArray, prim: NDArray, b: NDArray, mat: NDArray,
                        ng: NDArray, ns: NDArray) -> NDArray:
        """(N, 3) shading normals after the programs' normal output (normal map, bump), put
        on ng's side; lanes without a normal program keep ``ns``."""
        sel = valid & self.row_normal[mat]
        if not sel.any():
            return ns
        out = ns.copy()
        for program, lanes, lane_row in self._by_family(mat, sel):
            ctx = self.mesh.context(prim[lanes], b[lanes], ng[lanes], ns[lanes], lane_row)
            n = program.evaluate(ctx, ["normal"])["normal"]
            flip = (n * ng[lanes]).sum(1) < 0
            out[lanes] = np.where(flip[:, None], -n, n)
        return out

    def bsdf_params(self, key: NDArray, p: NDArray, ns: NDArray, ng: NDArray) -> dict[str, NDArray]:
        """Principled parameters per lane: base_color (N, 3), roughness, metallic, specular,
        transmission, ior, translucency (N,).

        Constant rows are gathered from the table; textured keys are evaluated per material.
        """
        key = np.asarray(key, np.int64).reshape(-1)
        rows = self.rows(key)
        out = {k: v[rows] for k, v in self.table.items()}
        textured = key >= self.n_rows
        if not textured.any():
            return out
        prim = np.where(textured, key - self.n_rows, 0)
        p, ns, ng = (np.asarray(a, np.float64).reshape(-1, 3) for a in (p, ns, ng))
        for program, lanes, lane_row in self._by_family(rows, textured):
            b = self.mesh.barycentrics(prim[lanes], p[lanes])
            ctx = self.mesh.context(prim[lanes], b, ng[lanes], ns[lanes], lane_row)
            for name, val in program.evaluate(ctx, BSDF_OUTPUTS).items():
                out[name][lanes] = val
        return out

    def alpha(self, prim: NDArray, b: NDArray) -> NDArray:
        """(N,) alpha in [0, 1] of hits (prim, barycentrics b); 1 for rows without alpha."""
        out = np.ones(len(prim))
        rows = self.tri_mat[prim]
        sel = self.row_alpha[rows]
        for program, lanes, lane_row in self._by_family(rows, sel):
            ng = self.tri_ng[prim[lanes]]
            ctx = self.mesh.context(prim[lanes], b[lanes], ng, ng, lane_row)
            out[lanes] = np.clip(program.evaluate(ctx, ["alpha"])["alpha"], 0.0, 1.0)
        return out

    def emission_at(self, prim: NDArray, p: NDArray) -> NDArray:
        """(N, 3) emitted radiance of emission programs at points p (N, 3) on triangles prim."""
        out = np.zeros((len(prim), 3))
        rows = self.tri_mat[prim]
        b = self.mesh.barycentrics(prim, p)
        ng = self.tri_ng[prim]
        for program, lanes, lane_row in self._by_family(rows, self.row_emission[rows]):
            ctx = self.mesh.context(prim[lanes], b[lanes], ng[lanes], ng[lanes], lane_row)
            out[lanes] = np.maximum(program.evaluate(ctx, ["emission"])["emission"], 0.0)
        return out

    def triangle_emission(self, emission: NDArray) -> NDArray:
        """(T, 3) per-triangle emitted radiance: the rows' constants, and for rows with an
        emission program the mean over a stratified grid of EMISSION_SAMPLES² points."""
        em = emission[self.tri_mat].astype(np.float64)
        tris = np.flatnonzero(self.row_emission[self.tri_mat]) if self.active else np.zeros(0, np.int64)
        if not len(tris):
            return em
        k = EMISSION_SAMPLES
        s, t = np.meshgrid((np.arange(k) + 0.5) / k, (np.arange(k) + 0.5) / k)
        su = np.sqrt(s.ravel())                      # uniform on the triangle [Turk 1990]
        grid = np.stack([1.0 - su, su * (1.0 - t.ravel()), su * t.ravel()], 1)   # (k², 3)
        prim = np.repeat(tris, len(grid))
        b = np.tile(grid, (len(tris), 1))
        ng = self.tri_ng[prim]
        rows = self.tri_mat[prim]
        for program, lanes, lane_row in self._by_family(rows, np.ones(len(prim), bool)):
            ctx = self.mesh.context(prim[lanes], b[lanes], ng[lanes], ng[lanes], lane_row)
            val = program.evaluate(ctx, ["emission"])["emission"]
            sums = np.zeros((len(em), 3))
            np.add.at(sums, prim[lanes], val)
            mine = np.unique(prim[lanes])
            em[mine] = np.maximum(sums[mine] / len(grid), 0.0)
        return em
