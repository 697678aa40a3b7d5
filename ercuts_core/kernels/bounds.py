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
:mod:`.lightcuts` patches those entries with numpy afterwards.
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
def cosine_bound1(n0, n1, n2, lo0, lo1, lo2, hi0, hi1, hi2) -> float:
    """Upper bound of max(0, cos∠(n, v)) over v in the box [lo, hi] (box relative to the
    point; Walter's box-in-axis-frame bound, lightcuts.cosine_bound for one pair)."""
    sign = 1.0 if n2 >= 0.0 else -1.0
    a = -1.0 / (sign + n2)
    b = n0 * n1 * a
    t0, t1, t2 = 1.0 + sign * n0 ** 2 * a, sign * b, -sign * n0
    s0, s1, s2 = b, sign + n1 ** 2 * a, -n1
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
