"""Compiled Lightcuts error bounds L̄_C of (shading point, cluster) pairs (Walter et al. 2005).

The same formulas, in the same order of operations, as the numpy functions of
:mod:`ercuts_core.integrators.ercuts.lightcuts` (``cosine_bound``, ``geometry_bound``,
``cluster_bound``; shared docs algorithm.md §E.2 (a)–(c)), one pair per loop iteration
instead of one (K,3) temporary per operation:

    L̄_C = cosbound(x, n_x, box_C) · Ḡ_C · Y(f̄_x ⊙ I_C),   0 for leaves,

with Ḡ_C = cos(max(0, θ_min − β)) / d²_min (≤ clamp when clamp > 0).  The only
difference from numpy is the luminance dot product Y = 0.2126 R + 0.7152 G + 0.0722 B,
which numpy computes through BLAS (possibly with fused multiply-adds): bounds agree to
~1 ulp (``tests/test_kernels.py`` measures it).

Glossy receivers' per-cluster GGX bound is not compiled: :func:`cluster_bound` of
:mod:`.lightcuts` patches those entries with numpy afterwards.  Rough glass receivers' bound
(``lightcuts.GlossyReceivers`` with ``glass``; :func:`ercuts_core.bsdf.rough_glass_cosine_bound`)
is: :func:`glass_bounds` computes their whole L̄_C in numpy's order of operations, with square
roots only, so it agrees with numpy to the luminance dot product's last bit (measured ≤ 4.4e-16
relative; ``tests/test_kernels.py``).
"""
from __future__ import annotations

import math

import numpy as np

from . import jit

#: Rec.709 luminance weights (``ercuts_core.sampling.LUMINANCE_WEIGHTS``).
_WR, _WG, _WB = 0.2126, 0.7152, 0.0722


@jit
def _min_abs(lo: float, hi: float) -> float:
    if lo <= 0.0 and hi >= 0.0:
        return 0.0
    return min(abs(lo), abs(hi))


@jit
def _range_min(d0, d1, d2, lo0, lo1, lo2, hi0, hi1, hi2) -> float:
    return min(d0 * lo0, d0 * hi0) + min(d1 * lo1, d1 * hi1) + min(d2 * lo2, d2 * hi2)


@jit
def _range_max(d0, d1, d2, lo0, lo1, lo2, hi0, hi1, hi2) -> float:
    return max(d0 * lo0, d0 * hi0) + max(d1 * lo1, d1 * hi1) + max(d2 * lo2, d2 * hi2)


@jit
def _frame(n0, n1, n2):
    """Two unit vectors t, s completing the unit n to an orthonormal frame (Duff et al. 2017,
    the branchless basis of ``sampling.coordinate_system``)."""
    sign = 1.0 if n2 >= 0.0 else -1.0
    a = -1.0 / (sign + n2)
    b = n0 * n1 * a
    return 1.0 + sign * n0 ** 2 * a, sign * b, -sign * n0, b, sign + n1 ** 2 * a, -n1


@jit
def cosine_bound1(n0, n1, n2, lo0, lo1, lo2, hi0, hi1, hi2) -> float:
    """Upper bound of max(0, cos∠(n, v)) over v in the box [lo, hi] (box relative to the
    point; Walter's box-in-axis-frame bound, lightcuts.cosine_bound for one pair)."""
    t0, t1, t2, s0, s1, s2 = _frame(n0, n1, n2)
    zmax = _range_max(n0, n1, n2, lo0, lo1, lo2, hi0, hi1, hi2)
    ax = _min_abs(_range_min(t0, t1, t2, lo0, lo1, lo2, hi0, hi1, hi2),
                  _range_max(t0, t1, t2, lo0, lo1, lo2, hi0, hi1, hi2))
    ay = _min_abs(_range_min(s0, s1, s2, lo0, lo1, lo2, hi0, hi1, hi2),
                  _range_max(s0, s1, s2, lo0, lo1, lo2, hi0, hi1, hi2))
    den = math.sqrt(ax * ax + ay * ay + zmax * zmax)
    if zmax > 0.0:
        return zmax / (den if den > 0.0 else 1.0)
    return 0.0


