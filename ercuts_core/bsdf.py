"""The one material model: Lambertian base + GGX microfacet reflection + a glass lobe, two-sided,
with delta lobes for perfectly smooth mirrors and glass.

Per lane (all directions world space, unit, pointing away from the surface; cosines are
taken with the shading normal n after the two-sided flip described below):

* alpha = max(roughness², 1e-3) (Principled/Disney remapping; the floor keeps roughness 0
  "rough but sharp": no delta lobe, finite values).
* Fresnel [Schlick 1994]  F(c) = F0 + (F90 − F0)(1 − c)⁵  with c = wi·h and
  F0 = lerp(F0_d, base, metallic),  F90 = lerp(F0_d, 1, metallic),  F0_d = 0.08·specular
  (Principled "Specular IOR Level": 0.5 ↔ F0 = 0.04). The *dielectric* part is the
  constant F0_d (F90 = F0 there); the *metallic* part is the full Schlick curve from the
  base colour to white. Why: with the constant diffuse weight below, a dielectric Fresnel
  that rises to 1 at grazing angles would reflect more than the incident energy (directional
  albedo ≈ 0.96 + 0.8 at cosθ = 0.05), and it would also make the "specular = 0" lobe
  non-zero; with F90 = F0_d the lobe is exactly zero when specular = metallic = 0.
* f_diffuse = kd/π,  kd = (1 − metallic)(1 − F0_d)·base  (constant weight: reciprocal and
  energy-bounded, kd + F ≤ 1 for base ≤ 1).
* f_spec = D(h)·G2(wo, wi)·F(wi·h) / (4 |n·wo| |n·wi|),  h = (wo + wi)/|wo + wi|, with the
  GGX/Trowbridge-Reitz NDF  D = α² / (π ((n·h)²(α² − 1) + 1)²)  [Walter et al. 2007, eq. 33]
  and the *height-correlated* Smith masking-shadowing
  G2 = 1/(1 + Λ(wo) + Λ(wi)),  Λ(w) = (√(1 + α² tan²θ) − 1)/2  [Heitz 2014, eqs. 72, 99].
  G2 and F(wi·h) = F(wo·h) are symmetric, so f(wo, wi) = f(wi, wo) exactly.

Sampling (one-sample MIS over the two lobes): lobe "specular" with probability
p_spec = s/(s + d), s = lerp(F0_d, 1, metallic), d = (1 − metallic)(1 − F0_d)·Y(base)
(Y = luminance); p_spec = 0 exactly when the specular lobe is zero, 1 when metallic = 1.
The specular lobe samples the GGX distribution of *visible* normals [Heitz 2018, JCGT 7(4)]
with the spherical-cap construction [Dupuy & Benyoub 2023] and reflects wo about it:
pdf_spec(wi) = G1(wo)·D(h)/(4 n·wo) [Heitz 2018, eqs. 3 and 17]; the diffuse lobe samples
cos/π. ``pdf()`` returns the mixture p_spec·pdf_spec + (1 − p_spec)·cos/π restricted to the
valid set, i.e. the true density of the valid outputs of ``sample()``.

Two-sidedness and validity: per call, a lane whose wo is below the geometric normal ng has
ns and ng flipped. f = 0 and pdf = 0 unless wo and wi are both strictly above the flipped
ng *and* above the flipped ns (cosines below ``COS_EPS`` count as "on the horizon").

Layers (Cycles' Principled BSDF, 4.x): metallic m, transmission t. The opaque dielectric
(diffuse + F0_d specular above) has weight o = (1 − m)(1 − t), the metal m, the *glass lobe*
tw = (1 − m)·t: a smooth dielectric interface with index η (``ior``; η_t/η_i = η when wo is on
the side ``ng`` points to, 1/η otherwise), exact unpolarised Fresnel reflectance F_r
[pbrt-v4 eq. 9.5], reflection weight tw (untinted), transmission tw·base, total internal
reflection; camera (radiance) transport through a refraction carries 1/η_rel², light
(importance, ``adjoint=True``) transport does not [Veach 1997 §5.2; pbrt-v4 §9.5.2]. So
kd = o(1 − F0_d)·base, F0 = o·F0_d + m·base, F90 = o·F0_d + m, and the selection
probabilities are s, d, tw normalised by s + d + tw.

Translucency (Cycles' Translucent BSDF, kernel ``bsdf_translucent``): a diffuse *transmission*
lobe f_dt = kdt/π for wo and wi on opposite sides of the surface (strictly below the flipped ns
and ng, as the glass lobe's transmission), sampled cosine-weighted about −ns (pdf |ns·wi|/π).
It is symmetric in wo and wi (reciprocal: f(wo, wi) = f(wi, wo)) and has no η factor, so the
adjoint is the same function; no bump shadowing. Its weight tl ∈ [0, 1] (``translucency``)
takes its share from the opaque dielectric layer *additively* beside the transmission weight:
with tl' = min(tl, 1 − t) the layers are metal m, glass (1 − m)·t, translucent (1 − m)·tl' and
opaque (1 − m)(1 − t − tl'), kdt = (1 − m)·tl'·base. Additive shares make the exporter's
linear parameter blends exact for mixes of Diffuse, Glass and Translucent BSDFs of one colour
(Mix(Glass, Translucent, f): t = 1 − f, tl = f; a product (1 − t)(1 − tl) would give the
translucent lobe only f²). Its selection probability is d_t/(s + d + tw + d_t), d_t =
(1 − m)·tl'·Y(base), like the diffuse lobe's; u0 picks, in order, specular [0, p_spec), diffuse,
translucent [1 − p_tr − p_dt, 1 − p_tr) and glass [1 − p_tr, 1).

Delta lobes: where α = roughness² ≤ ``DELTA_ALPHA`` (Cycles' singular threshold) the specular
lobe is a perfect mirror (Schlick F at wo·n, direction reflected about ns) and the glass lobe a
smooth interface; both are left out of ``eval``/``pdf`` and reached only by ``sample``, which
flags them (``BsdfSample.delta``): the weight is the lobe's factor over the discrete
probability of choosing it, and ``pdf`` that probability.

Rough glass (α above the threshold): the GGX dielectric of Walter et al. 2007 (eqs. 16, 21;
pbrt-v4 ``DielectricBxDF``): reflection kr·D·G2·F/(4|cos_i|cos_o) about h = wo + wi and
transmission kt·D·G2·(1 − F)·|wi·h||wo·h|/((wi·h + wo·h/η')²|cos_i|cos_o) about the generalized
half vector h ∝ wo + η'·wi (÷ η'² in radiance transport), F the exact Fresnel term at wo·h;
sampled through the visible normals of wo, reflecting with probability F. Single scattering
only (no multiple-scattering compensation: a white rough glass loses 0–55 % of the light,
tests/test_rough_glass.py).

Numerics: float64; every division is guarded; underflow is flushed silently, so results are
finite under ``np.errstate(all="raise")`` for grazing (n·wo = 0), wi = ±wo, roughness 0.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .arrays import take_rows
from .bump_shadowing import bump_shadowing
from .description import MaterialTable
from .sampling import INV_PI, coordinate_system, luminance, sample_cosine_hemisphere, to_local, to_world
from .vecmath import dot, normalize

F64 = NDArray[np.float64]
B = NDArray[np.bool_]

#: Smallest GGX alpha (roughness 0 → alpha 1e-3: a sharp but finite lobe).
ALPHA_MIN = 1e-3
#: Cosines at or below this count as grazing: f = 0 and pdf = 0 (avoids 1/cos blow-ups).
COS_EPS = 1e-10
#: GGX alpha at or below which the specular and glass lobes are perfectly smooth (delta lobes):
#: Cycles' threshold (alpha_x·alpha_y ≤ 1e-7, bsdf_microfacet.h), i.e. roughness ≤ 0.01778.
DELTA_ALPHA = 1e-7 ** 0.5
#: Principled/Glass default index of refraction and the accepted range.
DEFAULT_IOR = 1.5
IOR_MIN, IOR_MAX = 1.0 + 1e-4, 10.0


# ---------------------------------------------------------------------------------------
# Vector helpers
# ---------------------------------------------------------------------------------------


def _div(num: F64, den: F64) -> F64:
    """num/den where den > 0, else 0 (no floating-point warnings); broadcasts like ``/``."""
    num, den = np.asarray(num, np.float64), np.asarray(den, np.float64)
    out = np.zeros(np.broadcast_shapes(num.shape, den.shape), np.float64)
    np.divide(num, den, out=out, where=den > 0.0)
    return out


def _normalize(v: F64) -> F64:
    """Unit rows of (N, 3) ``v``; zero rows stay zero."""
    return normalize(v)[0]


def _as3(v: ArrayLike) -> F64:
    return np.asarray(v, dtype=np.float64).reshape(-1, 3)


def _oriented_normals(ns: ArrayLike, ng: ArrayLike) -> tuple[F64, F64]:
    """Unit (ns, ng), ns put on ng's side (inverted custom normals); zero rows stay zero."""
    ng = _normalize(_as3(ng))
    ns = _normalize(_as3(ns))
    return np.where((dot(ns, ng) < 0.0)[:, None], -ns, ns), ng


