"""Bump shadowing: Cycles' darkening of *diffuse* light on normal-mapped and bumped surfaces.

A normal map tilts the shading normal N away from the smooth (interpolated, unmapped)
normal Ns. Cycles multiplies the value of every diffuse closure whose N differs from Ns by
a factor S ≤ 1 that depends on the light direction I only (``bump_shadowing_term`` in
``kernel/closure/bsdf.h``), in evaluation and sampling alike, leaving the pdf unchanged:

* ``CHIANG2019`` (Cycles 2.92–4.4) [Chiang, Li, Burley 2019, "Taming the Shadow
  Terminator", SIGGRAPH talk]: with Ns put on the side of I when N·I < 0,
  g = (Ns·I) / ((N·I)(Ns·N));  S = 1 for g ≥ 1, 0 for g < 0, else −g³ + g² + g.
* ``ESTEVEZ2019`` (Cycles ≥ 4.5) [Conty Estevez, Lecocq, Stein 2019, "A Microfacet-Based
  Shadowing Function to Solve the Bump Terminator Problem", Ray Tracing Gems ch. 12]:
  the Smith GGX masking of I for a roughness that grows with the tilt,
  S = G1(α², |Ns·I|) = 1/(1 + Λ),  Λ = (√(1 + α² tan²θ_i) − 1)/2,
  α² = clamp(tan²θ_d / 8, 0, 1),  cos θ_d = |Ns·N|, cos θ_i = |Ns·I|;
  S = 1 where cos θ_d ≥ 1 or cos θ_i ≥ 1, S = 0 where cos θ_i < 1e-6.
* ``NONE``: S = 1 (the exact Lambert cosine; the core's default).

The term makes the BSDF non-reciprocal: I is the direction toward the light side of the
path (wi on camera paths, wo on light paths: :class:`ercuts_core.bsdf.Bsdf`'s ``adjoint``).
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .vecmath import dot

NONE, CHIANG2019, ESTEVEZ2019 = 0, 1, 2
#: Model names (as in shading programs' ``bump_shadowing`` key) → codes.
MODELS = {"NONE": NONE, "CHIANG2019": CHIANG2019, "ESTEVEZ2019": ESTEVEZ2019}


def _chiang(ns: NDArray, n: NDArray, w: NDArray) -> NDArray:
    cos_ni = dot(n, w)
    ns = np.where((cos_ni < 0.0)[:, None], -ns, ns)
    den = cos_ni * dot(ns, n)
    g = np.divide(dot(ns, w), den, out=np.zeros_like(den), where=den != 0.0)   # safe_divide
    cubic = (-g + 1.0) * g * g + g
    return np.where(g >= 1.0, 1.0, np.where(g < 0.0, 0.0, cubic))


def _estevez(ns: NDArray, n: NDArray, w: NDArray) -> NDArray:
    cos_i = np.abs(dot(ns, w))
    cos_d = np.abs(dot(ns, n))
    tan2_d = np.divide(1.0, cos_d * cos_d, out=np.ones_like(cos_d), where=cos_d > 0.0) - 1.0
    alpha2 = np.clip(0.125 * tan2_d, 0.0, 1.0)
    ci = np.maximum(cos_i, 1e-6)
    lam = 0.5 * (np.sqrt(1.0 + alpha2 * np.maximum(1.0 / (ci * ci) - 1.0, 0.0)) - 1.0)
    g1 = 1.0 / (1.0 + lam)
    return np.where((cos_d >= 1.0) | (cos_i >= 1.0), 1.0, np.where(cos_i < 1e-6, 0.0, g1))


def bump_shadowing(model: NDArray, ns: NDArray, n: NDArray, w: NDArray) -> NDArray:
    """(N,) factor S in [0, 1] of the diffuse BSDF value (module docstring).

    Args:
        model: (N,) int codes NONE / CHIANG2019 / ESTEVEZ2019 per lane.
        ns: (N, 3) unit smooth normals before the map; n: (N, 3) unit mapped normals on
            the same side; w: (N, 3) unit direction toward the light side of the path.
    """
    model = np.asarray(model)
    out = np.ones(len(model))
    for code, fn in ((CHIANG2019, _chiang), (ESTEVEZ2019, _estevez)):
        sel = np.flatnonzero(model == code)
        if len(sel):
            out[sel] = fn(ns[sel], n[sel], w[sel])
    return out
