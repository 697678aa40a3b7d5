"""Bias compensation of the VPL geometry clamp (Kollig & Keller 2004, "Illumination in the
presence of weak singularities", MCQMC 2004, §3).

The gather clamps each VPL's geometry term, cosθ_v/d² ≤ g_max (:func:`.vpl.g_clamp`), so
that a VPL close to a receiver cannot put a spike on it. What the clamp removes is light
over short distances — along the edges where walls meet, under furniture, at door frames:
a band of receivers 10–25 % too dark in the door scene (benchmarks/results/error_split.md).
Written over the hemisphere of directions ω at a receiver x, with y(ω) the surface seen and
L_o(y → x) its reflected radiance (which the VPLs stand for), the removed part is

    ΔL(x) = ∫ f(x, ω_o, ω) |cosθ_x| · L_o(y → x) · w(x, y) dω,
    w(x, y) = max(0, 1 − g_max·d²/cosθ_y) = 1 − min(1, g_max·d²/cosθ_y),

since a VPL's unclamped geometry term cosθ_y/d² times the solid angle's dA = d²/cosθ_y dω is
1. Kollig & Keller estimate ΔL by sampling ω from the BSDF at x (weight f|cos|/pdf), tracing
to y and, where w > 0, evaluating L_o(y → x) with the same clamped VPL estimator plus its own
compensation — a recursion in which w < 1 acts as absorption. Only y closer than
1/√g_max can have w > 0 (cosθ_y ≤ 1), so the rays are short. Here L_o(y → x) is the direct
light at y plus the gather's clamped VPL estimate at y (the VPLs of the default
``direct_light='NEE'`` carry light after at least one scattering, which starts with the
direct light at y). The direct light is multiple importance sampled [Veach 1997 §9.2]: a
light sample weighted by the power heuristic, and the next level's BSDF sample, traced to
any distance, collects the emission it meets with the other weight. Light sampling alone
(before stop 45) is unbiased but has a heavy tail wherever y lies close to an emitter: the
Cornell box's ceiling 1 cm above its two-sided lamp, where a light sample over the panel
rarely lands under y — a mean compensation of 0.92 ± 0.15 against 1.12 in
tests/test_bias_compensation.py's plates, while MIS gives 1.123 ± 0.003. The recursion ends
by Russian roulette after :data:`COMPENSATION_RR_DEPTH` levels (at most
:data:`COMPENSATION_DEPTH`), so it keeps the light that bounces many times inside such a
gap; stopping after three levels returned 4.3 of the 6.1 the clamp removed in the Cornell
box (64×48, 24 seeds; now 5.95). With the compensation the VPLs are normalised by their
*unclamped* image energy Ê1 (:func:`.vpl.make_vpls`), so clamped gather + compensation is
the unclamped VPL image in expectation: the image's energy is no longer moved from the edges
onto the open walls.
"""
from __future__ import annotations

from typing import Callable

import numpy as np
from numpy.typing import NDArray

from ...scene import BuiltScene
from ...vecmath import dot
from ..path import emission_found
from .vpl import clamp_factor

#: Most levels of the recursion (level 1: the receivers' own clamped light; level k: the
#: clamped light of the surfaces that compensate level k − 1); Russian roulette ends it first.
COMPENSATION_DEPTH = 64
#: Levels after which Russian roulette ends the recursion's paths (survival probability the
#: path's throughput, which the weights w < 1 and the reflectances keep shrinking).
COMPENSATION_RR_DEPTH = 3

#: BSDF rays of the compensation per iteration: each shading point sends
#: :func:`compensation_rays` = COMPENSATION_RAYS // points of them (1 … COMPENSATION_MAX_RAYS),
#: averaged. With one ray per point the compensation — a path-traced term at the 1–3 % of
#: points near a corner — puts its own noise on those pixels: at 1080p it averages out over
#: many small pixels, at 160×120 it made the error 20–35 % higher than no compensation at fixed work (README,
#: "VPL clamp").
COMPENSATION_RAYS = 1 << 18
COMPENSATION_MAX_RAYS = 16

#: radiance_at(p, ng, ns, wo, mat) -> (N, 3): reflected radiance toward wo at surface points
#: (normals flipped toward wo) by the clamped estimator.
RadianceAt = Callable[[NDArray, NDArray, NDArray, NDArray, NDArray], NDArray]


def compensation_weight(gmax: float, d2: NDArray, cos_y: NDArray) -> NDArray:
    """(n,) w = max(0, 1 − g_max·d²/cosθ_y): the share of the unclamped geometry term
    cosθ_y/d² that the clamp g_max removes (0 without a clamp and for cosθ_y ≤ 0)."""
    return 1.0 - clamp_factor(gmax, d2, np.maximum(cos_y, 0.0))


def reach(gmax: float) -> float:
    """Distance beyond which the clamp removes nothing: cosθ_y/d² ≤ 1/d² ≤ g_max [m]."""
    return float(1.0 / np.sqrt(gmax)) if np.isfinite(gmax) and gmax > 0 else np.inf