def _lobe_params(base_color: ArrayLike, roughness: ArrayLike, metallic: ArrayLike,
                 specular: ArrayLike, n: int, transmission: ArrayLike = 0.0,
                 ior: ArrayLike = DEFAULT_IOR, translucency: ArrayLike = 0.0) -> dict[str, NDArray]:
    """Per-lane lobe weights of :class:`Bsdf` from Principled parameters broadcast to n lanes.

    Returns the fields kd, f0, f90, kt, kdt (n, 3), alpha, p_spec, p_tr, p_dt, kr, eta (n,),
    is_diffuse, delta (n,) bool (formulas in the module docstring). Layering as Cycles'
    Principled BSDF (4.x): a metallic fraction m, a transmission fraction (1 − m)·t (the
    dielectric lobe), a translucent fraction (1 − m)·tl' (tl' = min(tl, 1 − t)) and the
    opaque dielectric (1 − m)(1 − t − tl') (diffuse + specular F0_d).
    """
    base = np.broadcast_to(np.clip(np.asarray(base_color, np.float64), 0.0, 1.0), (n, 3))
    r_raw = np.broadcast_to(np.clip(np.asarray(roughness, np.float64), 0.0, 1.0), (n,))
    metal = np.broadcast_to(np.clip(np.asarray(metallic, np.float64), 0.0, 1.0), (n,))
    spec = np.broadcast_to(np.asarray(specular, np.float64), (n,))
    trans = np.broadcast_to(np.clip(np.asarray(transmission, np.float64), 0.0, 1.0), (n,))
    eta = np.broadcast_to(np.clip(np.asarray(ior, np.float64), IOR_MIN, IOR_MAX), (n,))
    # translucency's share, beside the transmission's (module docstring): t + tl' ≤ 1
    tl = np.minimum(np.broadcast_to(np.clip(np.asarray(translucency, np.float64), 0.0, 1.0), (n,)),
                    1.0 - trans)
    f0_d = np.clip(0.08 * spec, 0.0, 1.0)
    opaque = (1.0 - metal) * (1.0 - trans - tl)     # weight of the opaque dielectric layer
    m, o = metal[:, None], opaque[:, None]
    kd = o * (1.0 - f0_d)[:, None] * base
    f0 = o * f0_d[:, None] + m * base
    f90 = o * f0_d[:, None] + m
    tw = (1.0 - metal) * trans                      # weight of the dielectric (glass) lobe
    kt = tw[:, None] * base                         # its transmission tint (reflection: white)
    tlw = (1.0 - metal) * tl                        # weight of the translucent lobe
    kdt = tlw[:, None] * base
    # Lobe-selection probabilities p_spec = s/total, p_tr = tw/total, p_dt = dt/total,
    # total = s + d + tw + dt (dt = 0 without translucency: the sums are unchanged bit for bit)
    s = opaque * f0_d + metal
    y = luminance(base)
    d = opaque * (1.0 - f0_d) * y
    dt = tlw * y
    total = s + d + tw + dt
    p_spec = np.clip(_div(s, total), 0.0, 1.0)
    p_tr = np.clip(_div(tw, total), 0.0, 1.0 - p_spec)
    p_dt = np.clip(_div(dt, total), 0.0, np.maximum(1.0 - p_spec - p_tr, 0.0))
    alpha = r_raw * r_raw
    return {"kd": kd, "f0": f0, "f90": f90, "alpha": np.maximum(alpha, ALPHA_MIN),
            "p_spec": p_spec, "is_diffuse": (s <= 0.0) & (tw <= 0.0), "kt": kt,
            "p_tr": p_tr, "kr": np.array(tw), "eta": np.array(eta), "delta": alpha <= DELTA_ALPHA,
            "kdt": kdt, "p_dt": p_dt}


# ---------------------------------------------------------------------------------------
# Microfacet terms (all on (N,) arrays of cosines with the shading normal)
# ---------------------------------------------------------------------------------------

def ggx_d(cos_h: F64, alpha: F64) -> F64:
    """GGX normal distribution D(h) [sr⁻¹] [Walter et al. 2007, eq. 33].

    Written as α²/(π (sin²θ_h + α² cos²θ_h)²); the bracket is >= min(α², 1) > 0.
    """
    a2 = alpha * alpha
    c2 = np.clip(cos_h, 0.0, 1.0) ** 2
    den = (1.0 - c2) + a2 * c2
    return np.where(cos_h > 0.0, _div(a2 * INV_PI, den * den), 0.0)


def smith_lambda(cos_t: F64, alpha: F64) -> F64:
    """Smith Λ for GGX [Heitz 2014, eq. 72], stable form α²tan²θ / (2(1 + √(1 + α²tan²θ))).

    Returns 0 where cos_t <= COS_EPS (those lanes are invalid anyway).
    """
    c2 = np.where(cos_t > COS_EPS, cos_t * cos_t, 1.0)
    x = alpha * alpha * np.maximum(1.0 - c2, 0.0) / c2
    return x / (2.0 * (1.0 + np.sqrt(1.0 + x)))


def schlick_fresnel(cos_d: F64, f0: F64, f90: F64) -> F64:
    """Schlick's approximation F0 + (F90 − F0)(1 − c)⁵ [Schlick 1994]. cos_d (N,), f0/f90 (N, 3)."""
    m = (1.0 - np.clip(cos_d, 0.0, 1.0)) ** 5
    return f0 + (f90 - f0) * m[:, None]


def fresnel_dielectric(cos_i: F64, eta: F64) -> tuple[F64, F64]:
    """Unpolarised Fresnel reflectance of a smooth dielectric interface [pbrt-v4 eq. 9.5].

    Args:
        cos_i: (N,) cosine of the incident direction with the normal on its side (≥ 0).
        eta: (N,) relative index η_t/η_i.
    Returns:
        (F_r (N,) in [0, 1], 1 under total internal reflection; cos_t (N,) ≥ 0, the
        transmitted cosine, 0 under total internal reflection).
    """
    c = np.clip(cos_i, 0.0, 1.0)
    sin2_t = (1.0 - c * c) / (eta * eta)
    tir = sin2_t >= 1.0
    cos_t = np.sqrt(np.clip(1.0 - sin2_t, 0.0, 1.0))
    r_par = _div(eta * c - cos_t, eta * c + cos_t)
    r_perp = _div(c - eta * cos_t, c + eta * cos_t)
    F = np.where(tir, 1.0, np.clip(0.5 * (r_par * r_par + r_perp * r_perp), 0.0, 1.0))
    return F, np.where(tir, 0.0, cos_t)


