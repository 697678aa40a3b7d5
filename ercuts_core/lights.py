"""All emitters of a scene behind one vectorized interface (SmallVCM's illuminate/emit/radiance triple).

Light kinds (one global index ``l`` per light, selected with a power-proportional pmf):

======  =================  ===========================================  =============
kind    source             emission                                     hittable
======  =================  ===========================================  =============
POINT   point and spot     intensity I(ω) = I·spot(ω) [W/sr]           no (delta position)
SUN     directional        irradiance E [W/m²] along ``direction``     no (delta direction)
AREA    rect/ellipse       radiance L [W·sr⁻¹·m⁻²], one-sided           no (next-event only)
TRI     emissive triangle  radiance L, two-sided (Blender's Emission)   yes
ENV     world background   constant radiance L                          yes (escaped rays)
======  =================  ===========================================  =============

Spot falloff follows Cycles ≥ 4.0: smoothstep((cosθ − cos½)/((1 − cos½)·blend)), a hard
edge when blend = 0 (``blender/cycles src/kernel/light/spot.h``).

Densities (all include the light-selection pmf):

* ``illuminate``: solid-angle density at the receiver (``pdf_w``); delta lights report
  the selection pmf and ``is_delta``.
* ``emit``: area density of the start point ``pdf_pos`` and solid-angle density of the
  direction ``pdf_dir`` — the quantities BDPT needs for light subpaths and MIS
  [Veach 1997 §10.2; pbrt-v3 Light::Sample_Le / Pdf_Le]. Infinite lights (SUN, ENV)
  start on a disk of the scene's bounding-sphere radius facing the direction.

Emitted power of an area light is π·L·A; of an emissive triangle 2π·L·A (two sides).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .description import SHAPE_ELLIPSE, SceneDescription
from .sampling import (
    Distribution1D,
    coordinate_system,
    luminance,
    sample_cosine_hemisphere,
    sample_uniform_cone,
    sample_uniform_disk_concentric,
    sample_uniform_sphere,
    sample_uniform_triangle,
    to_world,
)
from .vecmath import dot, normalize

POINT, SUN, AREA, TRI, ENV = 0, 1, 2, 3, 4
_INV_4PI = 1.0 / (4.0 * np.pi)



def smoothstep(x: NDArray) -> NDArray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


@dataclass
class LightSample:
    """Result of :meth:`LightSet.illuminate` for N receivers.

    Attributes:
        Li: (N, 3) incident radiance (area/tri/env), I(ω)/d² (point) or E (sun).
        wi: (N, 3) unit direction receiver → light.
        dist: (N,) distance to the light point (inf for SUN/ENV).
        pdf_w: (N,) solid-angle density incl. selection (selection pmf for delta lights).
        is_delta: (N,) point/spot/sun.
        light: (N,) global light index.
        p: (N, 3) point on the light (for SUN/ENV: receiver + wi·2R).
        n: (N, 3) light normal at p (zeros for POINT; −wi... for SUN/ENV: the direction of travel).
        pdf_pos: (N,) area density of p as an ``emit`` start point incl. selection (BDPT).
        pdf_dir: (N,) solid-angle density that ``emit`` leaves p toward the receiver (BDPT).
        valid: (N,) the sample carries energy.
    """

    Li: NDArray
    wi: NDArray
    dist: NDArray
    pdf_w: NDArray
    is_delta: NDArray
    light: NDArray
    p: NDArray
    n: NDArray
    pdf_pos: NDArray
    pdf_dir: NDArray
    valid: NDArray


@dataclass
class Emission:
    """Result of :meth:`LightSet.emit`: the first vertex of N light subpaths.

    Attributes:
        p: (N, 3) start point; d: (N, 3) unit direction; n: (N, 3) light normal
            (zeros for POINT; the direction for SUN/ENV).
        Le: (N, 3) radiance along d (intensity for POINT, irradiance for SUN).
        pdf_pos: (N,) area density of p incl. selection (selection pmf for POINT).
        pdf_dir: (N,) solid-angle density of d (1 for SUN: delta direction).
        beta: (N, 3) Le·|cos|/(pdf_pos·pdf_dir): the subpath's initial throughput.
        light: (N,) global index; kind: (N,) kind.
        is_delta_pos, is_delta_dir, is_infinite: (N,) flags.
    """

    p: NDArray
    d: NDArray
    n: NDArray
    Le: NDArray
    pdf_pos: NDArray
    pdf_dir: NDArray
    beta: NDArray
    light: NDArray
    kind: NDArray
    is_delta_pos: NDArray
    is_delta_dir: NDArray
    is_infinite: NDArray


class LightSet:
    """The emitters of a clean :class:`SceneDescription` (after :func:`validate.sanitize`).

    Args:
        desc: the scene.
        tri_p: (T, 3, 3) float64 triangle vertices (the built scene's geometry).
        tri_ng: (T, 3) unit geometric normals; tri_area: (T,) areas [m²].
        tri_emission: (T, 3) per-triangle radiance overriding the materials' constants
            (textured emission, :meth:`ercuts_core.shading.materials.SceneShading.triangle_emission`):
            the *mean* radiance, used for the power-based light choice.
        emission_at: callable (triangles (N,), points (N, 3)) → (N, 3) radiance at points of
            triangles whose emission is textured (``tri_textured`` (T,) bool); hits, light
            samples and emitted subpaths use it, so textured emitters are exact per point.
    """

    def __init__(self, desc: SceneDescription, tri_p: NDArray, tri_ng: NDArray, tri_area: NDArray,
                 tri_emission: NDArray | None = None, emission_at=None, tri_textured: NDArray | None = None):
        self._init_bounds(tri_p)
        pl, sl, al = desc.point_lights, desc.sun_lights, desc.area_lights
        em = desc.materials.emission[desc.mesh.material_ids].astype(np.float64) \
            if desc.mesh.n_triangles else np.zeros((0, 3))
        if tri_emission is not None:
            em = np.asarray(tri_emission, np.float64)
        self.emissive_tris = np.flatnonzero(luminance(em) > 0)
        # Per-kind tables (float64).
        self.pt_pos = pl.position.astype(np.float64)
        self.pt_I = pl.intensity.astype(np.float64)
        self.pt_axis = normalize(pl.direction.astype(np.float64) + 1e-300)[0]
        self.pt_cos = pl.cos_half_angle.astype(np.float64)
        self.pt_blend = pl.blend.astype(np.float64)
        self.sun_dir = sl.direction.astype(np.float64)
        self.sun_E = sl.irradiance.astype(np.float64)
        self.ar_c = al.center.astype(np.float64)
        self.ar_u = al.axis_u.astype(np.float64)
        self.ar_v = al.axis_v.astype(np.float64)
        self.ar_n = al.normal.astype(np.float64)
        self.ar_L = al.radiance.astype(np.float64)
        self.ar_ellipse = al.shape == SHAPE_ELLIPSE
        uv = np.linalg.norm(np.cross(self.ar_u, self.ar_v), axis=1)
        self.ar_area = np.where(self.ar_ellipse, np.pi * uv, 4.0 * uv)
        self.tri_index = self.emissive_tris
        self.tri_p = tri_p[self.emissive_tris]
        self.tri_n = tri_ng[self.emissive_tris]
        self.tri_area = tri_area[self.emissive_tris]
        self.tri_L = em[self.emissive_tris]
        self.emission_at = emission_at
        self.tri_textured = (np.zeros(len(self.emissive_tris), bool) if tri_textured is None
                             else np.asarray(tri_textured, bool)[self.emissive_tris])
        if not self.tri_textured.any():
            self.emission_at = None
        self.env_L = desc.world_radiance.astype(np.float64)
        has_env = luminance(self.env_L) > 0
        # Global light table: kind and index within its kind.
        kinds = [np.full(len(self.pt_pos), POINT), np.full(len(self.sun_dir), SUN),
                 np.full(len(self.ar_c), AREA), np.full(len(self.tri_p), TRI),
                 np.full(int(has_env), ENV)]
        self.kind = np.concatenate(kinds).astype(np.int64)
        self.local = np.concatenate([np.arange(len(k)) for k in kinds]).astype(np.int64)
        self.n_lights = len(self.kind)
        self.distribution = Distribution1D(self._powers()) if self.n_lights else None
        # Map triangle id -> global light index (for hits on emissive triangles).
        self.tri_light = np.full(len(tri_p), -1, np.int64)
        first_tri = len(self.pt_pos) + len(self.sun_dir) + len(self.ar_c)
        self.tri_light[self.emissive_tris] = first_tri + np.arange(len(self.emissive_tris))
        self.env_light = self.n_lights - 1 if has_env else -1

    def _init_bounds(self, tri_p: NDArray) -> None:
        if len(tri_p):
            lo, hi = tri_p.reshape(-1, 3).min(0), tri_p.reshape(-1, 3).max(0)
        else:
            lo, hi = -np.ones(3), np.ones(3)
        self.center = 0.5 * (lo + hi)
        self.radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-3)

    def _powers(self) -> NDArray:
        """Selection weights ∝ emitted power (luminance)."""
        cone = np.where(self.pt_cos > -1, 2 * np.pi * (1 - self.pt_cos), 4 * np.pi)
        r2 = np.pi * self.radius**2
        return np.concatenate([
            cone * luminance(self.pt_I),
            r2 * luminance(self.sun_E),
            np.pi * self.ar_area * luminance(self.ar_L),
            2 * np.pi * self.tri_area * luminance(self.tri_L),
            [r2 * 4 * np.pi * luminance(self.env_L)] if self.env_light_exists() else [],
        ])

    def env_light_exists(self) -> bool:
        return bool(luminance(self.env_L) > 0)

    @property
    def empty(self) -> bool:
        return self.n_lights == 0

    def pmf(self, light: NDArray) -> NDArray:
        """(N,) selection probability of global light indices."""
        return self.distribution.pmf[light]

    # ------------------------------------------------------------ emitter geometry
    def spot_factor(self, i: NDArray, w_out: NDArray) -> NDArray:
        """(N,) Cycles spot falloff for point lights ``i`` emitting along unit ``w_out``."""
        c = dot(self.pt_axis[i], w_out)
        cos_h = self.pt_cos[i]
        width = (1.0 - cos_h) * self.pt_blend[i]
        soft = smoothstep((c - cos_h) / np.where(width > 0, width, 1.0))
        hard = (c > cos_h).astype(np.float64)
        f = np.where(width > 0, soft, hard)
        return np.where(cos_h <= -1.0, 1.0, f)

    def _area_point(self, i: NDArray, u: NDArray) -> NDArray:
        """(N, 3) points on area lights ``i`` from (N, 2) uniforms; uniform by area."""
        disk = sample_uniform_disk_concentric(u)
        sq = 2.0 * u - 1.0
        ab = np.where(self.ar_ellipse[i][:, None], disk, sq)
        return self.ar_c[i] + ab[:, :1] * self.ar_u[i] + ab[:, 1:] * self.ar_v[i]

    def tri_radiance_at(self, i: NDArray, p: NDArray) -> NDArray:
        """(N, 3) radiance of emissive triangles ``i`` (local indices) at points p (N, 3):
        ``tri_L`` unless the triangle's emission is textured (then evaluated at p)."""
        L = self.tri_L[i]
        if self.emission_at is not None and len(i):
            t = self.tri_textured[i]
            if t.any():
                L[t] = self.emission_at(self.tri_index[i[t]], p[t])
        return L

    def _tri_point(self, i: NDArray, u: NDArray) -> NDArray:
        b = sample_uniform_triangle(u)
        return np.einsum("nk,nkj->nj", b, self.tri_p[i])

    # ------------------------------------------------------------ next-event estimation
    def illuminate(self, x: NDArray, u_sel: NDArray, u: NDArray) -> LightSample:
        """Sample a light point as seen from receivers ``x`` (N, 3).

        Args:
            u_sel: (N,) uniforms for the light choice; u: (N, 2) for the point.
        """
        n = len(x)
        light, sel = self.distribution.sample(u_sel)
        kind, loc = self.kind[light], self.local[light]
        Li = np.zeros((n, 3))
        p = np.zeros((n, 3))
        nl = np.zeros((n, 3))
        pdf_area = np.ones(n)       # area density of p (per kind, without selection)
        pdf_dir = np.zeros(n)
        Lsurf = np.zeros((n, 3))
        r2 = 2.0 * self.radius
        # Point and spot lights.
        m = kind == POINT
        if m.any():
            i = loc[m]
            p[m] = self.pt_pos[i]
            w_out, d = normalize(x[m] - p[m])
            Li[m] = self.pt_I[i] * self.spot_factor(i, w_out)[:, None] / np.maximum(d, 1e-30)[:, None] ** 2
            pdf_dir[m] = np.where(self.pt_cos[i] > -1, 1.0 / (2 * np.pi * (1 - self.pt_cos[i])), _INV_4PI)
        m = kind == SUN
        if m.any():
            i = loc[m]
            p[m] = x[m] - self.sun_dir[i] * r2
            nl[m] = self.sun_dir[i]
            Li[m] = self.sun_E[i]
            pdf_area[m] = 1.0 / (np.pi * self.radius**2)
            pdf_dir[m] = 1.0
        surfaces = ((AREA, self._area_point, self.ar_n, self.ar_L, self.ar_area),
                    (TRI, self._tri_point, self.tri_n, self.tri_L, self.tri_area))
        for surface_kind, point, normal, radiance, area in surfaces:   # uniform in area
            m = kind == surface_kind
            if m.any():
                i = loc[m]
                p[m] = point(i, u[m])
                nl[m] = normal[i]
                Lsurf[m] = radiance[i] if surface_kind == AREA else self.tri_radiance_at(i, p[m])
                pdf_area[m] = 1.0 / area[i]
        m = kind == ENV
        if m.any():
            w = sample_uniform_sphere(u[m])
            p[m] = x[m] + w * r2
            nl[m] = -w
            Li[m] = self.env_L
            pdf_area[m] = 1.0 / (np.pi * self.radius**2)
            pdf_dir[m] = _INV_4PI
        wi, dist = normalize(p - x)
        infinite = (kind == SUN) | (kind == ENV)
        dist = np.where(infinite, np.inf, dist)
        is_delta = (kind == POINT) | (kind == SUN)
        # Solid-angle density for surface emitters: p_A · d² / |cos_l|.
        surf = (kind == AREA) | (kind == TRI)
        cos_l = -dot(nl, wi)
        facing = np.where(kind == AREA, cos_l > 0, np.abs(cos_l) > 0)
        Li = np.where((surf & facing)[:, None], Lsurf, Li)
        pdf_dir = np.where(surf, np.maximum(np.where(kind == AREA, cos_l, np.abs(cos_l)), 0) / np.pi
                           * np.where(kind == TRI, 0.5, 1.0), pdf_dir)
        pdf_w = np.where(surf, pdf_area * np.where(np.isfinite(dist), dist, 0) ** 2 /
                         np.maximum(np.abs(cos_l), 1e-300), 1.0)
        pdf_w = np.where(kind == ENV, _INV_4PI, pdf_w) * sel
        pdf_w = np.where(is_delta, sel, pdf_w)
        valid = (sel > 0) & (luminance(Li) > 0) & np.isfinite(pdf_w) & (pdf_w > 0)
        return LightSample(Li, wi, dist, pdf_w, is_delta, light, p, nl, pdf_area * sel, pdf_dir, valid)

    # ------------------------------------------------------------ hits on emitters
    def tri_radiance(self, prim: NDArray, p: NDArray | None = None) -> NDArray:
        """(N, 3) emitted radiance of triangles ``prim`` toward any side (two-sided), at the
        hit points ``p`` (N, 3) (needed only for textured emission; None: the mean)."""
        out = np.zeros((len(prim), 3))
        light = self.tri_light[prim]
        m = light >= 0
        if p is None:
            out[m] = self.tri_L[self.local[light[m]]]
        else:
            out[m] = self.tri_radiance_at(self.local[light[m]], np.asarray(p)[m])
        return out

    def pdf_illuminate_tri(self, x: NDArray, prim: NDArray, p: NDArray, ng: NDArray) -> NDArray:
        """(N,) solid-angle density with which :meth:`illuminate` from ``x`` picks point ``p``
        on emissive triangle ``prim`` (0 where the triangle does not emit)."""
        light = self.tri_light[prim]
        m = light >= 0
        out = np.zeros(len(prim))
        if m.any():
            w, d = normalize(p[m] - x[m])
            cos_l = np.abs(dot(ng[m], w))
            area = self.tri_area[self.local[light[m]]]
            out[m] = self.pmf(light[m]) / area * d**2 / np.maximum(cos_l, 1e-300)
        return out

    def env_radiance(self, n: int) -> NDArray:
        """(n, 3) radiance of escaped rays."""
        return np.broadcast_to(self.env_L, (n, 3)).copy()

    def pdf_illuminate_env(self, n: int) -> NDArray:
        """(n,) solid-angle density of :meth:`illuminate` choosing a given environment direction."""
        if self.env_light < 0:
            return np.zeros(n)
        return np.full(n, self.pmf(np.array([self.env_light]))[0] * _INV_4PI)

    # ------------------------------------------------------------ emission (light subpaths)
    def emit(self, u_sel: NDArray, u_pos: NDArray, u_dir: NDArray) -> Emission:
        """Sample light subpath origins: a light, a point on it and a direction."""
        n = len(u_sel)
        light, sel = self.distribution.sample(u_sel)
        kind, loc = self.kind[light], self.local[light]
        p = np.zeros((n, 3))
        d = np.zeros((n, 3))
        nl = np.zeros((n, 3))
        Le = np.zeros((n, 3))
        pdf_pos = np.ones(n)
        pdf_dir = np.ones(n)
        cos = np.ones(n)
        m = kind == POINT
        if m.any():
            i = loc[m]
            spot = self.pt_cos[i] > -1
            cos_max = np.where(spot, self.pt_cos[i], -1.0)
            w_local = sample_uniform_cone(u_dir[m], cos_max)
            t, b = coordinate_system(self.pt_axis[i])
            d[m] = to_world(w_local, t, b, self.pt_axis[i])
            p[m] = self.pt_pos[i]
            Le[m] = self.pt_I[i] * self.spot_factor(i, d[m])[:, None]
            pdf_dir[m] = 1.0 / (2 * np.pi * (1 - cos_max))
        for kind_id, dirs in ((SUN, None), (ENV, None)):
            m = kind == kind_id
            if not m.any():
                continue
            if kind_id == SUN:
                dm = self.sun_dir[loc[m]]
                Le[m] = self.sun_E[loc[m]]
            else:
                dm = -sample_uniform_sphere(u_dir[m])
                Le[m] = self.env_L
                pdf_dir[m] = _INV_4PI
            t, b = coordinate_system(dm)
            disk = sample_uniform_disk_concentric(u_pos[m]) * self.radius
            p[m] = self.center - dm * self.radius + disk[:, :1] * t + disk[:, 1:] * b
            d[m] = dm
            nl[m] = dm
            pdf_pos[m] = 1.0 / (np.pi * self.radius**2)
        m = (kind == AREA) | (kind == TRI)
        if m.any():
            area_m = kind[m] == AREA
            i = loc[m]
            pa = np.zeros((m.sum(), 3))
            na = np.zeros((m.sum(), 3))
            La = np.zeros((m.sum(), 3))
            A = np.ones(m.sum())
            if area_m.any():
                ia = i[area_m]
                pa[area_m] = self._area_point(ia, u_pos[m][area_m])
                na[area_m] = self.ar_n[ia]
                La[area_m] = self.ar_L[ia]
                A[area_m] = self.ar_area[ia]
            if (~area_m).any():
                it = i[~area_m]
                pa[~area_m] = self._tri_point(it, u_pos[m][~area_m])
                na[~area_m] = self.tri_n[it]
                La[~area_m] = self.tri_radiance_at(it, pa[~area_m])
                A[~area_m] = self.tri_area[it]
            # Two-sided triangles: u_dir[:,0] picks the side, then is rescaled.
            ud = u_dir[m].copy()
            side = np.ones(m.sum())
            two = ~area_m
            flip = two & (ud[:, 0] < 0.5)
            ud[:, 0] = np.where(two, np.where(flip, ud[:, 0] * 2, ud[:, 0] * 2 - 1), ud[:, 0])
            ud[:, 0] = np.clip(ud[:, 0], 0.0, np.nextafter(1.0, 0))
            side[flip] = -1.0
            nn = na * side[:, None]
            w_local = sample_cosine_hemisphere(ud)
            t, b = coordinate_system(nn)
            dm = to_world(w_local, t, b, nn)
            cos[m] = w_local[:, 2]
            p[m], d[m], nl[m], Le[m] = pa, dm, na, La
            pdf_pos[m] = 1.0 / A
            pdf_dir[m] = w_local[:, 2] / np.pi * np.where(two, 0.5, 1.0)
        pdf_pos = pdf_pos * sel
        denom = pdf_pos * pdf_dir
        ok = denom > 0
        beta = np.where(ok[:, None], Le * cos[:, None] / np.where(ok, denom, 1.0)[:, None], 0.0)
        is_inf = (kind == SUN) | (kind == ENV)
        return Emission(p, d, nl, Le, pdf_pos, pdf_dir, beta, light, kind,
                        kind == POINT, kind == SUN, is_inf)

    def pdf_emit(self, light: NDArray, p: NDArray, n: NDArray, d: NDArray) -> tuple[NDArray, NDArray]:
        """Densities with which :meth:`emit` produces (``p``, direction ``d``) on ``light``.

        Returns:
            pdf_pos (N,) incl. selection, pdf_dir (N,) solid angle (pbrt Light::Pdf_Le).
        """
        kind, loc = self.kind[light], self.local[light]
        sel = self.pmf(light)
        pdf_pos = np.ones(len(light))
        pdf_dir = np.zeros(len(light))
        m = kind == POINT
        if m.any():
            cos_h = self.pt_cos[loc[m]]
            inside = dot(self.pt_axis[loc[m]], d[m]) >= cos_h
            pdf_dir[m] = np.where(cos_h > -1, inside / (2 * np.pi * (1 - cos_h)), _INV_4PI)
        m = (kind == SUN) | (kind == ENV)
        pdf_pos[m] = 1.0 / (np.pi * self.radius**2)
        pdf_dir[kind == SUN] = 0.0
        pdf_dir[kind == ENV] = _INV_4PI
        m = kind == AREA
        if m.any():
            pdf_pos[m] = 1.0 / self.ar_area[loc[m]]
            pdf_dir[m] = np.maximum(dot(n[m], d[m]), 0) / np.pi
        m = kind == TRI
        if m.any():
            pdf_pos[m] = 1.0 / self.tri_area[loc[m]]
            pdf_dir[m] = np.abs(dot(n[m], d[m])) / np.pi * 0.5
        return pdf_pos * sel, pdf_dir