def compensation_rays(points: int) -> int:
    """BSDF rays per shading point of the clamp's compensation in one iteration: as many as
    keep the iteration's total near :data:`COMPENSATION_RAYS`, at least 1, at most
    :data:`COMPENSATION_MAX_RAYS` (160×120: 13; from 640×480 on: 1)."""
    return int(np.clip(COMPENSATION_RAYS // max(points, 1), 1, COMPENSATION_MAX_RAYS))


def compensate(scene: BuiltScene, gmax: float, p: NDArray, ng: NDArray, ns: NDArray, wo: NDArray,
               mat: NDArray, rng: np.random.Generator, radiance_at: RadianceAt,
               depth: int = COMPENSATION_DEPTH, rays: int = 1, emission_mis: bool = False,
               rr_depth: int = COMPENSATION_RR_DEPTH) -> tuple[NDArray, NDArray]:
    """ΔL at receivers (module docstring): the mean of ``rays`` paths per receiver, one BSDF
    sample per path and level.

    Args:
        p, ng, ns, wo: (N, 3) receivers: position [m], normals flipped toward wo, unit
            direction to the viewer; mat: (N,) shading keys.
        radiance_at: the clamped estimator of L_o at the surfaces found (:data:`RadianceAt`).
        emission_mis: ``radiance_at``'s direct light is next-event estimation weighted by MIS
            against BSDF sampling (:func:`~ercuts_core.integrators.path.next_event`): the
            BSDF sample drawn at every surface found then also collects the emission it
            meets, at any distance, with the other weight
            (:func:`~ercuts_core.integrators.path.emission_found`) — one more BSDF sample at
            the last level's surfaces.
    Returns:
        (N, 3) ΔL [W m⁻² sr⁻¹, the image's units], and (N,) bool the receivers whose first
        sample found a surface with w > 0 on any of their paths.
    """
    if rays > 1:
        rep = [np.repeat(a, rays, axis=0) for a in (p, ng, ns, wo, mat)]
        out, near = compensate(scene, gmax, *rep, rng, radiance_at, depth, emission_mis=emission_mis,
                               rr_depth=rr_depth)
        return out.reshape(-1, rays, 3).mean(axis=1), near.reshape(-1, rays).any(axis=1)
    n = len(p)
    out = np.zeros((n, 3))
    near = np.zeros(n, bool)
    if not np.isfinite(gmax) or n == 0:
        return out, near
    idx, beta = np.arange(n), np.ones((n, 3))
    t_max = reach(gmax)
    bsdf = None                             # of the level's points when already evaluated
    for level in range(depth + 1):
        collect = emission_mis and level > 0   # the surfaces found: their direct light's BSDF half
        if level == depth and not collect:
            break
        bsdf = scene.bsdf(mat, ns, ng, p) if bsdf is None else bsdf
        bs = bsdf.sample(wo, rng.random((len(idx), 3)))
        go = np.flatnonzero(bs.valid & (bs.weight.max(axis=1) > 0) & (collect | ~bs.is_delta))
        if len(go) == 0:
            break
        wi = bs.wi[go]
        surf = scene.intersect(scene.tracer.offset(p[go], ng[go], wi), wi, np.inf if collect else t_max)
        if collect:
            le = emission_found(scene, p[go], wi, bs.pdf[go], bs.is_delta[go], surf)
            np.add.at(out, idx[go], beta[go] * bs.weight[go] * le)
        if level == depth:
            break
        h = np.flatnonzero(surf.valid & (surf.t < t_max) & ~bs.is_delta[go])
        y = surf.subset(h)
        wo_y = -wi[h]
        sign = np.where(dot(y.ng, wo_y) < 0.0, -1.0, 1.0)[:, None]
        ng_y, ns_y = y.ng * sign, y.ns * sign
        w = compensation_weight(gmax, y.t ** 2, dot(ng_y, wo_y))
        bsdf = None
        if scene.has_specular_or_glass:     # no VPL stands there: the clamp removed nothing
            bsdf = scene.bsdf(y.mat, ns_y, ng_y, y.p)
            w[bsdf.is_specular_or_glass] = 0.0
        b = beta[go[h]] * bs.weight[go[h]] * w[:, None]
        if level + 1 >= rr_depth:          # Russian roulette: unbiased, however deep
            q = np.minimum(1.0, b.max(axis=1))
            b = np.where((rng.random(len(b)) < q)[:, None], b / np.maximum(q, 1e-300)[:, None], 0.0)
        live = np.flatnonzero(b.max(axis=1) > 0.0)
        if len(live) == 0:
            break
        idx, beta = idx[go[h[live]]], b[live]
        if level == 0:
            near[idx] = True
        p, ng, ns, wo, mat = y.p[live], ng_y[live], ns_y[live], wo_y[live], y.mat[live]
        bsdf = None if bsdf is None else bsdf.subset(live)
        np.add.at(out, idx, beta * radiance_at(p, ng, ns, wo, mat))
    return out, near


def compensates(settings, gmax: float) -> bool:
    """The render compensates the clamp: ``clamp_compensation`` on, a clamp set, and the
    direct light by next-event estimation (with ``direct_light='VPL'`` emitter VPLs stand for
    the direct light too, and L_o(y → x) would need the emission at y: not compensated)."""
    return bool(settings.clamp_compensation) and np.isfinite(gmax) and settings.direct_light == "NEE"