def _refract(w: F64, n: F64, cos_w: F64, eta: F64, cos_t: F64) -> F64:
    """(N, 3) refraction of unit w (N, 3) about unit n on w's side: −w/η + (cos_w/η − cos_t)·n
    [pbrt-v4 eq. 9.4]; cos_w = w·n, η = η_t/η_i, cos_t from :func:`fresnel_dielectric`."""
    return -w / eta[:, None] + (cos_w / eta - cos_t)[:, None] * n


def sample_ggx_vndf(wo_local: F64, alpha: F64, u: F64) -> F64:
    """Sample a GGX microfacet normal from the distribution of visible normals.

    Spherical-cap method [Dupuy & Benyoub 2023, Listing 3] for [Heitz 2018]: stretch wo to
    the α = 1 configuration, sample the cap of the unit sphere above −wo_std, add wo_std,
    and unstretch the resulting normal.

    Args:
        wo_local: (N, 3) unit outgoing directions in the shading frame with z > 0.
        alpha: (N,) GGX alpha.
        u: (N, 2) uniforms.
    Returns:
        (N, 3) unit microfacet normals m in the shading frame (m.z >= 0) with density
        G1(wo)·max(0, wo·m)·D(m)/(n·wo).
    """
    a = alpha[:, None]
    wo_std = _normalize(np.concatenate([wo_local[:, :2] * a, wo_local[:, 2:3]], axis=1))
    phi = 2.0 * np.pi * u[:, 0]
    z = (1.0 - u[:, 1]) * (1.0 + wo_std[:, 2]) - wo_std[:, 2]
    sin_t = np.sqrt(np.clip(1.0 - z * z, 0.0, 1.0))
    c = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), z], axis=1)
    h = c + wo_std
    m = np.concatenate([h[:, :2] * a, np.maximum(h[:, 2:3], 0.0)], axis=1)
    return _normalize(m)


# ---------------------------------------------------------------------------------------
# The BSDF
# ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class BsdfSample:
    """Result of :meth:`Bsdf.sample` (world space).

    Attributes:
        wi: (N, 3) sampled unit direction (away from the surface).
        f: (N, 3) BSDF value f(wo, wi) [sr⁻¹] (0 where invalid).
        pdf: (N,) solid-angle pdf of wi [sr⁻¹] (0 where invalid).
        weight: (N, 3) f·|ns·wi|/pdf (0 where invalid).
        valid: (N,) bool; False lanes must be terminated by the caller.
        delta: (N,) bool, True where a delta lobe (mirror, smooth glass) was sampled: then
            ``pdf`` is the discrete probability of the event, ``f`` = weight·pdf/|ns·wi| (the
            delta lobe's factor), and the direction must not be MIS-weighted against light
            sampling (light sampling cannot produce it) [pbrt-v4 §9.1.2].
    """

    wi: F64
    f: F64
    pdf: F64
    weight: F64
    valid: B
    delta: B | None = None

    @property
    def is_delta(self) -> B:
        """(N,) bool: the sampled lobe was a delta lobe (all False when none was)."""
        return np.zeros(len(self.valid), bool) if self.delta is None else self.delta