@jit
def signed_cosine_bound1(n0, n1, n2, lo0, lo1, lo2, hi0, hi1, hi2) -> float:
    """Upper bound of cos∠(n, v) over v in the box [lo, hi], negative when the box lies behind
    the plane ⊥ n (lightcuts.signed_cosine_bound for one pair)."""
    t0, t1, t2, s0, s1, s2 = _frame(n0, n1, n2)
    zmax = _range_max(n0, n1, n2, lo0, lo1, lo2, hi0, hi1, hi2)
    xlo = _range_min(t0, t1, t2, lo0, lo1, lo2, hi0, hi1, hi2)
    xhi = _range_max(t0, t1, t2, lo0, lo1, lo2, hi0, hi1, hi2)
    ylo = _range_min(s0, s1, s2, lo0, lo1, lo2, hi0, hi1, hi2)
    yhi = _range_max(s0, s1, s2, lo0, lo1, lo2, hi0, hi1, hi2)
    if zmax > 0.0:
        ax, ay = _min_abs(xlo, xhi), _min_abs(ylo, yhi)
        den = math.sqrt(ax * ax + ay * ay + zmax * zmax)
        return zmax / (den if den > 0.0 else 1.0)
    if zmax < 0.0:
        bx, by = max(abs(xlo), abs(xhi)), max(abs(ylo), abs(yhi))
        far = math.sqrt(bx * bx + by * by + zmax * zmax)
        return zmax / (far if far > 0.0 else 1.0)
    return 0.0


@jit
def geometry_bound1(x0, x1, x2, bmin, bmax, axis, cone_cos: float, clamp: float) -> float:
    """Ḡ of one pair (lightcuts.geometry_bound): ``bmin``, ``bmax``, ``axis`` (3,) rows."""
    c0 = min(max(x0, bmin[0]), bmax[0])
    c1 = min(max(x1, bmin[1]), bmax[1])
    c2 = min(max(x2, bmin[2]), bmax[2])
    d2 = (x0 - c0) ** 2 + (x1 - c1) ** 2 + (x2 - c2) ** 2
    c = cosine_bound1(axis[0], axis[1], axis[2], x0 - bmax[0], x1 - bmax[1], x2 - bmax[2],
                      x0 - bmin[0], x1 - bmin[1], x2 - bmin[2])
    s = math.sqrt(max(0.0, 1.0 - c * c))
    cb = min(max(cone_cos, -1.0), 1.0)
    sb = math.sqrt(max(0.0, 1.0 - cb * cb))
    cos_min = 1.0 if c >= cb else max(0.0, c * cb + s * sb)
    if cos_min > 0.0:
        g = cos_min / d2 if d2 > 0.0 else math.inf
    else:
        g = 0.0
    return min(g, clamp) if clamp > 0.0 else g


@jit
def pair_bound(k, pt, node, p, n, f_bound, transmissive, is_leaf, intensity, bmin, bmax,
               cone_axis, cone_cos, clamp, cb_out) -> float:
    """L̄_C of entry k = (point pt, node) with the receiver cosine bound stored in cb_out[k]."""
    x0, x1, x2 = p[pt, 0], p[pt, 1], p[pt, 2]
    lo0, lo1, lo2 = bmin[node, 0] - x0, bmin[node, 1] - x1, bmin[node, 2] - x2
    hi0, hi1, hi2 = bmax[node, 0] - x0, bmax[node, 1] - x1, bmax[node, 2] - x2
    cb = cosine_bound1(n[pt, 0], n[pt, 1], n[pt, 2], lo0, lo1, lo2, hi0, hi1, hi2)
    if transmissive[pt]:
        cb = max(cb, cosine_bound1(-n[pt, 0], -n[pt, 1], -n[pt, 2], lo0, lo1, lo2, hi0, hi1, hi2))
    cb_out[k] = cb
    if is_leaf[node]:
        return 0.0
    y = (f_bound[pt, 0] * intensity[node, 0] * _WR + f_bound[pt, 1] * intensity[node, 1] * _WG
         + f_bound[pt, 2] * intensity[node, 2] * _WB)
    m = cb * y
    if not m > 0.0:
        return 0.0
    return m * geometry_bound1(x0, x1, x2, bmin[node], bmax[node], cone_axis[node],
                               cone_cos[node], clamp)


@jit
def cluster_bounds(pidx, node, p, n, f_bound, transmissive, is_leaf, intensity, bmin, bmax,
                   cone_axis, cone_cos, clamp):
    """(K,) bounds and (K,) receiver cosine bounds of the entries (pidx, node) (K,)."""
    K = pidx.shape[0]
    out = np.empty(K)
    cb = np.empty(K)
    for k in range(K):
        out[k] = pair_bound(k, pidx[k], node[k], p, n, f_bound, transmissive, is_leaf, intensity,
                            bmin, bmax, cone_axis, cone_cos, clamp, cb)
    return out, cb


