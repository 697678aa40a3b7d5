"""Area-light spread (Blender ≥ 3.0 ``spread``), as Cycles renders it (``kernel/light/area.h``).

A light of spread s emits into the cone of half-angle h = s/2 about its normal, modelled as a
soft-box grid: the radiance along a direction at angle θ to the normal is scaled by

    A(θ) = max(0, (tan h − tan θ)·k),   k = 1/(tan h − h)   (3/h³ for h ≤ 0.05, Taylor)

[Cycles ``area_light_spread_attenuation`` and ``scene/light.cpp`` ``normalize_spread``], which
keeps the emitted power: ∫ A(θ)·cosθ dω over the hemisphere = π, so P = π·L·A as without
spread. s = π is the plain Lambertian light (A = 1).

Next-event estimation samples, as Cycles does, only the part of the light that can reach the
receiver x: the points whose direction to x is within h of the normal lie in the circle of
radius t·tan h around x's projection on the light plane (t the distance to the plane). The
core samples uniformly the light's parameter box [−1, 1]² (point c + α·u + β·v) clipped to the
circle's bounding box in (α, β) (Cycles picks the smallest of that box, the circle and the
disk light; same support, so the same expectation). Light tracing samples directions
cosine-weighted inside the cone (density cosθ/(π·sin²h)) and weights them by A(θ).
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .vecmath import dot

#: Spreads at least this close to π are plain (A = 1); Cycles' test is spread == π.
PLAIN = np.pi - 1e-6


def normalization(half: NDArray) -> NDArray:
    """(N,) k of the attenuation for half-angles h in (0, π/2) (Cycles' ``normalize_spread``)."""
    h = np.asarray(half, np.float64)
    big = h > 0.05
    with np.errstate(divide="ignore", invalid="ignore"):
        exact = 1.0 / (np.tan(h) - h)
        taylor = 3.0 / h**3
    return np.where(big, exact, taylor)


def attenuation(cos_theta: NDArray, half: NDArray, k: NDArray) -> NDArray:
    """(N,) A(θ) for cosθ between the emission direction and the light normal; 0 behind."""
    c = np.asarray(cos_theta, np.float64)
    front = c > 0
    sc = np.where(front, c, 1.0)
    tan_t = np.sqrt(np.maximum(1.0 - sc * sc, 0.0)) / sc
    return np.where(front, np.maximum((np.tan(half) - tan_t) * k, 0.0), 0.0)


def plane_coordinates(q: NDArray, u: NDArray, v: NDArray) -> NDArray:
    """(N, 2) (α, β) of the projection of offsets q (N, 3) on the plane of the (N, 3) axes
    u, v: q ≈ α·u + β·v (least squares through the Gram matrix; u, v need not be orthogonal)."""
    uu, uv, vv = dot(u, u), dot(u, v), dot(v, v)
    qu, qv = dot(q, u), dot(q, v)
    det = uu * vv - uv * uv
    return np.stack([(vv * qu - uv * qv) / det, (uu * qv - uv * qu) / det], axis=1)


def clip_box(x: NDArray, c: NDArray, u: NDArray, v: NDArray, n: NDArray, half: NDArray):
    """The part of the parameter box [−1, 1]² that can reach receivers x.

    Args:
        x: (N, 3) receivers; c, u, v, n: (N, 3) light centres, half-extent axes, unit normals;
        half: (N,) spread half-angles.
    Returns:
        lo (N, 2), hi (N, 2) the (α, β) box and ok (N,): non-empty and x in front.
    """
    q = x - c
    t = dot(q, n)
    centre = plane_coordinates(q, u, v)
    uu, uv, vv = dot(u, u), dot(u, v), dot(v, v)
    det = uu * vv - uv * uv
    # |∇α|² = (G⁻¹)₀₀ = vv/det, |∇β|² = uu/det: the circle's half-widths in (α, β)
    radius = np.maximum(t, 0.0) * np.tan(half)
    ext = radius[:, None] * np.sqrt(np.stack([vv, uu], axis=1) / det[:, None])
    lo = np.maximum(centre - ext, -1.0)
    hi = np.minimum(centre + ext, 1.0)
    ok = (t > 0) & (hi > lo).all(axis=1)
    return lo, hi, ok