@dataclass(frozen=True, eq=False)
class Bsdf:
    """Per-lane material parameters at N shading points (structure of arrays).

    Attributes:
        ns: (N, 3) unit shading normals, flipped onto the side of ``ng`` at construction.
        ng: (N, 3) unit geometric normals (either side; the side of wo decides per call).
        kd: (N, 3) diffuse reflectance (1 − metallic)(1 − F0_d)·base; f_diffuse = kd/π.
        f0: (N, 3) Schlick F0 = lerp(F0_d, base, metallic).
        f90: (N, 3) Schlick F90 = lerp(F0_d, 1, metallic).
        alpha: (N,) GGX alpha = max(roughness², 1e-3).
        p_spec: (N,) probability of sampling the specular lobe.
        is_diffuse: (N,) bool, True where the lane has no specular or glass lobe (it may have
            a translucent one: ``kdt``).
        kt: (N, 3) glass-lobe weight (1 − metallic)·transmission·base (the transmission tint;
            the glass lobe's reflection has weight (1 − metallic)·transmission, untinted).
        p_tr: (N,) probability of sampling the glass lobe.
        kr: (N,) the glass lobe's reflection weight (1 − metallic)·transmission.
        eta: (N,) index of refraction of the side ``ng`` points away from (η outside = 1).
        delta: (N,) bool, the specular and glass lobes are perfectly smooth (delta lobes, not
            part of eval/pdf; only ``sample`` produces their directions).
        kdt: (N, 3) translucent (diffuse transmission) weight (1 − metallic)·tl'·base;
            f = kdt/π for wo and wi on opposite sides (module docstring).
        p_dt: (N,) probability of sampling the translucent lobe.
        n_smooth: (N, 3) unit smooth normals before a normal map/bump (on ``ng``'s side) and
        shadowing: (N,) int bump-shadowing model codes (:mod:`ercuts_core.bump_shadowing`),
            both None when no lane has one: the diffuse value kd/π is multiplied by
            S(light direction) ≤ 1, the pdf is unchanged. S makes f non-reciprocal: the light
            side is wi, or wo with ``adjoint=True`` (light subpaths).
    """

    ns: F64
    ng: F64
    kd: F64
    f0: F64
    f90: F64
    alpha: F64
    p_spec: F64
    is_diffuse: B
    kt: F64
    p_tr: F64
    kr: F64
    eta: F64
    delta: B
    kdt: F64
    p_dt: F64
    n_smooth: F64 | None = None
    shadowing: NDArray | None = None

    # -- construction ---------------------------------------------------------------

    @classmethod
    def from_params(cls, base_color: ArrayLike, roughness: ArrayLike, metallic: ArrayLike,
                    specular: ArrayLike, ns: ArrayLike, ng: ArrayLike, n_smooth: ArrayLike | None = None,
                    shadowing: ArrayLike | None = None, transmission: ArrayLike = 0.0,
                    ior: ArrayLike = DEFAULT_IOR, translucency: ArrayLike = 0.0) -> Bsdf:
        """Build from per-lane Principled parameters (broadcast to the N lanes of the normals).

        Args:
            base_color: (N, 3) linear RGB, clipped to [0, 1] (keeps the model energy-bounded).
            roughness, metallic: (N,) clipped to [0, 1].
            specular: (N,) "Specular IOR Level" >= 0 (F0_d = 0.08·specular, clipped to 1).
            ns, ng: (N, 3) shading / geometric normals (renormalized; zero rows give f = 0).
            n_smooth, shadowing: bump shadowing (class docstring), or None.
            transmission: (N,) Principled transmission weight in [0, 1] (1: glass).
            ior: (N,) index of refraction (clipped to [1.0001, 10]).
            translucency: (N,) weight of the translucent lobe in [0, 1] (1: a Translucent BSDF).
        """
        ns, ng = _oriented_normals(ns, ng)
        lobes = _lobe_params(base_color, roughness, metallic, specular, ng.shape[0], transmission, ior,
                             translucency)
        if n_smooth is not None and shadowing is not None:
            lobes.update(n_smooth=_oriented_normals(n_smooth, ng)[0],
                         shadowing=np.asarray(shadowing, np.int8).reshape(-1))
        return cls(ns=ns, ng=ng, **lobes)

    @classmethod
    def from_table(cls, table: MaterialTable, mat_idx: ArrayLike, ns: ArrayLike,
                   ng: ArrayLike) -> Bsdf:
        """Gather per-lane parameters from ``table`` rows ``mat_idx`` (N,) int.

        The lobe parameters are computed once per material row and gathered (the same
        arithmetic as :meth:`from_params` on the gathered rows, so bit-identical).
        """
        idx = np.asarray(mat_idx, dtype=np.int64).reshape(-1)
        ns, ng = _oriented_normals(ns, ng)
        rows = _lobe_params(table.base_color.astype(np.float64), table.roughness.astype(np.float64),
                            table.metallic.astype(np.float64), table.specular.astype(np.float64),
                            len(table.roughness), table.transmission.astype(np.float64),
                            table.ior.astype(np.float64), table.translucency.astype(np.float64))
        return cls(ns=ns, ng=ng, **{k: take_rows(v, idx) for k, v in rows.items()})

    def __len__(self) -> int:
        return int(self.alpha.shape[0])

    def subset(self, mask_or_idx: ArrayLike) -> Bsdf:
        """The lanes selected by a (N,) bool mask or an integer index array."""
        sel = np.asarray(mask_or_idx)
        return Bsdf(**{f: take_rows(getattr(self, f), sel) for f in _FIELDS
                       if getattr(self, f) is not None})

    @cached_property
    def all_diffuse(self) -> bool:
        """True when no lane has a specular lobe: eval/pdf/sample take the Lambert-only path.

        Exact, not an approximation: a diffuse lane has F0 = F90 = 0 and p_spec = 0, so the
        general formulas reduce to f = kd/π, pdf = cos/π bit for bit (tests/test_bsdf.py).
        """
        return bool(self.is_diffuse.all())

    @cached_property
    def has_delta(self) -> bool:
        """True when some lane has a delta lobe (a smooth specular or glass lobe)."""
        return bool((self.delta & ((self.p_spec > 0.0) | (self.p_tr > 0.0))).any())

    @cached_property
    def has_rough_glass(self) -> bool:
        """True when some lane has a rough (non-delta) glass lobe."""
        return bool(((self.p_tr > 0.0) & ~self.delta).any())

    @cached_property
    def translucent(self) -> B:
        """(N,) bool: the lane has a translucent (diffuse transmission) lobe."""
        return self.kdt.max(axis=1) > 0.0

    @cached_property
    def has_translucent(self) -> bool:
        """True when some lane has a translucent lobe."""
        return bool(self.translucent.any())

    @cached_property
    def reflect_only(self) -> B:
        """(N,) bool: no lobe of the lane transmits (no glass, no translucent lobe), so f = 0
        unless wo and wi lie on one side of the surface."""
        return (self.p_tr <= 0.0) & ~self.translucent

    @cached_property
    def is_delta(self) -> B:
        """(N,) bool: every lobe of the lane is a delta lobe (a perfect mirror, smooth glass):
        eval and pdf are 0 for every direction, so no connection or light sample can reach it."""
        smooth = self.delta | ((self.p_spec <= 0.0) & (self.p_tr <= 0.0))
        return smooth & ~self.is_diffuse & (self.kd.max(axis=1) <= 0.0) & ~self.translucent

    @cached_property
    def is_specular_or_glass(self) -> B:
        """(N,) bool: the lane has no diffuse or translucent part and every lobe is a delta lobe
        (:attr:`is_delta`), the glass lobe (a smooth or rough dielectric interface), or a
        reflection lobe of any roughness: a mirror, glass or a metal. No VPL can shine through
        glass; VPLs gathered at (or standing on) a sharp lobe are dominated by rare peaks (a
        white glossy floor's VPL image was ×880 / ×26 / ×2.3 its energy at roughness 0.05 /
        0.1 / 0.2: 1/Ê1 at sharp receivers); and a VPL emits like a diffuse patch, so one on a
        metal sends the metal's light in a cosine instead of along its lobe, whatever the
        roughness (tests/blender/test_gltf_cycles.py's box of metal stripes at roughness 0.6:
        the floor beside it 64 % short of its indirect light, in front 30–50 % over, while
        such metals held VPLs). So ERCUTS's gather follows the camera through such a surface
        (``vpl.follow_specular``) and its chains leave it out. A lobe with a diffuse part
        keeps its VPLs (a dielectric's specular layer carries a few percent of its light)."""
        no_diffuse = (self.kd.max(axis=1) <= 0.0) & ~self.translucent   # diffuse nor translucent
        glass = (self.p_tr > 0.0) & (self.p_spec <= 0.0)
        sharp = (self.p_spec > 0.0) & (self.p_tr <= 0.0)
        return self.is_delta | (no_diffuse & (glass | sharp))

    # -- evaluation -------------------------------------------------------------------

    def _flipped_normals(self, wo: F64) -> tuple[F64, F64]:
        """(ns, ng) flipped per lane onto the side of wo (two-sided surfaces)."""
        sign = np.where(dot(wo, self.ng) < 0.0, -1.0, 1.0)[:, None]   # ×(±1) is exact
        return self.ns * sign, self.ng * sign

    def _diffuse_weight(self, wo: F64, wi: F64, adjoint: bool) -> F64 | float:
        """1/π, or 1/π·S (N,) with the bump shadowing S of the light-side direction."""
        if self.shadowing is None:
            return INV_PI
        # S is unchanged when ns and n_smooth flip together: the unflipped pair is used
        return INV_PI * bump_shadowing(self.shadowing, self.n_smooth, self.ns, wo if adjoint else wi)

    def _eval_pdf(self, wo: F64, wi: F64, flipped: tuple[F64, F64] | None = None,
                  adjoint: bool = False) -> tuple[F64, F64, F64, B]:
        """Shared core of eval/pdf/sample (``flipped``: this call's ``_flipped_normals(wo)``).

        Returns:
            f (N, 3) [sr⁻¹], pdf (N,) [sr⁻¹], cos_i = ns·wi (N,), valid (N,) bool.
        """
        ns, ng = self._flipped_normals(wo) if flipped is None else flipped
        cos_o, cos_i = dot(wo, ns), dot(wi, ns)
        valid = ((cos_o > COS_EPS) & (cos_i > COS_EPS)
                 & (dot(wo, ng) > COS_EPS) & (dot(wi, ng) > COS_EPS))
        inv_pi = self._diffuse_weight(wo, wi, adjoint)
        if self.all_diffuse:
            # Lambert only: f = kd/π, pdf = cos_i/π on the valid set (see all_diffuse).
            w = np.where(valid, inv_pi, 0.0)          # kd ≥ 0 finite: kd·0 = +0 exactly
            f, pdf = self.kd * w[:, None], np.where(valid, cos_i * INV_PI, 0.0)
            if self.has_translucent:                  # the diffuse lobe is chosen with 1 − p_dt
                pdf = pdf * (1.0 - self.p_dt)
        else:
            f, pdf, valid = self._reflection_and_glass(wo, wi, ns, ng, cos_o, cos_i, valid, inv_pi,
                                                       adjoint)
        if self.has_translucent:
            f_t, pdf_t, valid_t = self._translucent(wo, wi, ns, ng, cos_o, cos_i)
            f, pdf, valid = f + f_t, pdf + pdf_t, valid | valid_t
        return f, pdf, cos_i, valid

    def _reflection_and_glass(self, wo: F64, wi: F64, ns: F64, ng: F64, cos_o: F64, cos_i: F64,
                              valid: B, inv_pi: F64, adjoint: bool) -> tuple[F64, F64, B]:
        """Diffuse + GGX reflection (Heitz 2014) and the rough glass lobe of :meth:`_eval_pdf`:
        f (N, 3) [sr⁻¹], their share of the mixture pdf (N,) [sr⁻¹] and validity (N,)."""
        # Half vector terms; wo + wi is computed the same way for (wo, wi) and (wi, wo)
        h_len = np.sqrt(dot(wo + wi, wo + wi))
        cos_h = np.clip(_div(cos_o + cos_i, h_len), 0.0, 1.0)
        cos_d = np.clip(0.5 * h_len, 0.0, 1.0)  # wi·h = |wo + wi|/2 for unit wo, wi
        D = ggx_d(cos_h, self.alpha)
        lam_o, lam_i = smith_lambda(cos_o, self.alpha), smith_lambda(cos_i, self.alpha)
        G2 = 1.0 / (1.0 + (lam_o + lam_i))  # height-correlated [Heitz 2014, eq. 99]
        F = schlick_fresnel(cos_d, self.f0, self.f90)
        cc = np.where(valid & ~self.delta, 4.0 * cos_o * cos_i, 0.0)  # delta lobes: not in f
        f_spec = F * _div(D * G2, cc)[:, None]
        kd_pi = self.kd * (inv_pi if self.shadowing is None else inv_pi[:, None])
        f = np.where(valid[:, None], kd_pi + f_spec, 0.0)
        # Mixture pdf of sample(): VNDF reflection pdf G1(wo) D / (4 cos_o) and cos/π
        pdf_spec = _div(D / (1.0 + lam_o), np.where(valid & ~self.delta, 4.0 * cos_o, 0.0))
        pdf_diff = np.maximum(cos_i, 0.0) * INV_PI
        p_diff = np.maximum(1.0 - self.p_spec - self.p_tr - self.p_dt, 0.0)
        pdf = np.where(valid, self.p_spec * pdf_spec + p_diff * pdf_diff, 0.0)
        if self.has_rough_glass:
            f_g, pdf_g, valid_g = self._rough_glass(wo, wi, ns, ng, cos_o, cos_i, adjoint)
            f, pdf, valid = f + f_g, pdf + self.p_tr * pdf_g, valid | valid_g
        return f, pdf, valid

    def _translucent(self, wo: F64, wi: F64, ns: F64, ng: F64, cos_o: F64,
                     cos_i: F64) -> tuple[F64, F64, B]:
        """The translucent lobe (Cycles' ``bsdf_translucent``): f = kdt/π (N, 3), its share of
        the mixture pdf p_dt·|cos_i|/π (N,) and validity, where wo is above and wi strictly below
        the flipped normals ns and ng (a refraction's side test, as the rough glass lobe's).
        Symmetric in (wo, wi) and the same in both transport directions (no η factor)."""
        ok = (self.translucent & (cos_o > COS_EPS) & (dot(wo, ng) > COS_EPS)
              & (cos_i < -COS_EPS) & (dot(wi, ng) < -COS_EPS))
        f = np.where(ok[:, None], self.kdt * INV_PI, 0.0)
        pdf = np.where(ok, self.p_dt * (-cos_i) * INV_PI, 0.0)
        return f, pdf, ok

    def _rough_glass(self, wo: F64, wi: F64, ns: F64, ng: F64, cos_o: F64, cos_i: F64,
                     adjoint: bool) -> tuple[F64, F64, B]:
        """The rough glass lobe (GGX dielectric, Walter et al. 2007; pbrt-v4 DielectricBxDF):
        f (N, 3), its own pdf (N,) (reflection with probability F, transmission 1 − F, each
        through the visible-normal density of the generalized half vector) and validity.

        Reflection: kr·D·G2·F/(4|cos_i|cos_o), h = wo + wi. Transmission (wi below the flipped
        normals): kt·D·G2·(1 − F)·|wi·h||wo·h| / ((wi·h + wo·h/η')²|cos_i|cos_o), h ∝ wo + η'wi
        [Walter et al. 2007, eqs. 16, 21], η' = η_t/η_i; radiance transport ÷ η'²."""
        lanes = (self.p_tr > 0.0) & ~self.delta
        up = (cos_o > COS_EPS) & (dot(wo, ng) > COS_EPS) & lanes
        refl = up & (cos_i > COS_EPS) & (dot(wi, ng) > COS_EPS)
        trans = up & (cos_i < -COS_EPS) & (dot(wi, ng) < -COS_EPS)
        eta_rel = self._eta_rel(wo)
        etap = np.where(trans, eta_rel, 1.0)
        wm = _normalize(wo + etap[:, None] * wi)
        wm = np.where((dot(wm, ns) < 0.0)[:, None], -wm, wm)
        d_o, d_i, cos_m = dot(wo, wm), dot(wi, wm), dot(wm, ns)
        ok = (refl | trans) & (d_o > 0.0) & (d_i * cos_i > 0.0)   # no back-facing microfacets
        F, _ = fresnel_dielectric(d_o, eta_rel)
        a_i = np.abs(cos_i)
        D = ggx_d(cos_m, self.alpha)
        lam_o = smith_lambda(cos_o, self.alpha)
        G2 = 1.0 / (1.0 + lam_o + smith_lambda(a_i, self.alpha))
        vndf = _div(D * d_o, cos_o * (1.0 + lam_o))           # G1(wo)·D·(wo·h)/cos_o
        den_t = (d_i + d_o / etap) ** 2
        scale = 1.0 if adjoint else _div(np.ones_like(etap), etap * etap)
        f_r = _div(D * G2 * F, 4.0 * a_i * cos_o)[:, None] * self.kr[:, None]
        f_t = (_div(D * G2 * (1.0 - F) * np.abs(d_i * d_o), den_t * a_i * cos_o) * scale)[:, None] * self.kt
        pdf_r = F * _div(vndf, 4.0 * d_o)
        pdf_t = (1.0 - F) * _div(vndf * np.abs(d_i), den_t)
        is_t = trans[:, None]
        f = np.where(ok[:, None], np.where(is_t, f_t, f_r), 0.0)
        pdf = np.where(ok, np.where(trans, pdf_t, pdf_r), 0.0)
        return f, pdf, ok

    def eval(self, wo: ArrayLike, wi: ArrayLike, adjoint: bool = False) -> F64:
        """BSDF value f_r(wo, wi) (no cosine factor), (N, 3) [sr⁻¹]; ``adjoint``: wo is the
        light side (class docstring)."""
        with np.errstate(under="ignore"):
            return self._eval_pdf(_as3(wo), _as3(wi), adjoint=adjoint)[0]

    def pdf(self, wo: ArrayLike, wi: ArrayLike) -> F64:
        """Solid-angle pdf (N,) [sr⁻¹] with which :meth:`sample` (given wo) returns wi."""
        with np.errstate(under="ignore"):
            return self._eval_pdf(_as3(wo), _as3(wi))[1]

    def eval_pdf(self, wo: ArrayLike, wi: ArrayLike, adjoint: bool = False) -> tuple[F64, F64]:
        """``(eval(wo, wi, adjoint), pdf(wo, wi))`` from one evaluation: (N, 3), (N,) [sr⁻¹]."""
        with np.errstate(under="ignore"):
            f, pdf, _, _ = self._eval_pdf(_as3(wo), _as3(wi), adjoint=adjoint)
        return f, pdf

    def sample(self, wo: ArrayLike, u: ArrayLike, adjoint: bool = False) -> BsdfSample:
        """Importance-sample wi given wo.

        Args:
            wo: (N, 3) unit outgoing directions (away from the surface).
            u: (N, 3) uniforms; u[:, 0] selects the lobe, u[:, 1:] the direction.
            adjoint: wo is the light side (light subpaths; class docstring).
        Returns:
            :class:`BsdfSample`; lanes with wo or wi under the (flipped) horizon are invalid.
        """
        wo = _as3(wo)
        u = np.asarray(u, dtype=np.float64).reshape(-1, 3)
        with np.errstate(under="ignore"):
            flipped = self._flipped_normals(wo)
            ns = flipped[0]
            t, b = coordinate_system(ns)
            wi_l = sample_cosine_hemisphere(u[:, 1:3])
            if not self.all_diffuse:  # (all diffuse: p_spec = 0, the cosine lobe is always chosen)
                wo_l = to_local(wo, t, b, ns)
                # Lanes with wo under the shading horizon are invalid; sample them about +z
                wo_l = np.where((wo_l[:, 2] > COS_EPS)[:, None], wo_l, [0.0, 0.0, 1.0])
                # Specular: reflect wo about a visible GGX normal; diffuse: cosine lobe
                m = sample_ggx_vndf(wo_l, self.alpha, u[:, 1:3])
                wi_spec = 2.0 * dot(wo_l, m)[:, None] * m - wo_l
                wi_l = np.where((u[:, 0] < self.p_spec)[:, None], wi_spec, wi_l)
                if self.has_rough_glass:
                    # a specular reflection below the surface is no sample (the glass lobe's
                    # pdf would read it as a refraction)
                    below = (u[:, 0] < self.p_spec) & (wi_l[:, 2] <= 0.0)
                    wi_l = np.where(below[:, None], 0.0, wi_l)
                    wi_l = self._sample_rough_glass(wo, wo_l, m, u[:, 0], wi_l)
            if self.has_translucent:
                # translucent lanes (u0 in [1 − p_tr − p_dt, 1 − p_tr)): the cosine lobe about −ns
                u0 = u[:, 0]
                pick = (u0 >= 1.0 - self.p_tr - self.p_dt) & (u0 < 1.0 - self.p_tr)
                wi_l = np.where(pick[:, None], wi_l * np.array([1.0, 1.0, -1.0]), wi_l)
            wi = _normalize(to_world(wi_l, t, b, ns))
            f, pdf, cos_i, valid = self._eval_pdf(wo, wi, flipped, adjoint)
            valid &= pdf > 0.0
            weight = np.where(valid[:, None], f * _div(np.abs(cos_i), pdf)[:, None], 0.0)
            sample = BsdfSample(wi=wi, f=f, pdf=np.where(valid, pdf, 0.0), weight=weight, valid=valid)
            if self.has_delta:
                sample = self._sample_delta(sample, wo, flipped, u, adjoint)
        return sample

    def _eta_rel(self, wo: F64) -> F64:
        """(N,) relative index η_t/η_i of the glass lobe for wo: η when wo is on the side ``ng``
        points to (entering), 1/η when it leaves."""
        return np.where(dot(wo, self.ng) > 0.0, self.eta, 1.0 / self.eta)

    def eta_rel(self, wo: ArrayLike) -> F64:
        """(N,) relative index η' = η_t/η_i of the glass lobe for unit wo (N, 3) (as in eval)."""
        return self._eta_rel(_as3(wo))

    def _sample_rough_glass(self, wo: F64, wo_l: F64, m: F64, u0: F64, wi_l: F64) -> F64:
        """(N, 3) local directions: where u0 picked the rough glass lobe (u0 ≥ 1 − p_tr), the
        reflection (probability F, from the rescaled u0) or the refraction of wo about the
        visible GGX normal m [Walter et al. 2007 §5.3; pbrt-v4 DielectricBxDF::Sample_f];
        total internal reflection reflects. Other lanes keep ``wi_l``."""
        pick = (u0 >= 1.0 - self.p_tr) & ~self.delta
        eta_rel = self._eta_rel(wo)
        d_o = dot(wo_l, m)
        F, cos_t = fresnel_dielectric(d_o, eta_rel)
        v = _div(u0 - (1.0 - self.p_tr), self.p_tr)
        refl = 2.0 * d_o[:, None] * m - wo_l
        refr = _refract(wo_l, m, d_o, eta_rel, cos_t)
        reflect = v < F
        wi_g = np.where(reflect[:, None], refl, refr)
        # a reflection below the surface or a refraction above it is no sample (pbrt-v4):
        # the zero vector makes the lane invalid (the pdf would read it as the other event)
        wrong = np.where(reflect, wi_g[:, 2] <= 0.0, wi_g[:, 2] >= 0.0)
        wi_g = np.where(wrong[:, None], 0.0, wi_g)
        return np.where(pick[:, None], wi_g, wi_l)

    def _sample_delta(self, sample: BsdfSample, wo: F64, flipped: tuple[F64, F64], u: F64,
                      adjoint: bool) -> BsdfSample:
        """Replace the lanes of ``sample`` whose lobe choice u[:, 0] picked a delta lobe: the
        perfect mirror of a smooth specular lobe (u0 < p_spec), or the glass lobe
        (u0 ≥ 1 − p_tr): Fresnel reflection with probability F_r, refraction otherwise."""
        ns, ng = flipped
        u0 = u[:, 0]
        mirror = (u0 < self.p_spec) & self.delta
        glass = (u0 >= 1.0 - self.p_tr) & self.delta
        lanes = np.flatnonzero(mirror | glass)
        if len(lanes) == 0:
            return sample
        n_l, g_l, wo_l = ns[lanes], ng[lanes], wo[lanes]
        cos_o = dot(wo_l, n_l)
        refl = 2.0 * cos_o[:, None] * n_l - wo_l
        # Mirror: Schlick F at wo·n, chosen with probability p_spec
        F_m = schlick_fresnel(cos_o, self.f0[lanes], self.f90[lanes])
        w_m = F_m * _div(np.ones(len(lanes)), self.p_spec[lanes])[:, None]
        # Glass: exact dielectric Fresnel
        eta_rel = self._eta_rel(wo)[lanes]
        Fr, cos_t = fresnel_dielectric(cos_o, eta_rel)
        reflect = u[lanes, 1] < Fr
        refr = _refract(wo_l, n_l, cos_o, eta_rel, cos_t)
        p_g = self.p_tr[lanes]
        w_r = np.repeat(_div(self.kr[lanes], p_g)[:, None], 3, axis=1)
        # Radiance (camera) transport through a refraction scales by 1/η_rel² [Veach 1997 §5.2]
        scale = 1.0 if adjoint else 1.0 / (eta_rel * eta_rel)
        w_t = self.kt[lanes] * _div(scale * np.ones(len(lanes)), p_g)[:, None]
        is_m = mirror[lanes]
        wi = np.where(is_m[:, None], refl, np.where(reflect[:, None], refl, refr))
        wi = _normalize(wi)
        weight = np.where(is_m[:, None], w_m, np.where(reflect[:, None], w_r, w_t))
        prob = np.where(is_m, self.p_spec[lanes], p_g * np.where(reflect, Fr, 1.0 - Fr))
        # Valid: reflections stay above the (flipped) geometric normal, refractions go below it
        side = dot(wi, g_l)
        ok = np.where(is_m | reflect, side > COS_EPS, side < -COS_EPS) & (cos_o > COS_EPS) & (prob > 0.0)
        weight = np.where(ok[:, None], weight, 0.0)
        cos_i = np.abs(dot(wi, n_l))
        out = {k: np.array(getattr(sample, k), copy=True) for k in ("wi", "f", "pdf", "weight", "valid")}
        out["wi"][lanes] = wi
        out["weight"][lanes] = weight
        out["pdf"][lanes] = np.where(ok, prob, 0.0)
        out["f"][lanes] = weight * _div(np.where(ok, prob, 0.0), cos_i)[:, None]
        out["valid"][lanes] = ok
        delta = np.zeros(len(u0), bool)
        delta[lanes] = True
        return BsdfSample(**out, delta=delta)

    def albedo(self) -> F64:
        """Cheap reflectance estimate kd + F0, (N, 3), for Russian roulette and AOV passes.

        Not the directional albedo: ignores Fresnel growth at grazing and Smith losses; the
        glass lobe counts with its transmission tint, the translucent lobe with kdt (its
        directional albedo, exactly).
        """
        return np.clip(self.kd + self.f0 + self.kt + self.kdt, 0.0, 1.0)


