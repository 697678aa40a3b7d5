"""Sample warps, discrete distributions and MIS heuristics, vectorized over N lanes.

Every continuous warp comes as the pbrt-v4 triple (``util/sampling.h``)
``sample_*(u) / *_pdf(...) / invert_*(...)`` [Pharr, Jakob & Humphreys 2023, PBR 4th ed.,
§A.5], so tests can check sample ↔ pdf consistency (chi²) and round trips.

* Concentric square → disk map [Shirley & Chiu 1997]; its inverse follows pbrt-v4
  ``InvertUniformDiskConcentricSample``.
* Cosine-weighted hemisphere by Malley's method (disk sample lifted to the hemisphere),
  pdf cosθ/π [PBR4 eq. A.15].
* Uniform sphere / cone by inverting the cosθ marginal (pdf 1/(4π), 1/(2π(1 − cosθ_max)));
  a cone given 1 − cosθ_max for tiny cones (sphere lights, the sun), a cosine-weighted cone
  (area-light spread) and a regular polygon (aperture blades, Cycles ``regular_polygon_sample``).
* Uniform triangle by the area-preserving "no sqrt" map of pbrt-v4 ``SampleUniformTriangle``
  [Heitz 2019, "A Low-Distortion Map Between Triangle and Square"].
* Orthonormal basis from one vector, branchless [Duff et al. 2017, JCGT 6(1)].
* ``Distribution1D``: piecewise-constant discrete distribution (pmf + cdf, inversion).
* Power / balance heuristics [Veach 1997, §9.2, eqs. 9.13 and 9.14].

Conventions: inputs are float64 arrays; directions are (N, 3) unit vectors; ``u`` are
uniform samples in [0, 1); solid-angle pdfs are per steradian [sr⁻¹]. Nothing here loops
over lanes in Python.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .vecmath import dot

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

PI = np.pi
INV_PI = 1.0 / np.pi
INV_2PI = 0.5 / np.pi
INV_4PI = 0.25 / np.pi
PI_OVER_2 = 0.5 * np.pi
PI_OVER_4 = 0.25 * np.pi

#: Largest float64 strictly below 1: the upper end of a "[0, 1)" sample.
ONE_MINUS_EPSILON = float(np.nextafter(1.0, 0.0))


# ---------------------------------------------------------------------------------------
# Small helpers
# ---------------------------------------------------------------------------------------

def _as2(u: ArrayLike) -> F64:
    """Return ``u`` as a float64 (N, 2) array."""
    return np.asarray(u, dtype=np.float64).reshape(-1, 2)


def _as3(v: ArrayLike) -> F64:
    """Return ``v`` as a float64 (N, 3) array."""
    return np.asarray(v, dtype=np.float64).reshape(-1, 3)


def _safe_div(num: F64, den: F64) -> F64:
    """``num / den`` where ``den != 0``, else 0, without floating-point warnings."""
    num, den = np.broadcast_arrays(np.asarray(num, np.float64), np.asarray(den, np.float64))
    out = np.zeros(num.shape, dtype=np.float64)
    np.divide(num, den, out=out, where=den != 0)
    return out


def _safe_sqrt(x: F64) -> F64:
    """sqrt(max(x, 0)): guards against tiny negative rounding errors."""
    return np.sqrt(np.maximum(x, 0.0))


#: Rec.709 luminance weights (Blender's colours are linear Rec.709).
LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])


def luminance(rgb: ArrayLike) -> F64:
    """Relative luminance of linear Rec.709 RGB: Y = 0.2126 R + 0.7152 G + 0.0722 B.

    Args:
        rgb: (..., 3) linear RGB.
    Returns:
        (...) luminance.
    """
    rgb = np.asarray(rgb, dtype=np.float64)
    return rgb[..., 0] * 0.2126 + rgb[..., 1] * 0.7152 + rgb[..., 2] * 0.0722


# ---------------------------------------------------------------------------------------
# Frames
# ---------------------------------------------------------------------------------------

def coordinate_system(n: ArrayLike) -> tuple[F64, F64]:
    """Orthonormal tangents (t, b) with t × b = n, branchless [Duff et al. 2017, Listing 3].

    Robust for every unit ``n`` including (0, 0, −1) and its neighbourhood (the sign of
    n.z selects the chart; ``copysign`` makes n.z = −0.0 use the lower chart).

    Args:
        n: (N, 3) unit normals.
    Returns:
        t, b: (N, 3) unit tangents; (t, b, n) is a right-handed orthonormal frame.
    """
    n = _as3(n)
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    sign = np.copysign(1.0, z)
    a = -1.0 / (sign + z)  # |sign + z| >= 1, never a division by zero
    with np.errstate(under="ignore"):  # x·x·a of a tiny x flushes harmlessly to 0
        c = x * y * a
        t = np.stack([1.0 + sign * x * x * a, sign * c, -sign * x], axis=1)
        b = np.stack([c, sign + y * y * a, -y], axis=1)
    return t, b


def to_local(v: ArrayLike, t: ArrayLike, b: ArrayLike, n: ArrayLike) -> F64:
    """Express world vectors in the frame (t, b, n): returns (v·t, v·b, v·n), shape (N, 3)."""
    v = _as3(v)
    return np.stack([dot(v, _as3(t)),
                     dot(v, _as3(b)),
                     dot(v, _as3(n))], axis=1)


def to_world(v_local: ArrayLike, t: ArrayLike, b: ArrayLike, n: ArrayLike) -> F64:
    """Inverse of :func:`to_local`: x·t + y·b + z·n, shape (N, 3)."""
    v = _as3(v_local)
    return v[:, 0:1] * _as3(t) + v[:, 1:2] * _as3(b) + v[:, 2:3] * _as3(n)


# ---------------------------------------------------------------------------------------
# Disk
# ---------------------------------------------------------------------------------------

def sample_uniform_disk_concentric(u: ArrayLike) -> F64:
    """Concentric map of the unit square onto the unit disk [Shirley & Chiu 1997].

    Area preserving (pdf 1/π per unit area on the disk) with low distortion.

    Args:
        u: (N, 2) uniforms in [0, 1).
    Returns:
        (N, 2) points in the unit disk.
    """
    uo = 2.0 * _as2(u) - 1.0
    ux, uy = uo[:, 0], uo[:, 1]
    x_major = np.abs(ux) > np.abs(uy)
    # Wedge |x| > |y|: r = x, θ = π/4·y/x; otherwise r = y, θ = π/2 − π/4·x/y
    r = np.where(x_major, ux, uy)
    q = PI_OVER_4 * _safe_div(np.where(x_major, uy, ux), r)   # one division for both wedges
    theta = np.where(x_major, q, PI_OVER_2 - q)
    out = np.empty((len(r), 2))
    np.multiply(r, np.cos(theta), out=out[:, 0])
    np.multiply(r, np.sin(theta), out=out[:, 1])
    return out


def invert_uniform_disk_concentric(p: ArrayLike) -> F64:
    """Inverse of :func:`sample_uniform_disk_concentric` (pbrt-v4 ``InvertUniformDiskConcentricSample``).

    Args:
        p: (N, 2) points in the unit disk.
    Returns:
        (N, 2) samples u in [0, 1]².
    """
    p = _as2(p)
    px, py = p[:, 0], p[:, 1]
    theta = np.arctan2(py, px)  # (−π, π]
    r = np.hypot(px, py)
    x_major = (np.abs(theta) < PI_OVER_4) | (np.abs(theta) > 3.0 * PI_OVER_4)
    # Wedges around ±x: the square coordinate x is ±r, y follows from θ
    rx = np.copysign(r, px)
    theta_x = np.where(px < 0.0, np.where(py < 0.0, PI + theta, theta - PI), theta)
    ux_a, uy_a = rx, theta_x * rx / PI_OVER_4
    # Wedges around ±y
    ry = np.copysign(r, py)
    ux_b = np.where(py < 0.0, -(PI_OVER_2 + theta), PI_OVER_2 - theta) * ry / PI_OVER_4
    uy_b = ry
    ux = np.where(x_major, ux_a, ux_b)
    uy = np.where(x_major, uy_a, uy_b)
    return np.clip(np.stack([(ux + 1.0) * 0.5, (uy + 1.0) * 0.5], axis=1), 0.0, 1.0)


# ---------------------------------------------------------------------------------------
# Hemisphere, sphere, cone
# ---------------------------------------------------------------------------------------

def sample_cosine_hemisphere(u: ArrayLike) -> F64:
    """Cosine-weighted directions about +z by Malley's method [PBR4 §A.5.3].

    Args:
        u: (N, 2) uniforms.
    Returns:
        (N, 3) unit directions with z >= 0; pdf = cosθ/π per steradian.
    """
    d = sample_uniform_disk_concentric(u)
    z = _safe_sqrt(1.0 - d[:, 0] ** 2 - d[:, 1] ** 2)
    return np.stack([d[:, 0], d[:, 1], z], axis=1)


def cosine_hemisphere_pdf(cos_theta: ArrayLike) -> F64:
    """Solid-angle pdf of :func:`sample_cosine_hemisphere`: max(cosθ, 0)/π [sr⁻¹], shape (N,)."""
    return np.maximum(np.asarray(cos_theta, dtype=np.float64), 0.0) * INV_PI


def invert_cosine_hemisphere_sample(w: ArrayLike) -> F64:
    """Inverse of :func:`sample_cosine_hemisphere`: project to the disk and invert. (N, 2)."""
    return invert_uniform_disk_concentric(_as3(w)[:, :2])


def sample_uniform_sphere(u: ArrayLike) -> F64:
    """Uniform directions on the unit sphere: z = 1 − 2u₀, φ = 2πu₁. Returns (N, 3)."""
    u = _as2(u)
    z = 1.0 - 2.0 * u[:, 0]
    r = _safe_sqrt(1.0 - z * z)
    phi = 2.0 * PI * u[:, 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def uniform_sphere_pdf() -> float:
    """Solid-angle pdf of :func:`sample_uniform_sphere`: 1/(4π) [sr⁻¹]."""
    return INV_4PI


def _phi_01(w: F64) -> F64:
    """Azimuth of (N, 3) directions mapped to [0, 1)."""
    phi = np.arctan2(w[:, 1], w[:, 0])
    phi = np.where(phi < 0.0, phi + 2.0 * PI, phi)
    return np.minimum(phi * INV_2PI, ONE_MINUS_EPSILON)


def invert_uniform_sphere_sample(w: ArrayLike) -> F64:
    """Inverse of :func:`sample_uniform_sphere`: u = ((1 − z)/2, φ/2π). Returns (N, 2)."""
    w = _as3(w)
    return np.stack([np.clip((1.0 - w[:, 2]) * 0.5, 0.0, 1.0), _phi_01(w)], axis=1)


def sample_uniform_cone(u: ArrayLike, cos_max: ArrayLike) -> F64:
    """Uniform directions in the cone of half-angle acos(cos_max) about +z.

    cosθ = (1 − u₀) + u₀·cos_max, φ = 2πu₁ [PBR4 §A.5.4].

    Args:
        u: (N, 2) uniforms.
        cos_max: (N,) or scalar cosine of the half-angle, in [−1, 1].
    Returns:
        (N, 3) unit directions.
    """
    u = _as2(u)
    cos_max = np.broadcast_to(np.asarray(cos_max, np.float64), u[:, 0].shape)
    cos_t = (1.0 - u[:, 0]) + u[:, 0] * cos_max
    sin_t = _safe_sqrt(1.0 - cos_t * cos_t)
    phi = 2.0 * PI * u[:, 1]
    return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=1)


def uniform_cone_pdf(cos_max: ArrayLike) -> F64:
    """Solid-angle pdf of :func:`sample_uniform_cone`: 1/(2π(1 − cos_max)) [sr⁻¹].

    A degenerate cone (cos_max >= 1) is a delta direction: returns ``inf`` there
    (without a floating-point warning); callers treat it as a delta light.
    """
    cos_max = np.asarray(cos_max, dtype=np.float64)
    den = 2.0 * PI * (1.0 - cos_max)
    return np.where(den > 0.0, _safe_div(1.0, den), np.inf)


def invert_uniform_cone_sample(w: ArrayLike, cos_max: ArrayLike) -> F64:
    """Inverse of :func:`sample_uniform_cone`: u = ((1 − cosθ)/(1 − cos_max), φ/2π). (N, 2)."""
    w = _as3(w)
    cos_max = np.broadcast_to(np.asarray(cos_max, np.float64), w[:, 0].shape)
    u0 = np.clip(_safe_div(1.0 - w[:, 2], 1.0 - cos_max), 0.0, 1.0)
    return np.stack([u0, _phi_01(w)], axis=1)


def sample_uniform_cone_omc(u: ArrayLike, one_minus_cos: ArrayLike) -> F64:
    """Uniform directions in the cone about +z given 1 − cosθ_max (precise for tiny cones).

    1 − cosθ = u₀·(1 − cosθ_max), so sin²θ = u₀·m·(2 − u₀·m) keeps full precision when
    m = 1 − cosθ_max ≪ 1 (Cycles ``sample_uniform_cone`` takes 1 − cos for the same reason).
    Density 1/(2π·m) = :func:`uniform_cone_pdf_omc`.

    Args:
        u: (N, 2) uniforms; one_minus_cos: (N,) or scalar in (0, 2].
    Returns:
        (N, 3) unit directions.
    """
    u = _as2(u)
    m = np.broadcast_to(np.asarray(one_minus_cos, np.float64), u[:, 0].shape)
    a = u[:, 0] * m
    sin_t = _safe_sqrt(a * (2.0 - a))
    phi = 2.0 * PI * u[:, 1]
    return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), 1.0 - a], axis=1)


def uniform_cone_pdf_omc(one_minus_cos: ArrayLike) -> F64:
    """Solid-angle pdf of :func:`sample_uniform_cone_omc`: 1/(2π·(1 − cosθ_max)) [sr⁻¹]."""
    return INV_2PI / np.asarray(one_minus_cos, np.float64)


def one_minus_cos_from_sin2(sin2: ArrayLike) -> F64:
    """1 − √(1 − s) for s = sin²θ in [0, 1], as s/(1 + √(1 − s)) (no cancellation)."""
    s = np.clip(np.asarray(sin2, np.float64), 0.0, 1.0)
    return s / (1.0 + np.sqrt(1.0 - s))


def sample_cosine_cone(u: ArrayLike, sin_max: ArrayLike) -> F64:
    """Cosine-weighted directions about +z restricted to θ ≤ θ_max (Malley's method on the
    disk of radius sinθ_max). Density cosθ/(π·sin²θ_max) inside the cone, 0 outside.

    Args:
        u: (N, 2) uniforms; sin_max: (N,) or scalar sinθ_max in (0, 1].
    Returns:
        (N, 3) unit directions.
    """
    u = _as2(u)
    d = sample_uniform_disk_concentric(u) * np.asarray(sin_max, np.float64).reshape(-1, 1)
    z = _safe_sqrt(1.0 - d[:, 0] ** 2 - d[:, 1] ** 2)
    return np.stack([d[:, 0], d[:, 1], z], axis=1)


def cosine_cone_pdf(cos_theta: ArrayLike, cos_max: ArrayLike, sin_max: ArrayLike) -> F64:
    """Solid-angle pdf of :func:`sample_cosine_cone` at cosθ: cosθ/(π·sin²θ_max) for
    cosθ ≥ cosθ_max, else 0."""
    c = np.asarray(cos_theta, np.float64)
    s2 = np.asarray(sin_max, np.float64) ** 2
    return np.where(c >= np.asarray(cos_max, np.float64), np.maximum(c, 0.0) * INV_PI / s2, 0.0)


def sample_regular_polygon(u: ArrayLike, corners: int, rotation: float) -> F64:
    """Uniform points in the regular polygon with ``corners`` vertices on the unit circle,
    rotated by ``rotation`` [rad] (Cycles ``regular_polygon_sample``: a corner triangle
    chosen by u₀, a uniform point in it). Area corners·sin(π/c)·cos(π/c).

    Args:
        u: (N, 2) uniforms; corners >= 3.
    Returns:
        (N, 2) points.
    """
    u = _as2(u)
    c = float(corners)
    corner = np.floor(u[:, 0] * c)
    a = np.sqrt(u[:, 0] * c - corner)
    v = u[:, 1] * a
    w = 1.0 - a
    angle = PI / c
    px, py = (w + v) * np.cos(angle), (w - v) * np.sin(angle)
    rot = rotation + corner * 2.0 * angle
    cr, sr = np.cos(rot), np.sin(rot)
    return np.stack([cr * px - sr * py, sr * px + cr * py], axis=1)


def regular_polygon_area(corners: int) -> float:
    """Area of the unit-circumradius regular polygon of :func:`sample_regular_polygon`."""
    return corners * np.sin(PI / corners) * np.cos(PI / corners)


# ---------------------------------------------------------------------------------------
# Triangle
# ---------------------------------------------------------------------------------------

def sample_uniform_triangle(u: ArrayLike) -> F64:
    """Uniform barycentrics over a triangle (pbrt-v4 ``SampleUniformTriangle``, [Heitz 2019]).

    Args:
        u: (N, 2) uniforms.
    Returns:
        (N, 3) barycentrics (b0, b1, b2), each >= 0, summing to 1; the density is
        2 per unit (b0, b1) area, i.e. 1/area on the triangle.
    """
    u = _as2(u)
    u0, u1 = u[:, 0], u[:, 1]
    lower = u0 < u1
    b0 = np.where(lower, 0.5 * u0, u0 - 0.5 * u1)
    b1 = np.where(lower, u1 - 0.5 * u0, 0.5 * u1)
    return np.stack([b0, b1, 1.0 - b0 - b1], axis=1)


def invert_uniform_triangle(b: ArrayLike) -> F64:
    """Inverse of :func:`sample_uniform_triangle` (uses b0, b1 only). Returns (N, 2)."""
    b = _as3(b)
    b0, b1 = b[:, 0], b[:, 1]
    lower = b0 < b1
    u0 = np.where(lower, 2.0 * b0, b0 + b1)
    u1 = np.where(lower, b0 + b1, 2.0 * b1)
    return np.clip(np.stack([u0, u1], axis=1), 0.0, 1.0)


# ---------------------------------------------------------------------------------------
# Discrete distribution
# ---------------------------------------------------------------------------------------

class Distribution1D:
    """Discrete distribution proportional to non-negative weights (sampling by cdf inversion).

    Attributes:
        pmf: (K,) probabilities w/Σw (all zero when the total is 0).
        cdf: (K+1,) running sums, cdf[0] = 0 and cdf[K] = 1 (all zero when the total is 0).
        total: Σw.

    Zero-weight entries occupy empty cdf intervals and are never returned by
    :meth:`sample`. A zero total (or K = 0) is allowed: ``sample`` then returns index 0
    with pmf 0, and callers must check ``pmf > 0`` before using the index.
    """

    def __init__(self, weights: ArrayLike) -> None:
        w = np.asarray(weights, dtype=np.float64).reshape(-1)
        if not np.all(np.isfinite(w)) or np.any(w < 0.0):
            raise ValueError("Distribution1D weights must be finite and >= 0")
        csum = np.cumsum(w)
        # total = last running sum, so cdf <= 1 holds exactly after the division
        self.total: float = float(csum[-1]) if w.size else 0.0
        self.cdf: F64 = np.zeros(w.size + 1, dtype=np.float64)
        self.pmf: F64 = np.zeros(w.size, dtype=np.float64)
        if self.total > 0.0:
            self.pmf = w / self.total
            self.cdf[1:] = csum / self.total
            self.cdf[-1] = 1.0

    def __len__(self) -> int:
        return int(self.pmf.size)

    def sample(self, u: ArrayLike) -> tuple[I64, F64]:
        """Pick indices by inverting the cdf.

        Args:
            u: (N,) uniforms in [0, 1).
        Returns:
            idx: (N,) int64 index i with cdf[i] <= u < cdf[i+1] (so pmf[i] > 0).
            pmf: (N,) probability of ``idx``.
        """
        u = np.asarray(u, dtype=np.float64).reshape(-1)
        if self.total <= 0.0:
            return np.zeros(u.shape, np.int64), np.zeros(u.shape, np.float64)
        u = np.clip(u, 0.0, ONE_MINUS_EPSILON)
        idx = np.searchsorted(self.cdf, u, side="right").astype(np.int64) - 1
        idx = np.clip(idx, 0, self.pmf.size - 1)
        return idx, self.pmf[idx]

    def pmf_of(self, idx: ArrayLike) -> F64:
        """Probability of the given (N,) indices (0 for out-of-range indices)."""
        idx = np.asarray(idx, dtype=np.int64).reshape(-1)
        inside = (idx >= 0) & (idx < self.pmf.size)
        out = np.zeros(idx.shape, np.float64)
        out[inside] = self.pmf[idx[inside]]
        return out


# ---------------------------------------------------------------------------------------
# Multiple importance sampling
# ---------------------------------------------------------------------------------------

def power_heuristic(pdf_a: ArrayLike, pdf_b: ArrayLike) -> F64:
    """MIS weight of strategy a, p_a² / (p_a² + p_b²) [Veach 1997, eq. 9.14, β = 2].

    Vectorized, computed through the ratio p_b/p_a (no overflow of p²); 0 where p_a is 0,
    1 where only p_a is inf, 0 where only p_b is inf, 0.5 where both are inf.
    """
    pdf_a, pdf_b = np.asarray(pdf_a, np.float64), np.asarray(pdf_b, np.float64)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        r = pdf_b / pdf_a
        w = 1.0 / (1.0 + r * r)
    inf_a = np.isinf(pdf_a) & (pdf_a > 0)
    return np.where((pdf_a > 0) & np.isfinite(w), w,
                    np.where(inf_a, np.where(np.isinf(pdf_b), 0.5, 1.0), 0.0))