# ------------------------------------------------------------------- rough glass receivers
# The per-cluster material bound of rough glass points (lightcuts.GlossyReceivers,
# bsdf.rough_glass_cosine_bound), one pair per iteration, in numpy's order of operations
# (only square roots: no transcendental function whose last bit could differ from numpy's).

_INV_PI = 1.0 / math.pi
_COS_EPS = 1e-10            # ercuts_core.bsdf.COS_EPS


@jit
def _ggx_d(cos_h: float, alpha: float) -> float:
    """bsdf.ggx_d of one value."""
    a2 = alpha * alpha
    c = min(max(cos_h, 0.0), 1.0)
    c2 = c * c
    den = (1.0 - c2) + a2 * c2
    dd = den * den
    if cos_h > 0.0 and dd > 0.0:
        return a2 * _INV_PI / dd
    return 0.0


@jit
def _smith_lambda(cos_t: float, alpha: float) -> float:
    """bsdf.smith_lambda of one value."""
    c2 = cos_t * cos_t if cos_t > _COS_EPS else 1.0
    x = alpha * alpha * max(1.0 - c2, 0.0) / c2
    return x / (2.0 * (1.0 + math.sqrt(1.0 + x)))


@jit
def _fresnel_perp(c: float, e: float) -> float:
    """bsdf.fresnel_perp of one value."""
    c = min(max(c, 0.0), 1.0)
    s2 = (e - 1.0) * (e + 1.0) + c * c
    if not s2 > 0.0:
        return 1.0
    s = math.sqrt(s2)
    r = (c - s) / (c + s) if c + s > 0.0 else 0.0
    return r * r


@jit
def _half_cos(w: float, e: float, wc: float, sig: float) -> float:
    w = min(min(max(w, -1.0), 1.0), wc)
    v2 = (1.0 - e) * (1.0 - e) + 2.0 * e * (1.0 + w)
    return min(max(sig * (1.0 + e * w) / math.sqrt(v2), 0.0), 1.0)


@jit
def rough_glass_bound1(cos_o, alpha, e, w_min, w_max, cos_r, cos_t):
    """(refl, trans) of bsdf.rough_glass_cosine_bound for one pair."""
    if not cos_o > _COS_EPS:
        return 0.0, 0.0
    co = min(max(cos_o, 0.0), 1.0)
    den = co * (1.0 + _smith_lambda(co, alpha))
    g1 = 1.0 / den if den > 0.0 else 0.0
    wlo = min(max(w_min, -1.0), 1.0)
    c_r = math.sqrt(0.5 * (1.0 + wlo))
    d_r = _ggx_d(math.sqrt(0.5 * (1.0 + min(max(cos_r, -1.0), 1.0))), alpha)
    refl = _fresnel_perp(c_r, e) * d_r * (0.25 * g1)
    e2m1 = (e - 1.0) * (e + 1.0)
    wc = -min(e, 1.0 / e if e > 0.0 else 0.0)
    sig = -1.0 if e > 1.0 else 1.0
    c_hi = _half_cos(wlo, e, wc, sig)
    c_lo = _half_cos(w_max, e, wc, sig)
    s_hi = math.sqrt(max(e2m1 + c_hi * c_hi, 0.0))
    t_hi = c_hi * s_hi * (c_hi + s_hi) ** 2 / (e * e2m1 * e2m1)
    sin_o = math.sqrt(max(1.0 - co * co, 0.0))
    sin_lo = math.sqrt(max(1.0 - c_lo * c_lo, 0.0))
    c1 = min(co * c_lo + sin_o * sin_lo, 1.0) if c_lo > co else 1.0
    c_m = min(co, c_lo)
    s_m = math.sqrt(max(e2m1 + c_m * c_m, 0.0))
    k = abs(c_m - s_m) / s_m if s_m > 0.0 else 0.0
    k2 = k * k
    q = min(max(cos_t, -1.0), 1.0)
    c2 = 1.0
    if s_m > 0.0 and k > 0.0:
        if k <= 1.0:
            num = (1.0 + q) * k2 - (1.0 - q)
            dn = (1.0 + q) * k2 + (1.0 - q)
            c2 = num / dn if dn > 0.0 else 0.0
        else:
            c2 = 1.0 - ((1.0 - q) / k2 if k2 > 0.0 else 0.0)
    trans = _ggx_d(min(c1, c2), alpha) * t_hi * (1.0 - 0.5 * _fresnel_perp(c_hi, e)) * g1
    return refl, trans