#: The per-lane array fields of :class:`Bsdf` (what ``subset`` selects).
_FIELDS = ("ns", "ng", "kd", "f0", "f90", "alpha", "p_spec", "is_diffuse", "kt", "p_tr", "kr", "eta",
           "delta", "kdt", "p_dt", "n_smooth", "shadowing")


def bsdf_max_value(table: MaterialTable, mat_idx: ArrayLike) -> F64:
    """Practical upper bound of f over directions, (N, 3) [sr⁻¹], for the Lightcuts material bound.

    Exact for the diffuse and translucent parts (kd/π + kdt/π; they never both reach one
    direction, so the sum is loose by the smaller one). For the specular part it is the value of the lobe
    peak at normal incidence (wo = wi = n: D = 1/(πα²), G2 = 1) with the largest Fresnel
    value max(F0, F90) = F90:  F90/(4π α²). The true supremum is unbounded at grazing angles
    (f_spec ∝ 1/(n·wo n·wi)), so this is an approximation for glossy materials: the
    lightcuts use the per-cluster bound :func:`ggx_cosine_bound` at glossy receivers
    (:class:`ercuts_core.integrators.ercuts.lightcuts.GlossyReceivers`). Delta lobes are not
    part of ``Bsdf.eval`` (no VPL lights them), so their bound is 0. The rough glass term
    below is no bound either (reflection ×10³ at grazing views, transmission ×1.5,
    tests/test_rough_glass_bound.py): the lightcuts use :func:`rough_glass_cosine_bound` there.
    """
    idx = np.asarray(mat_idx, dtype=np.int64).reshape(-1)
    n = idx.shape[0]
    up = np.tile([0.0, 0.0, 1.0], (n, 1))
    bsdf = Bsdf.from_table(table, idx, up, up)
    spec_peak = _div(np.ones(n), 4.0 * np.pi * bsdf.alpha ** 2)
    no_spec = bsdf.is_diffuse | bsdf.delta          # delta lobes: not in eval, so no bound either
    spec = np.where(no_spec[:, None], 0.0, np.maximum(bsdf.f0, bsdf.f90) * spec_peak[:, None])
    # Rough glass: the lobes' values at normal incidence (h = n), reflection kr·D/4 and
    # transmission kt·D·η'²/(η' − 1)² (Walter et al. 2007 eq. 21 with wi·h = −1, wo·h = 1,
    # radiance ÷ η'²: kt·D/(η' − 1)²·η'²/η'²), the larger of η' = η and 1/η; D = 1/(πα²).
    eta = bsdf.eta
    t_peak = np.maximum(eta, 1.0 / eta) ** 2 / np.maximum((eta - 1.0) ** 2, 1e-6)
    glass = np.where((bsdf.delta | (bsdf.p_tr <= 0.0))[:, None], 0.0,
                     (0.25 * bsdf.kr[:, None] + bsdf.kt * t_peak[:, None])
                     * _div(np.ones(n), np.pi * bsdf.alpha ** 2)[:, None])
    return bsdf.kd * INV_PI + spec + glass + bsdf.kdt * INV_PI


