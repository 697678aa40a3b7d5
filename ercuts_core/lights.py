"""All emitters of a scene behind one vectorized interface (SmallVCM's illuminate/emit/radiance triple).

Light kinds (one global index ``l`` per light, selected with a power-proportional pmf):

======  =================  ===========================================  =============
kind    source             emission                                     hittable
======  =================  ===========================================  =============
POINT   point and spot     intensity I(ω) = I·spot(ω) [W/sr]           no (delta position)
SUN     directional        irradiance E [W/m²] along ``direction``     no (delta direction)
AREA    rect/ellipse       radiance L [W·sr⁻¹·m⁻²], one-sided           no (next-event only)
TRI     emissive triangle  radiance L, two-sided (Blender's Emission)   yes
ENV     world background   radiance L(ω): constant, or an HDRI map      yes (escaped rays)
======  =================  ===========================================  =============

The environment is either the constant ``world_radiance`` (directions sampled uniformly on
the sphere, density 1/(4π)) or an equirectangular map (``SceneDescription.world_map``,
:class:`~ercuts_core.envmap.EnvMap`: bilinear lookup, directions importance-sampled ∝
luminance·sinθ). Every ENV quantity is a function of the direction ω *toward* the
environment: :meth:`LightSet.env_radiance`, :meth:`LightSet.env_pdf_dir`,
:meth:`LightSet.pdf_illuminate_env`; its selection power is πR²·∫Y(L(ω))dω (pbrt-v3
InfiniteAreaLight::Power).

Spot falloff follows Cycles ≥ 4.0: smoothstep((cosθ − cos½)/((1 − cos½)·blend)), a hard
edge when blend = 0 (``blender/cycles src/kernel/light/spot.h``).

Soft lights, as Cycles renders them: a point or spot light of radius r > 0 is a sphere or a
disk facing the receiver of radiance I/(π·r²) (:mod:`.sphere_lights`); a sun of angle θ > 0
has radiance E/(π·sin²(θ/2)) over the cone of half-angle θ/2, sampled uniformly in solid
angle (Cycles ``distant.h``); an area light of spread s < π emits into a cone with Cycles'
soft-box attenuation (:mod:`.area_spread`). None of them can be hit by rays (next-event
estimation and light tracing only), so their radius-0 / angle-0 / spread-π forms keep the
exact code paths (and images) of the delta and plain lights.

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

from . import area_spread, sphere_lights
from .description import SHAPE_ELLIPSE, SceneDescription
from .envmap import EnvMap
from .sampling import (
    Distribution1D,
    coordinate_system,
    cosine_cone_pdf,
    luminance,
    sample_cosine_cone,
    sample_cosine_hemisphere,
    sample_uniform_cone,
    sample_uniform_cone_omc,
    sample_uniform_disk_concentric,
    sample_uniform_sphere,
    sample_uniform_triangle,
    to_world,
    uniform_cone_pdf_omc,
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
        Li: (N, 3) incident radiance (area/tri/env, soft point/spot, sun with an angle),
            I(ω)/d² (point of radius 0) or E (sun of angle 0).
        wi: (N, 3) unit direction receiver → light.
        dist: (N,) distance to the light point (inf for SUN/ENV).
        pdf_w: (N,) solid-angle density incl. selection (selection pmf for delta lights).
        is_delta: (N,) point/spot of radius 0, sun of angle 0.
        light: (N,) global light index.
        p: (N, 3) point on the light (for SUN/ENV: receiver + wi·2R).
        n: (N, 3) light normal at p (zeros for POINT; −wi... for SUN/ENV: the direction of travel).
        pdf_pos: (N,) area density of p as an ``emit`` start point incl. selection (BDPT);
            soft point/spot: 1/(π·r²) per unit projected area of the emitted line.
        pdf_dir: (N,) solid-angle density that ``emit`` leaves p toward the receiver (BDPT);
            soft point/spot: scaled so that pdf_dir/dist² is the emission's (sphere_lights).
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
            (zeros for POINT; the direction for SUN/ENV). A point/spot light of radius r > 0
            starts its line on the sphere or at the line's closest point to the centre
            (:mod:`.sphere_lights`; :meth:`LightSet.emission_reaches` tests the first hit).
        Le: (N, 3) radiance along d (intensity for a point of radius 0, irradiance for a
            sun of angle 0).
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
        self.pt_radius = pl.radius.astype(np.float64)
        self.pt_sphere = pl.sphere.astype(bool)
        self.pt_soft = self.pt_radius > 0
        self.sun_dir = sl.direction.astype(np.float64)
        self.sun_E = sl.irradiance.astype(np.float64)
        half = 0.5 * sl.angle.astype(np.float64)
        self.sun_cone = half > 0
        self.sun_omc = 2.0 * np.sin(0.5 * half) ** 2           # 1 − cos(half), precise
        sin2 = np.where(self.sun_cone, np.sin(half) ** 2, 1.0)
        self.sun_L = self.sun_E / (np.pi * sin2)[:, None]      # radiance over the cone
        self.ar_c = al.center.astype(np.float64)
        self.ar_u = al.axis_u.astype(np.float64)
        self.ar_v = al.axis_v.astype(np.float64)
        self.ar_n = al.normal.astype(np.float64)
        self.ar_L = al.radiance.astype(np.float64)
        self.ar_ellipse = al.shape == SHAPE_ELLIPSE
        uv = np.linalg.norm(np.cross(self.ar_u, self.ar_v), axis=1)
        self.ar_area = np.where(self.ar_ellipse, np.pi * uv, 4.0 * uv)
        self.ar_plain = al.spread >= area_spread.PLAIN
        self.ar_half = np.where(self.ar_plain, 0.5 * np.pi, 0.5 * al.spread.astype(np.float64))
        self.ar_k = np.where(self.ar_plain, 1.0, area_spread.normalization(np.minimum(self.ar_half, 1.5)))
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
        wm = desc.world_map
        #: The HDRI (None: the constant ``env_L``); env_L is then the map's mean colour.
        self.env_map = EnvMap(wm.radiance, wm.rotation) if wm is not None else None
        self.env_L = desc.world_radiance.astype(np.float64) if self.env_map is None \
            else self.env_map.mean_rgb
        has_env = self.env_light_exists()
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
            [r2 * self._env_integral()] if self.env_light_exists() else [],
        ])

    def _env_integral(self) -> float:
        """∫ Y(L(ω)) dω over the sphere [W·m⁻²]."""
        if self.env_map is not None:
            return self.env_map.integral_Y
        return 4 * np.pi * luminance(self.env_L)

    def env_light_exists(self) -> bool:
        if self.env_map is not None:
            return self.env_map.total > 0
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
        soft = self._rows(m, loc, self.pt_soft)
        if soft.any():
            j = loc[soft]
            p[soft], pdf_soft, inside = sphere_lights.sample_from_receiver(
                self.pt_pos[j], self.pt_radius[j], self.pt_sphere[j], x[soft], u[soft])
        m = kind == SUN
        if m.any():
            i = loc[m]
            p[m] = x[m] - self.sun_dir[i] * r2
            nl[m] = self.sun_dir[i]
            Li[m] = self.sun_E[i]
            pdf_area[m] = 1.0 / (np.pi * self.radius**2)
            pdf_dir[m] = 1.0
        cone = self._rows(m, loc, self.sun_cone)
        if cone.any():
            j = loc[cone]
            w = self._sun_direction(j, -self.sun_dir[j], u[cone])
            p[cone], nl[cone], Li[cone] = x[cone] + w * r2, -w, self.sun_L[j]
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
        spread = self._rows(kind == AREA, loc, ~self.ar_plain)
        if spread.any():
            p[spread], pdf_area[spread], reach = self._spread_point(loc[spread], x[spread], u[spread])
        m = kind == ENV
        if m.any():
            w, pdf_dir[m] = self.env_sample(u[m])
            p[m] = x[m] + w * r2
            nl[m] = -w
            Li[m] = self.env_radiance(w)
            pdf_area[m] = 1.0 / (np.pi * self.radius**2)
        wi, dist = normalize(p - x)
        infinite = (kind == SUN) | (kind == ENV)
        dist = np.where(infinite, np.inf, dist)
        is_delta = ((kind == POINT) | (kind == SUN)) & ~soft & ~cone
        # Solid-angle density for surface emitters: p_A · d² / |cos_l|.
        surf = (kind == AREA) | (kind == TRI)
        cos_l = -dot(nl, wi)
        facing = np.where(kind == AREA, cos_l > 0, np.abs(cos_l) > 0)
        if spread.any():
            j = loc[spread]
            Lsurf[spread] *= (area_spread.attenuation(cos_l[spread], self.ar_half[j], self.ar_k[j])
                              * reach)[:, None]
        Li = np.where((surf & facing)[:, None], Lsurf, Li)
        pdf_dir = np.where(surf, np.maximum(np.where(kind == AREA, cos_l, np.abs(cos_l)), 0) / np.pi
                           * np.where(kind == TRI, 0.5, 1.0), pdf_dir)
        if spread.any():
            pdf_dir[spread] = self._spread_pdf_dir(loc[spread], cos_l[spread])
        pdf_w = np.where(surf, pdf_area * np.where(np.isfinite(dist), dist, 0) ** 2 /
                         np.maximum(np.abs(cos_l), 1e-300), 1.0)
        pdf_w = np.where(kind == ENV, pdf_dir, pdf_w) * sel
        pdf_w = np.where(is_delta, sel, pdf_w)
        if cone.any():
            pdf_w[cone] = sel[cone] * uniform_cone_pdf_omc(self.sun_omc[loc[cone]])
        if soft.any():
            pdf_w[soft] = sel[soft] * pdf_soft
            Li[soft], pdf_area[soft], pdf_dir[soft] = self._soft_point_sample(
                loc[soft], x[soft], p[soft], -wi[soft], dist[soft], inside)
        valid = (sel > 0) & (luminance(Li) > 0) & np.isfinite(pdf_w) & (pdf_w > 0)
        return LightSample(Li, wi, dist, pdf_w, is_delta, light, p, nl, pdf_area * sel, pdf_dir, valid)

    @staticmethod
    def _rows(m: NDArray, loc: NDArray, flag: NDArray) -> NDArray:
        """(N,) rows of kind mask ``m`` whose light (local index ``loc``) has ``flag`` set."""
        out = np.zeros(len(m), bool)
        out[m] = flag[loc[m]]
        return out

    def _sun_direction(self, j: NDArray, axis: NDArray, u: NDArray) -> NDArray:
        """(N, 3) directions uniform in the cone of suns ``j`` about unit ``axis`` (Cycles
        ``distant_light_sample``: half-angle = angle/2)."""
        t, b = coordinate_system(axis)
        return to_world(sample_uniform_cone_omc(u, self.sun_omc[j]), t, b, axis)

    def _soft_point_sample(self, j, x, p, w_out, dist, inside):
        """Radiance, pdf_pos (without selection) and pdf_dir of next-event samples p of soft
        point/spot lights ``j`` toward receivers x (:mod:`.sphere_lights` for the densities)."""
        r = self.pt_radius[j]
        spot = np.where(inside, 1.0, self.spot_factor(j, w_out))
        Li = self.pt_I[j] * (spot / (np.pi * r * r))[:, None]
        o = sphere_lights.line_start(self.pt_pos[j], self.pt_sphere[j], p, w_out)
        d_o2 = np.maximum(dot(x - o, x - o), 1e-300)
        pdf_dir = np.where(inside, 0.0, self._point_dir_pdf(j, w_out) * dist * dist / d_o2)
        return Li, 1.0 / (np.pi * r * r), pdf_dir

    def _point_dir_pdf(self, j: NDArray, w: NDArray) -> NDArray:
        """(N,) density of :meth:`emit`'s direction for point/spot lights ``j``: uniform in
        the spot cone (0 outside), uniform on the sphere for point lights."""
        cos_h = self.pt_cos[j]
        inside = dot(self.pt_axis[j], w) >= cos_h
        return np.where(cos_h > -1, inside / (2 * np.pi * (1 - cos_h)), _INV_4PI)

    def _spread_point(self, j: NDArray, x: NDArray, u: NDArray):
        """Points of spread area lights ``j`` for receivers x: uniform in the parameter box
        that can reach x (:func:`.area_spread.clip_box`).

        Returns:
            p (N, 3), area density (N,) (1 where nothing can reach: then reach = 0), reach
            (N,) 1.0 for points of the light that may light x, else 0.
        """
        c, au, av = self.ar_c[j], self.ar_u[j], self.ar_v[j]
        lo, hi, ok = area_spread.clip_box(x, c, au, av, self.ar_n[j], self.ar_half[j])
        ab = lo + (hi - lo) * u
        p = c + ab[:, :1] * au + ab[:, 1:] * av
        box = np.prod(hi - lo, axis=1) * np.linalg.norm(np.cross(au, av), axis=1)
        on_light = np.where(self.ar_ellipse[j], (ab * ab).sum(axis=1) <= 1.0, True)
        return p, np.where(ok, 1.0 / np.where(ok, box, 1.0), 1.0), (ok & on_light).astype(np.float64)

    def _spread_pdf_dir(self, j: NDArray, cos_l: NDArray) -> NDArray:
        """(N,) emission direction density of spread area lights ``j`` at cosθ ``cos_l``."""
        half = self.ar_half[j]
        return cosine_cone_pdf(cos_l, np.cos(half), np.sin(half))

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

    def env_radiance(self, w: NDArray) -> NDArray:
        """(N, 3) radiance arriving from unit directions ``w`` (N, 3) toward the environment
        (the radiance of escaped rays along ``w``)."""
        if self.env_map is not None:
            return self.env_map.lookup(w)
        return np.broadcast_to(self.env_L, (len(w), 3)).copy()

    def env_sample(self, u: NDArray) -> tuple[NDArray, NDArray]:
        """(N, 3) unit directions toward the environment from (N, 2) uniforms, and their (N,)
        solid-angle density without the selection pmf (uniform sphere for a constant world)."""
        if self.env_map is not None:
            return self.env_map.sample(u)
        return sample_uniform_sphere(u), np.full(len(u), _INV_4PI)

    def env_pdf_dir(self, w: NDArray) -> NDArray:
        """(N,) solid-angle density of :meth:`env_sample` producing directions ``w`` (N, 3)."""
        if self.env_map is not None:
            return self.env_map.pdf(w)
        return np.full(len(w), _INV_4PI)

    def pdf_illuminate_env(self, w: NDArray) -> NDArray:
        """(N,) solid-angle density of :meth:`illuminate` choosing environment directions
        ``w`` (N, 3) (selection pmf included; 0 without an environment light)."""
        if self.env_light < 0:
            return np.zeros(len(w))
        return self.pmf(np.array([self.env_light]))[0] * self.env_pdf_dir(w)

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
        soft = self._rows(m, loc, self.pt_soft)
        if soft.any():                         # a line within r of the centre (sphere_lights)
            j = loc[soft]
            r = self.pt_radius[j]
            p[soft] = sphere_lights.emit_points(self.pt_pos[j], r, self.pt_sphere[j], d[soft], u_pos[soft])
            Le[soft] /= (np.pi * r * r)[:, None]
            pdf_pos[soft] = 1.0 / (np.pi * r * r)
        for kind_id, dirs in ((SUN, None), (ENV, None)):
            m = kind == kind_id
            if not m.any():
                continue
            if kind_id == SUN:
                dm = self.sun_dir[loc[m]]
                Le[m] = self.sun_E[loc[m]]
                cone = self.sun_cone[loc[m]]
                if cone.any():                 # uniform in the sun's cone (Cycles distant.h)
                    rows, j = np.flatnonzero(m)[cone], loc[m][cone]
                    dm[cone] = self._sun_direction(j, self.sun_dir[j], u_dir[rows])
                    Le[rows], pdf_dir[rows] = self.sun_L[j], uniform_cone_pdf_omc(self.sun_omc[j])
            else:
                w, pdf_dir[m] = self.env_sample(u_dir[m])
                dm = -w
                Le[m] = self.env_radiance(w)
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
            spread = np.zeros(len(i), bool)
            spread[area_m] = ~self.ar_plain[i[area_m]]
            if spread.any():                   # cosine-weighted inside the spread cone
                j = i[spread]
                w_local[spread] = sample_cosine_cone(ud[spread], np.sin(self.ar_half[j]))
                att = area_spread.attenuation(w_local[spread, 2], self.ar_half[j], self.ar_k[j])
                La[spread] *= att[:, None]
            t, b = coordinate_system(nn)
            dm = to_world(w_local, t, b, nn)
            cos[m] = w_local[:, 2]
            p[m], d[m], nl[m], Le[m] = pa, dm, na, La
            pdf_pos[m] = 1.0 / A
            pdf_dir[m] = w_local[:, 2] / np.pi * np.where(two, 0.5, 1.0)
            if spread.any():
                pdf_dir[np.flatnonzero(m)[spread]] = self._spread_pdf_dir(i[spread], w_local[spread, 2])
        pdf_pos = pdf_pos * sel
        denom = pdf_pos * pdf_dir
        ok = denom > 0
        beta = np.where(ok[:, None], Le * cos[:, None] / np.where(ok, denom, 1.0)[:, None], 0.0)
        is_inf = (kind == SUN) | (kind == ENV)
        return Emission(p, d, nl, Le, pdf_pos, pdf_dir, beta, light, kind,
                        (kind == POINT) & ~self._rows(kind == POINT, loc, self.pt_soft),
                        (kind == SUN) & ~self._rows(kind == SUN, loc, self.sun_cone), is_inf)

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
            pdf_dir[m] = self._point_dir_pdf(loc[m], d[m])
        soft = self._rows(m, loc, self.pt_soft)
        pdf_pos[soft] = 1.0 / (np.pi * self.pt_radius[loc[soft]] ** 2)
        m = (kind == SUN) | (kind == ENV)
        pdf_pos[m] = 1.0 / (np.pi * self.radius**2)
        pdf_dir[kind == SUN] = 0.0
        cone = self._rows(kind == SUN, loc, self.sun_cone)
        if cone.any():
            j = loc[cone]
            inside = dot(self.sun_dir[j], d[cone]) >= 1.0 - self.sun_omc[j]
            pdf_dir[cone] = inside * uniform_cone_pdf_omc(self.sun_omc[j])
        m = kind == ENV
        if m.any():
            pdf_dir[m] = self.env_pdf_dir(-d[m])       # d: direction of travel, −d toward the map
        m = kind == AREA
        if m.any():
            pdf_pos[m] = 1.0 / self.ar_area[loc[m]]
            pdf_dir[m] = np.maximum(dot(n[m], d[m]), 0) / np.pi
        spread = self._rows(m, loc, ~self.ar_plain)
        if spread.any():
            pdf_dir[spread] = self._spread_pdf_dir(loc[spread], dot(n[spread], d[spread]))
        m = kind == TRI
        if m.any():
            pdf_pos[m] = 1.0 / self.tri_area[loc[m]]
            pdf_dir[m] = np.abs(dot(n[m], d[m])) / np.pi * 0.5
        return pdf_pos * sel, pdf_dir

    # ------------------------------------------------------------ helpers for the integrators
    def emission_reaches(self, light: NDArray, p0: NDArray, x1: NDArray) -> NDArray:
        """(N,) bool: light emitted by :meth:`emit` from ``p0`` on ``light`` lights its first
        hit ``x1``. False only for soft-falloff (disk) point/spot lights whose line misses the
        receiver's facing disk (:func:`.sphere_lights.reaches`); BDPT drops those subpaths."""
        out = np.ones(len(light), bool)
        kind, loc = self.kind[light], self.local[light]
        m = self._rows(kind == POINT, loc, self.pt_soft & ~self.pt_sphere)
        if m.any():
            j = loc[m]
            out[m] = sphere_lights.reaches(self.pt_pos[j], self.pt_radius[j], self.pt_sphere[j],
                                           p0[m], x1[m])
        return out

    def chain_vertex(self, light: NDArray, p: NDArray) -> NDArray:
        """(N, 3) light vertices as the ER chains store them: ``p``, except the centre of
        point/spot lights — the chains' target function treats a light of radius r > 0 as
        the point at its centre (the approximation is limited to where the VPLs go in the
        light's penumbra; direct light and the rough BDPT image render the radius exactly)."""
        kind = self.kind[light]
        m = kind == POINT
        if not m.any():
            return p
        out = p.copy()
        out[m] = self.pt_pos[self.local[light[m]]]
        return out

    def area_radiance(self, i: NDArray, w_out: NDArray) -> NDArray:
        """(N, 3) radiance of area lights ``i`` (local indices) along unit ``w_out`` leaving
        them: L in front (× the spread attenuation), 0 behind."""
        cos = dot(self.ar_n[i], w_out)
        out = self.ar_L[i] * (cos > 0)[:, None]
        spread = ~self.ar_plain[i]
        if spread.any():
            j = i[spread]
            out[spread] *= area_spread.attenuation(cos[spread], self.ar_half[j], self.ar_k[j])[:, None]
        return out

    @property
    def has_shapes(self) -> bool:
        """Some light has a shape rays can meet (:meth:`radiance_along`): an area light, a
        point/spot light with a radius or a sun with an angle."""
        return bool(len(self.ar_c) or self.pt_soft.any() or self.sun_cone.any())

    def radiance_along(self, o: NDArray, d: NDArray, t_max: NDArray) -> NDArray:
        """(N, 3) radiance reaching ray origins ``o`` along unit ``d`` (N, 3) from the lights
        that are not scene geometry — area lights (front side, spread included), point and
        spot lights with a radius (:mod:`.sphere_lights`: the sphere, or the disk facing
        ``o``) and suns with an angle (their cone, only for rays with ``t_max`` = inf) —
        nearer than ``t_max`` (N,) [m]; unoccluded up to t_max by construction. Lights are
        transparent to the rays that meet them, as in Cycles (``integrator_shade_light``
        continues the path past a light it hit, a transparent bounce): the radiance of every
        light shape the ray crosses before ``t_max`` adds up — two overlapping soft lights seen
        in a mirror show their sum where they overlap, not the nearer one's radiance.

        Next-event estimation is the only other way to reach these lights, and it cannot
        follow a delta lobe: the integrators add this after a mirror or glass event (the
        lights a mirror shows, as Cycles renders them). Emissive meshes and the world are
        hit as geometry/misses and are not included."""
        n = len(o)
        out = np.zeros((n, 3))
        t_max = np.asarray(t_max, np.float64)
        for i in range(len(self.ar_c)):                    # few lights: a loop over lights
            t, ab = self._area_hit(i, o, d)
            inside = np.where(self.ar_ellipse[i], (ab ** 2).sum(axis=1) <= 1.0,
                              (np.abs(ab) <= 1.0).all(axis=1))
            hit = inside & (t > 0) & (t < t_max)
            if hit.any():
                out[hit] += self.area_radiance(np.full(int(hit.sum()), i), -d[hit])
        for j in np.flatnonzero(self.pt_soft):
            t = self._soft_point_hit(j, o, d)
            hit = (t > 0) & (t < t_max)
            if hit.any():
                r = self.pt_radius[j]
                spot = self.spot_factor(np.full(int(hit.sum()), j), -d[hit])
                out[hit] += self.pt_I[j] * (spot / (np.pi * r * r))[:, None]
        for j in np.flatnonzero(self.sun_cone):
            cos = d @ self.sun_dir[j]                      # −d · (toward the sun = −sun_dir)
            hit = ~np.isfinite(t_max) & (1.0 - cos <= self.sun_omc[j])
            out[hit] += self.sun_L[j]
        return out

    def _area_hit(self, i: int, o: NDArray, d: NDArray) -> tuple[NDArray, NDArray]:
        """Ray distances t (N,) to area light i's plane (inf when parallel) and the hit's
        coordinates (N, 2) in units of its half axes u, v."""
        n, c, u, v = self.ar_n[i], self.ar_c[i], self.ar_u[i], self.ar_v[i]
        den = d @ n
        t = np.divide((c - o) @ n, den, out=np.full(len(o), np.inf), where=np.abs(den) > 1e-12)
        q = o + np.where(np.isfinite(t), t, 0.0)[:, None] * d - c
        ab = np.stack([(q @ u) / max(u @ u, 1e-300), (q @ v) / max(v @ v, 1e-300)], axis=1)
        return t, ab

    def _soft_point_hit(self, j: int, o: NDArray, d: NDArray) -> NDArray:
        """Ray distances (N,) to soft point light j (its sphere, or its disk facing the ray
        origin), inf on a miss or from inside the sphere."""
        c, r = self.pt_pos[j], self.pt_radius[j]
        oc = c - o
        if self.pt_sphere[j]:
            b = np.einsum("ij,ij->i", oc, d)
            disc = b * b - (np.einsum("ij,ij->i", oc, oc) - r * r)
            t = b - np.sqrt(np.maximum(disc, 0.0))
            return np.where((disc >= 0) & (t > 0), t, np.inf)
        m, dist = normalize(-oc)                           # the disk faces the origin
        den = np.einsum("ij,ij->i", d, m)
        t = np.divide(dist, -den, out=np.full(len(o), np.inf), where=den < -1e-12)
        q = o + np.where(np.isfinite(t), t, 0.0)[:, None] * d - c
        return np.where(np.einsum("ij,ij->i", q, q) <= r * r, t, np.inf)

    def pdf_illuminate_vertex(self, light: NDArray, x: NDArray, p: NDArray) -> NDArray:
        """(N,) density with which :meth:`illuminate` from receivers ``x`` picks the light
        vertex ``p`` of ``light``, in the vertex's own measure: area (area lights — the
        reachable box of spread lights — and emissive triangles), counting (point, spot and
        sun lights, as the ER chains store them) or solid angle (environment: ``p`` is then
        the unit direction toward it); the selection pmf included."""
        kind, loc = self.kind[light], self.local[light]
        area = np.ones(len(light))
        a, t = kind == AREA, kind == TRI
        area[a] = self.ar_area[loc[a]]
        area[t] = self.tri_area[loc[t]]
        out = self.pmf(light) / area
        spread = self._rows(a, loc, ~self.ar_plain)
        if spread.any():
            j = loc[spread]
            lo, hi, ok = area_spread.clip_box(x[spread], self.ar_c[j], self.ar_u[j], self.ar_v[j],
                                              self.ar_n[j], self.ar_half[j])
            ab = area_spread.plane_coordinates(p[spread] - self.ar_c[j], self.ar_u[j], self.ar_v[j])
            inside = ok & (ab >= lo).all(axis=1) & (ab <= hi).all(axis=1)
            box = np.prod(hi - lo, axis=1) * np.linalg.norm(np.cross(self.ar_u[j], self.ar_v[j]), axis=1)
            out[spread] = np.where(inside, self.pmf(light[spread]) / np.where(inside, box, 1.0), 0.0)
        env = kind == ENV
        if self.env_map is None:
            out[env] /= 4 * np.pi                     # uniform sphere (kept bit-identical)
        elif env.any():
            out[env] *= self.env_pdf_dir(p[env])
        return out