@jit
def _ggx_cos_bound(cos_o: float, alpha: float, cos_r: float) -> float:
    """bsdf.ggx_cosine_bound of one value."""
    cos_h = math.sqrt(0.5 * (1.0 + min(max(cos_r, -1.0), 1.0)))
    den = 4.0 * max(cos_o, 0.0) * (1.0 + _smith_lambda(cos_o, alpha))
    g1_4 = 1.0 / den if den > 0.0 else 0.0
    return _ggx_d(cos_h, alpha) * g1_4 if cos_o > _COS_EPS else 0.0


@jit
def _cb(a0, a1, a2, lo0, lo1, lo2, hi0, hi1, hi2, sign):
    return cosine_bound1(sign * a0, sign * a1, sign * a2, lo0, lo1, lo2, hi0, hi1, hi2)


@jit
def glass_pair_bound(pt, node, p, ns, wo, r, t, cos_o, alpha, eta, kd_pi, spec, kr, kt, kdt_pi,
                     is_leaf, intensity, bmin, bmax, cone_axis, cone_cos, clamp) -> float:
    """L̄_C = Ḡ_C·Y(M̄ ⊙ I_C) of one rough glass entry (lightcuts._glass_material_bound)."""
    if is_leaf[node]:
        return 0.0
    x0, x1, x2 = p[pt, 0], p[pt, 1], p[pt, 2]
    lo0, lo1, lo2 = bmin[node, 0] - x0, bmin[node, 1] - x1, bmin[node, 2] - x2
    hi0, hi1, hi2 = bmax[node, 0] - x0, bmax[node, 1] - x1, bmax[node, 2] - x2
    n0, n1, n2 = ns[pt, 0], ns[pt, 1], ns[pt, 2]
    o0, o1, o2 = wo[pt, 0], wo[pt, 1], wo[pt, 2]
    cb_up = _cb(n0, n1, n2, lo0, lo1, lo2, hi0, hi1, hi2, 1.0)
    cb_dn = _cb(n0, n1, n2, lo0, lo1, lo2, hi0, hi1, hi2, -1.0)
    w_max = signed_cosine_bound1(o0, o1, o2, lo0, lo1, lo2, hi0, hi1, hi2)
    w_min = -signed_cosine_bound1(-o0, -o1, -o2, lo0, lo1, lo2, hi0, hi1, hi2)
    cos_r = signed_cosine_bound1(r[pt, 0], r[pt, 1], r[pt, 2], lo0, lo1, lo2, hi0, hi1, hi2)
    cos_t = signed_cosine_bound1(t[pt, 0], t[pt, 1], t[pt, 2], lo0, lo1, lo2, hi0, hi1, hi2)
    co, a = cos_o[pt], alpha[pt]
    refl, trans = rough_glass_bound1(co, a, eta[pt], w_min, w_max, cos_r, cos_t)
    s = _ggx_cos_bound(co, a, cos_r) if cb_up > 0.0 else 0.0
    if not cb_up > 0.0:
        refl = 0.0
    if not cb_dn > 0.0:
        trans = 0.0
    rk = refl * kr[pt]
    m = 0.0
    for j in range(3):
        mb = cb_up * kd_pi[pt, j] + s * spec[pt, j] + rk + trans * kt[pt, j] + cb_dn * kdt_pi[pt, j]
        m += mb * intensity[node, j] * (_WR if j == 0 else (_WG if j == 1 else _WB))
    if not m > 0.0:
        return 0.0
    return m * geometry_bound1(x0, x1, x2, bmin[node], bmax[node], cone_axis[node],
                               cone_cos[node], clamp)


@jit
def glass_bounds(pidx, node, p, ns, wo, r, t, cos_o, alpha, eta, kd_pi, spec, kr, kt, kdt_pi, is_leaf,
                 intensity, bmin, bmax, cone_axis, cone_cos, clamp):
    """(K,) bounds L̄_C of the rough glass entries (pidx, node) (K,)."""
    K = pidx.shape[0]
    out = np.empty(K)
    for k in range(K):
        out[k] = glass_pair_bound(pidx[k], node[k], p, ns, wo, r, t, cos_o, alpha, eta, kd_pi,
                                  spec, kr, kt, kdt_pi, is_leaf, intensity, bmin, bmax, cone_axis,
                                  cone_cos, clamp)
    return out