def ggx_cosine_bound(cos_o: ArrayLike, alpha: ArrayLike, cos_r: ArrayLike) -> F64:
    """Upper bound (N,) of D(h)·G2(wo, wi)·(n·wi) / (4 |n·wo| |n·wi|) = D·G2/(4 n·wo) over
    every wi whose angle to the mirror direction r = 2(n·wo)n − wo is at least
    θ_r = arccos(cos_r), i.e. of f_spec·cos θ_i / F for the GGX lobe of :class:`Bsdf`.

    Multiplied by max(F0, F90) (Schlick's F lies between F0 and F90) it bounds the
    specular part of the lightcut material term M = f·cos θ_i over a cluster whose box
    is seen under angles ≥ θ_r from r (the receiver cosine cancels the 1/(n·wi) of the
    microfacet BRDF, so no minimum of n·wi over the box is needed).  Derivation:

    * Half-vector cone.  wi is the mirror image of wo about its half vector h:
      wi = R(h) = 2(wo·h)h − wo, and r = R(n).  R is 2-Lipschitz on the unit sphere
      (for a tangent step dh ⊥ h, |dR|² = 4|dh|²((wo·ê)² + (wo·h)²) ≤ 4|dh|², ê = dh/|dh|),
      so angle(wi, r) ≤ 2·angle(h, n):  θ_h ≥ θ_r/2 and
      cos θ_h ≤ cos(θ_r/2) = √((1 + cos_r)/2).  This is the bound over the lobe's
      reflection cone of Walter et al. 2005 (§4.1, Phong: the cosine to r bounded over
      the cluster's box), carried to the half vector; the converse direction (h moves by
      *at most* half of wi's motion) is false near grazing angles (algorithm.md §E.2(d)).
    * D.  The GGX NDF [Walter et al. 2007, eq. 33] increases with cos θ_h for α ≤ 1, so
      D ≤ D(√((1 + cos_r)/2)); cos_r ≥ 1 (r inside the cone) gives the peak 1/(πα²).
    * G2.  Height-correlated Smith [Heitz 2014, eq. 99]: G2 = 1/(1 + Λ(wo) + Λ(wi)) ≤
      1/(1 + Λ(wo)) = G1(wo) since Λ ≥ 0.  It keeps the bound finite at grazing wo:
      G1(wo)/(4 n·wo) = 1/(2(n·wo + √((n·wo)² + α²(1 − (n·wo)²)))) ≤ 1/(2α sin θ_o).
    * Lanes with n·wo ≤ COS_EPS have f = 0 (bound 0).

    Args:
        cos_o: (N,) n·wo with the lobe's (flipped) shading normal.
        alpha: (N,) GGX alpha.
        cos_r: (N,) upper bound of cos∠(r, wi) over the directions (values > 1 act as 1).
    """
    cos_o = np.asarray(cos_o, np.float64)
    alpha = np.asarray(alpha, np.float64)
    cos_h = np.sqrt(0.5 * (1.0 + np.clip(np.asarray(cos_r, np.float64), -1.0, 1.0)))
    g1_4 = _div(1.0, 4.0 * np.maximum(cos_o, 0.0) * (1.0 + smith_lambda(cos_o, alpha)))
    return np.where(cos_o > COS_EPS, ggx_d(cos_h, alpha) * g1_4, 0.0)


def refracted_direction(wo: ArrayLike, n: ArrayLike, eta: ArrayLike) -> tuple[F64, B]:
    """The refraction t (N, 3) of unit wo (N, 3) about the unit normal n (N, 3) on wo's side,
    relative index ``eta`` (N,) = η_t/η_i [pbrt-v4 eq. 9.4], and (N,) bool: it exists
    (n·wo > 0 and no total internal reflection); elsewhere t = −n."""
    wo, n = _as3(wo), _as3(n)
    eta = np.asarray(eta, np.float64).reshape(-1)
    cos_o = dot(wo, n)
    F, cos_t = fresnel_dielectric(np.clip(cos_o, 0.0, 1.0), eta)
    ok = (cos_o > 0.0) & (F < 1.0)
    return np.where(ok[:, None], _refract(wo, n, cos_o, eta, cos_t), -n), ok


def fresnel_perp(cos_i: ArrayLike, eta: ArrayLike) -> F64:
    """s-polarised Fresnel reflectance R_s = ((c − s)/(c + s))², s = √(η² − 1 + c²) = η·cos θ_t
    (1 under total internal reflection), (N,), of a dielectric interface of relative index η
    (η_t/η_i) at incidence cosine c = cos_i ∈ [0, 1] [pbrt-v4 eq. 9.3 (r_⊥)].

    An upper bound of the unpolarised reflectance F = (R_s + R_p)/2 of
    :func:`fresnel_dielectric` (R_p = R_s·cos²(θ_i + θ_t)/cos²(θ_i − θ_t) ≤ R_s), and R_s is
    non-increasing in c (s/c is monotone in c), so F(c) ≤ fresnel_perp(c_lo) for every
    c ≥ c_lo.  F itself is not monotone for large η (at η = 10 it dips near Brewster's
    angle), R_s is.
    """
    c = np.clip(np.asarray(cos_i, np.float64), 0.0, 1.0)
    eta = np.asarray(eta, np.float64)
    s2 = (eta - 1.0) * (eta + 1.0) + c * c
    s = np.sqrt(np.maximum(s2, 0.0))
    r = _div(c - s, c + s)
    return np.where(s2 > 0.0, r * r, 1.0)


def rough_glass_cosine_bound(cos_o: ArrayLike, alpha: ArrayLike, eta: ArrayLike, w_min: ArrayLike,
                             w_max: ArrayLike, cos_r: ArrayLike, cos_t: ArrayLike) -> tuple[F64, F64]:
    """Upper bounds (refl, trans), (N,) each, of the rough glass lobe's material term
    M = f(wo, wi)·|n·wi| over a set of directions wi [sr⁻¹], per unit lobe weight: the
    reflection part (wi above the surface) is ≤ kr·refl, the transmission part (wi below)
    ≤ kt·trans, in radiance transport (``Bsdf.eval(adjoint=False)``: the ÷ η'² of
    Walter et al. 2007 eq. 21's radiance form is in).

    The set of directions (a lightcut cluster's box B seen from the point, Walter et al. 2005
    §4) enters through four cosine bounds over it (Walter's box-in-axis-frame bound, signed:
    ``lightcuts.signed_cosine_bound``): ``w_min`` ≤ wo·wi ≤ ``w_max``, cos∠(r, wi) ≤ ``cos_r``
    (r = 2(n·wo)n − wo the mirror direction), cos∠(t, wi) ≤ ``cos_t`` (t the refraction of wo
    about n, pbrt-v4 eq. 9.4, :func:`refracted_direction`; ignored where wo is beyond the
    critical angle).  Directions are unit vectors; M in sr⁻¹ (f in sr⁻¹ times a cosine).

    Args:
        cos_o: (N,) n·wo with the lobe's normal flipped to wo's side (≤ COS_EPS: M = 0).
        alpha: (N,) GGX alpha (≤ 1).
        eta: (N,) relative index η' = η_t/η_i for this wo (``Bsdf.eta_rel``; ≠ 1).
        w_min, w_max, cos_r, cos_t: (N,) the cosine bounds above.

    Derivation (e = η', c = wo·h, h the (generalized) half vector, G1(wo) = 1/(1 + Λ(wo))):

    * Reflection [Walter et al. 2007 eq. 20]: M = D(h)·G2·F(c)/(4 n·wo).  G2 ≤ G1(wo)
      [Heitz 2014 eq. 99], D ≤ D(√((1 + cos_r)/2)) (the half-vector cone of
      :func:`ggx_cosine_bound`), and F ≤ R_s(c) ≤ R_s(√((1 + w_min)/2)) (:func:`fresnel_perp`;
      c = wo·h = √((1 + wo·wi)/2)).  So refl = R_s·D·G1(wo)/(4 n·wo).
    * Transmission [eqs. 16, 21]: with h ∝ −(wo + e·wi) (e > 1) or +(wo + e·wi) (e < 1),
      wi is the refraction of wo about h, −wi·h = s/e with s = √(e² − 1 + c²), and
      |wo + e·wi| = |c − s| = |1 − e²|/(c + s).  The receiver cosine cancels |n·wi| and

          M = D(h)·G2·(1 − F)·c·|wi·h| / (n·wo·(c − s)²) ≤ G1(wo)/(n·wo) · D(h) · T(c),
          T(c) = c·s·(c + s)² / (e·(e² − 1)²),

      T increasing in c (T(1) = 1/(e − 1)²: the peak at normal incidence).
    * c over the set: c = f(wo·wi) = σ(1 + e·w)/√((1 − e)² + 2e(1 + w)) (σ = −1 for e > 1,
      +1 for e < 1) is decreasing in w on the transmitting range w ≤ −min(e, 1/e) (beyond it
      there is no refraction: no transmission, or total internal reflection), so
      c ≤ c_hi = f(min(w_min, −min(e, 1/e))) and c ≥ c_lo = f(min(w_max, −min(e, 1/e))).
    * θ_h = ∠(n, h) from below, two ways; D uses the smaller cosine:
      (i) the triangle inequality θ_h ≥ θ_o − ∠(wo, h) ≥ θ_o − arccos(c_lo);
      (ii) the refraction map h ↦ wi stretches arcs by at most K(c) = |c − s|/s (the
      Jacobian of the generalized half vector, Walter et al. 2007 eq. 17, inverted:
      |dh| = e·|P_h dwi|/|wo + e·wi| ≥ e·|wi·h|·|dwi|/|c − s|), K decreasing in c, and c ≥
      min(n·wo, c_lo) on the arc from n to h; the arc maps to a path from t to wi, so
      ∠(t, wi) ≤ K·θ_h.  Then tan(θ_h/2) ≥ tan(θ_t/2)/K for K ≤ 1 (tan convex; where
      θ_t/K ≥ π no such h exists) and sin(θ_h/2) ≥ sin(θ_t/2)/K for K > 1 (sin concave),
      θ_t = arccos(cos_t): only square roots, so the compiled kernel
      (``kernels.bounds.rough_glass_bound1``) computes the same numbers.
      For e > 1, K < 1 everywhere (entering glass compresses directions ×(1 − 1/e) at normal
      incidence); for e < 1, K → ∞ at the critical angle (no information there).
    * 1 − F = (T_s + T_p)/2 ≤ (1 − R_s(c))/2 + 1/2 ≤ 1 − R_s(c_hi)/2 (R_s non-increasing in
      c, :func:`fresnel_perp`); G2 ≤ G1(wo) as above.  So
      trans = D(cos θ_h,max)·T(c_hi)·(1 − R_s(c_hi)/2)·G1(wo)/(n·wo).

    Both are finite (G1(wo)/(n·wo) ≤ 2/(α sin θ_o) at grazing wo) and exact at the peak
    (wi = r or t at normal incidence, up to F and G1(wi)).
    """
    co = np.asarray(cos_o, np.float64)
    alpha = np.asarray(alpha, np.float64)
    e = np.asarray(eta, np.float64)
    live = co > COS_EPS
    co = np.clip(co, 0.0, 1.0)
    g1 = _div(np.ones_like(co), np.where(live, co * (1.0 + smith_lambda(co, alpha)), 0.0))
    # Reflection
    wlo = np.clip(np.asarray(w_min, np.float64), -1.0, 1.0)
    c_r = np.sqrt(0.5 * (1.0 + wlo))
    d_r = ggx_d(np.sqrt(0.5 * (1.0 + np.clip(np.asarray(cos_r, np.float64), -1.0, 1.0))), alpha)
    refl = fresnel_perp(c_r, e) * d_r * (0.25 * g1)
    # Transmission: the range of c = wo·h
    e2m1 = (e - 1.0) * (e + 1.0)
    wc = -np.minimum(e, _div(np.ones_like(e), e))
    sig = np.where(e > 1.0, -1.0, 1.0)

    def half_cos(w: F64) -> F64:
        w = np.minimum(np.clip(np.asarray(w, np.float64), -1.0, 1.0), wc)
        v2 = (1.0 - e) * (1.0 - e) + 2.0 * e * (1.0 + w)
        return np.clip(sig * (1.0 + e * w) / np.sqrt(v2), 0.0, 1.0)

    c_hi, c_lo = half_cos(wlo), half_cos(w_max)
    s_hi = np.sqrt(np.maximum(e2m1 + c_hi * c_hi, 0.0))
    t_hi = c_hi * s_hi * (c_hi + s_hi) ** 2 / (e * e2m1 * e2m1)
    # (i) θ_h ≥ θ_o − arccos(c_lo)
    sin_o = np.sqrt(np.maximum(1.0 - co * co, 0.0))
    sin_lo = np.sqrt(np.maximum(1.0 - c_lo * c_lo, 0.0))
    c1 = np.where(c_lo > co, np.minimum(co * c_lo + sin_o * sin_lo, 1.0), 1.0)
    # (ii) ∠(t, wi) ≤ K·θ_h
    c_m = np.minimum(co, c_lo)
    s_m = np.sqrt(np.maximum(e2m1 + c_m * c_m, 0.0))
    k = _div(np.abs(c_m - s_m), s_m)
    k2 = k * k
    q = np.clip(np.asarray(cos_t, np.float64), -1.0, 1.0)
    c_tan = _div((1.0 + q) * k2 - (1.0 - q), (1.0 + q) * k2 + (1.0 - q))
    c_sin = 1.0 - _div(1.0 - q, k2)
    c2 = np.where((s_m > 0.0) & (k > 0.0), np.where(k <= 1.0, c_tan, c_sin), 1.0)
    trans = ggx_d(np.minimum(c1, c2), alpha) * t_hi * (1.0 - 0.5 * fresnel_perp(c_hi, e)) * g1
    return np.where(live, refl, 0.0), np.where(live, trans, 0.0)
