"""The lightcut material bound at rough glass receivers (issue 15).

M = f(wo, wi)·|n·wi| of the rough glass lobe (GGX dielectric reflection + transmission,
Walter et al. 2007) over a cluster's box must never be exceeded
(:func:`ercuts_core.bsdf.rough_glass_cosine_bound`, ``GlossyReceivers`` with ``glass``).  The
old bound, the lobe's value at normal incidence (``bsdf_max_value``), is exceeded: toward the
reflection peak at grazing views and on the transmission side near the refracted direction.

Random receivers: roughness 0.02–1, IOR 1.1–2.5, wo on both sides of the surface (entering
and leaving the glass, total internal reflection included), a third of them grazing
(n·wo ∈ [1e-4, 0.05]); random boxes on both sides, around the mirror direction r, the
refracted direction t, the straight-through direction −wo and anywhere, of sizes from 1e-3
to 2 at distances 0.3–3; M over dense samples of each box (interior, corners, edge points,
and the box points nearest the peak ray).  Fixed seeds.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from ercuts_core.bsdf import (COS_EPS, Bsdf, bsdf_max_value, fresnel_dielectric, fresnel_perp,
                              refracted_direction, rough_glass_cosine_bound)
from ercuts_core.description import MaterialTable
from ercuts_core.integrators.ercuts.light_tree import build_light_tree
from ercuts_core.integrators.ercuts.lightcuts import (GlossyReceivers, ShadingPoints,
                                                      _glass_material_bound,
                                                      _receiver_cos_bound, brute_force, lightcut)
from ercuts_core.sampling import luminance
from ercuts_core.vecmath import dot
from tests.test_glossy_bound import bound_table, violations, worst_member
from tests.vpl_cases import random_vpls, receiver_points, unit

#: Relative slack for rounding (the bound is exact at the peak: ratios reach 1 − 1e-7).
TOL = 1e-9


def glass_receivers(n: int, seed: int, transmission=1.0, metallic=0.0):
    """n rough glass receivers at the origin-free frame: (table, bsdf, wo, ns) with random
    roughness 0.02–1, IOR 1.1–2.5, base colour, normals, wo on both sides (a third grazing)."""
    rng = np.random.default_rng(seed)
    nrm = unit(rng.normal(size=(n, 3)))
    cos = rng.random(n)
    graze = rng.random(n) < 1.0 / 3.0
    cos[graze] = 10.0 ** rng.uniform(-4.0, np.log10(0.05), graze.sum())
    side = np.where(rng.random(n) < 0.5, 1.0, -1.0)             # wo outside / inside
    tang = unit(np.cross(nrm, rng.normal(size=(n, 3))))
    wo = side[:, None] * (cos[:, None] * nrm) + np.sqrt(1.0 - cos * cos)[:, None] * tang
    table = MaterialTable([f"g{i}" for i in range(n)], rng.uniform(0.2, 1.0, (n, 3)),
                          rng.uniform(0.02, 1.0, n), np.broadcast_to(metallic, (n,)).copy(),
                          rng.uniform(0.0, 1.0, n), np.zeros((n, 3)), (),
                          np.broadcast_to(transmission, (n,)).copy(), rng.uniform(1.1, 2.5, n))
    idx = np.arange(n)
    bsdf = Bsdf.from_table(table, idx, nrm, nrm)
    ns = nrm * side[:, None]                                    # flipped to wo's side
    return table, bsdf, wo, ns


def random_boxes(wo, ns, eta, per: int, rng):
    """``per`` boxes per receiver (K = n·per): (point index, bmin, bmax), centred around r, t,
    −wo or a random direction (both sides), half sizes 1e-3–1, distances 0.3–3."""
    n = len(wo)
    pt = np.repeat(np.arange(n), per)
    r = 2.0 * dot(wo, ns)[:, None] * ns - wo
    t, _ = refracted_direction(wo, ns, eta)
    kind = rng.integers(0, 4, pt.size)
    axis = np.where((kind == 0)[:, None], r[pt], np.where((kind == 1)[:, None], t[pt], -wo[pt]))
    axis = np.where((kind == 3)[:, None], unit(rng.normal(size=(pt.size, 3))), axis)
    jitter = 10.0 ** rng.uniform(-4.0, -0.5, (pt.size, 1))
    axis = unit(axis + jitter * rng.normal(size=(pt.size, 3)))
    dist = rng.uniform(0.3, 3.0, (pt.size, 1))
    half = 10.0 ** rng.uniform(-3.0, 0.0, (pt.size, 3)) * np.minimum(dist, 1.0)
    c = axis * dist
    return pt, c - half, c + half


def box_samples(x, axes, bmin, bmax, count: int, rng):
    """(K, S, 3) points of each box: random interior points, the 8 corners, random points on
    the 12 edges, and the points of the rays x + s·axis (each axis of ``axes``) clamped into
    the box (the box points nearest to a lobe's peak direction)."""
    K = len(bmin)
    size = bmax - bmin
    u = rng.random((K, count, 3))
    corners = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)], float)
    e = rng.random((K, 48, 3))
    ax = rng.integers(0, 3, (K, 48))
    e = np.where(np.arange(3)[None, None, :] == ax[..., None], e, np.round(e))
    pts = [bmin[:, None] + size[:, None] * u, bmin[:, None] + size[:, None] * corners[None],
           bmin[:, None] + size[:, None] * e]
    s = np.geomspace(1e-3, 10.0, 64)
    for a in axes:
        ray = x[:, None] + s[None, :, None] * a[:, None]
        pts.append(np.clip(ray, bmin[:, None], bmax[:, None]))
    return np.concatenate(pts, axis=1)


def material_term(bsdf: Bsdf, wo, ns, pt, y, x):
    """(K, S, 3) M = f(wo, wi)·|n·wi| of the receivers pt (K,) toward the points y (K, S, 3)."""
    K, S, _ = y.shape
    d = y - x[:, None]
    wi = (d / np.linalg.norm(d, axis=2, keepdims=True)).reshape(-1, 3)
    lane = np.repeat(pt, S)
    f = bsdf.subset(lane).eval(np.repeat(wo[pt], S, axis=0), wi)
    return (f * np.abs(dot(wi, np.repeat(ns[pt], S, axis=0)))[:, None]).reshape(K, S, 3)


def dense_case(n: int, per: int, samples: int, seed: int, **kw):
    """(M (K,S,3), new bound (K,3), old bound (K,3), point index (K,)) over random boxes."""
    rng = np.random.default_rng(seed + 77)
    table, bsdf, wo, ns = glass_receivers(n, seed, **kw)
    eta = bsdf.eta_rel(wo)
    pt, bmin, bmax = random_boxes(wo, ns, eta, per, rng)
    x = np.zeros((len(pt), 3))
    gl = GlossyReceivers.from_bsdf(bsdf, wo, ns)
    assert gl.glass is not None and gl.glass.all() and gl.mask.all()
    new = _glass_material_bound(gl, x, pt, bmin, bmax)
    r = 2.0 * dot(wo, ns)[:, None] * ns - wo
    t, _ = refracted_direction(wo, ns, eta)
    y = box_samples(x, (r[pt], t[pt], -wo[pt], ns[pt], -ns[pt]), bmin, bmax, samples, rng)
    M = material_term(bsdf, wo, ns, pt, y, x)
    # The old bound: the constant f_bound times the receiver cosine bound of both sides
    pts = ShadingPoints(x[:1].repeat(n, 0), ns, wo, bsdf_max_value(table, np.arange(n)),
                        None, None, transmissive=np.ones(n, bool))
    old = _receiver_cos_bound(pts, pt, bmin, bmax)[:, None] * pts.f_bound[pt]
    return M, new, old, pt


def ratios(M, bound):
    """(K, 3) max over the samples of M / bound (inf where M > 0 = bound)."""
    top = M.max(axis=1)
    return np.where(bound > 0.0, top / np.where(bound > 0.0, bound, 1.0), np.where(top > 0, np.inf, 0.0))


# ------------------------------------------------------------------------------ tests


def test_pointwise_bound_dominates_the_lobe() -> None:
    """With the exact cosines of single directions (a box shrunk to a point) the bound is
    never below M, and reaches it at the peaks (ratio → 1); 400 000 random (wo, wi)."""
    rng = np.random.default_rng(3)
    _, bsdf, wo, ns = glass_receivers(400_000, 11)
    eta = bsdf.eta_rel(wo)
    r = 2.0 * dot(wo, ns)[:, None] * ns - wo
    t, _ = refracted_direction(wo, ns, eta)
    N = len(wo)
    kind = rng.integers(0, 4, N)
    sc = 10.0 ** rng.uniform(-5.0, 0.0, (N, 1))
    axis = np.where((kind == 0)[:, None], r, np.where((kind == 1)[:, None], t, -wo))
    wi = unit(axis + sc * rng.normal(size=(N, 3)))
    wi = np.where((kind == 3)[:, None], unit(rng.normal(size=(N, 3))), wi)
    M = bsdf.eval(wo, wi) * np.abs(dot(wi, ns))[:, None]
    w = dot(wo, wi)
    refl, trans = rough_glass_cosine_bound(dot(wo, ns), bsdf.alpha, eta, w, w, dot(r, wi), dot(t, wi))
    up = dot(wi, ns) > 0.0
    bound = np.where(up[:, None], (refl * bsdf.kr)[:, None], trans[:, None] * bsdf.kt)
    ratio = ratios(M[:, None], bound)
    print(f"pointwise: worst M/bound {ratio.max():.9f} over {N} pairs "
          f"({int((M.max(1) > 0).sum())} lit)")
    assert ratio.max() <= 1.0 + TOL
    assert ratio.max() > 0.999                    # tight at the peak
    assert np.all(np.isfinite(bound))


def test_fresnel_perp_bounds_the_dielectric_fresnel() -> None:
    """F ≤ R_s(c_lo) for every c ≥ c_lo (R_s ≥ F and R_s non-increasing), over IOR 1.0001–10
    both ways; F itself is not monotone (η = 10)."""
    c = np.linspace(0.0, 1.0, 2001)
    for eta in np.concatenate([np.geomspace(1.0001, 10.0, 60), 1.0 / np.geomspace(1.0001, 10.0, 60)]):
        e = np.full_like(c, eta)
        F, _ = fresnel_dielectric(c, e)
        Rs = fresnel_perp(c, e)
        assert np.all(F <= Rs + 1e-15)
        assert np.all(np.diff(Rs) <= 1e-15)
    F10, _ = fresnel_dielectric(c, np.full_like(c, 10.0))
    assert np.diff(F10).max() > 0.0


@pytest.mark.parametrize("seed", [0, 1])
def test_box_bound_dominates_dense_samples(seed: int) -> None:
    """Per channel, M̄ ≥ max of M over ~1 000 points of each of 2 400 random boxes (600
    receivers × 4 boxes: reflection and transmission side, near the peaks); the old
    normal-incidence bound is exceeded on the same boxes."""
    M, new, old, pt = dense_case(600, 4, 700, seed)
    r_new, r_old = ratios(M, new), ratios(M, old)
    lit = M.max(axis=(1, 2)) > 0.0
    worst_old = r_old.max()
    print(f"seed {seed}: {len(pt)} boxes ({lit.sum()} lit), {M.shape[1]} samples each; new "
          f"bound: worst M/M̄ {r_new.max():.6f}, median {np.median(r_new.max(1)[lit]):.3g}; old "
          f"bound exceeded in {(r_old.max(1) > 1 + TOL).sum()} boxes, worst ×{worst_old:.3g}")
    assert r_new.max() <= 1.0 + TOL
    assert np.all(np.isfinite(new))
    assert worst_old > 3.0


def test_partly_transmitting_principled_bound() -> None:
    """A Principled BSDF with transmission 0.5 and some metallic: diffuse + opaque GGX +
    the glass lobe (weights (1 − m)(1 − t), m, (1 − m)·t) under one M̄."""
    M, new, _, _ = dense_case(300, 4, 500, 5, transmission=0.5, metallic=0.3)
    assert ratios(M, new).max() <= 1.0 + TOL


def test_old_bound_fails_where_the_new_one_holds() -> None:
    """The old bound (the lobe at normal incidence, ``bsdf_max_value``) fails on both sides:
    (a) toward the reflection peak at a grazing view (n·wo = 0.005, roughness 0.05, IOR 2.5:
    M ∝ F·G1(wo)/(4 n·wo) grows as 1/(α sin θ_o) there); (b) on the transmission side at a
    grazing view of a very rough ball (roughness 1, IOR 1.1) near the straight-through
    direction, where G1(wo)/(n·wo) → 2/α exceeds the normal-incidence value 1.  The new bound
    holds, within a small factor of the true maximum.  Exceed factors printed."""
    n = np.array([[0.0, 0.0, 1.0]] * 2)
    table = MaterialTable(["a", "b"], np.ones((2, 3)), [0.05, 1.0], np.zeros(2), np.zeros(2),
                          np.zeros((2, 3)), (), np.ones(2), np.array([2.5, 1.1]))
    bsdf = Bsdf.from_table(table, np.arange(2), n, n)
    wo = unit(np.array([[1.0, 0.0, 0.005], [1.0, 0.0, 0.001]]))
    ns = n
    r = 2.0 * dot(wo, ns)[:, None] * ns - wo
    axis = np.stack([r[0], unit(np.array([[-1.0, 0.0, -0.014]]))[0]])
    half = np.array([[1e-3], [2e-3]])
    bmin, bmax = axis - half, axis + half
    assert bmax[1, 2] < 0.0                              # (b): the box is below the surface
    x = np.zeros((2, 3))
    gl = GlossyReceivers.from_bsdf(bsdf, wo, ns)
    new = _glass_material_bound(gl, x, np.arange(2), bmin, bmax)
    y = box_samples(x, (axis,), bmin, bmax, 4000, np.random.default_rng(0))
    M = material_term(bsdf, wo, ns, np.arange(2), y, x).max(axis=1)
    old = bsdf_max_value(table, np.arange(2))
    exceed = M[:, 0] / old[:, 0]
    print("old bound exceeded ×", np.round(exceed, 3), "; new bound / max M:",
          np.round(new[:, 0] / M[:, 0], 3))
    assert exceed[0] > 10.0 and exceed[1] > 1.3
    assert np.all(M <= new * (1 + TOL))
    assert np.all(new[:, 0] / M[:, 0] < 2.0)           # and it stays tight here


def glass_points(n: int, seed: int, diffuse_share: float = 0.0) -> ShadingPoints:
    """Random rough glass receivers (and a share of Lambert points) in [−3, 3]³ as the gather
    builds them: lightcut normal = the G-buffer normal on wo's side, transmissive glass."""
    rng = np.random.default_rng(seed + 3000)
    table, bsdf, wo, ns = glass_receivers(n, seed)
    dif = rng.random(n) < diffuse_share
    table.transmission[dif] = 0.0
    table.roughness[dif] = 1.0
    table.specular[dif] = 0.0
    x = rng.random((n, 3)) * 6.0 - 3.0
    return receiver_points(table, x, ns, wo, transmissive=~dif)


@pytest.mark.parametrize("seed", [0, 1])
def test_cluster_bound_dominates_every_member_at_glass_receivers(seed: int) -> None:
    """L̄_C ≥ max_{i∈C} Y(f_i |cos θ_i| G_i ⊙ I_C) for every (point, internal node) of a
    500-VPL tree (VPLs on both sides of the receivers); the old constant bound fails."""
    lights = random_vpls(500, 50 + seed, scale=8.0, shift=-4.0)
    tree = build_light_tree(*lights, seed=seed)
    new = glass_points(150, seed, diffuse_share=0.2)
    old = replace(new, glossy=None)
    worst = worst_member(tree, lights, new)
    bad_new, lit, ratio_new = violations(bound_table(tree, new), worst)
    bad_old, _, ratio_old = violations(bound_table(tree, old), worst)
    print(f"seed {seed}: {lit} lit (point, cluster) pairs; old bound exceeded in {bad_old} "
          f"(worst ×{ratio_old:.3g}), new in {bad_new} (worst ratio {ratio_new:.3g})")
    assert bad_new == 0, (bad_new, ratio_new)
    assert bad_old > 0 and ratio_old > 2.0
    dif = ~new.glossy.mask
    assert dif.any()
    np.testing.assert_array_equal(bound_table(tree, new)[dif], bound_table(tree, old)[dif])


@pytest.mark.parametrize("max_error", [0.02, 0.1])
def test_total_mode_relative_error_at_glass_receivers(max_error: float) -> None:
    """error_mode='total' keeps |L̃ − L| ≤ ε·L at rough glass receivers with the new bound."""
    lights = random_vpls(800, 60, scale=8.0, shift=-4.0)
    pts = glass_points(150, 60, diffuse_share=0.2)
    tree = build_light_tree(*lights, seed=5)
    exact = luminance(brute_force(*lights, pts))
    res = lightcut(tree, *lights, pts, max_error=max_error, error_mode="total")
    got = luminance(res.radiance)
    assert np.all(np.abs(got - exact) <= max_error * exact + 1e-12 * exact.max())
    assert res.cut_size.mean() < 0.9 * len(lights[0])


def test_glass_receivers_fields() -> None:
    """Rough glass lanes join the mask with their weights, the refraction t (unit, Snell's
    law) and η' of wo's side; a grazing wo (n·wo ≤ COS_EPS) gets no glass weight; smooth
    glass (a delta lobe) is no receiver; total internal reflection leaves t = −n."""
    up = np.tile([0.0, 0.0, 1.0], (5, 1))
    bsdf = Bsdf.from_params(np.full((5, 3), 0.5), [0.3, 0.3, 0.3, 0.0, 0.3], 0.0, 0.5, up, up,
                            transmission=1.0, ior=1.5)
    wo = unit(np.array([[0.3, 0.0, 1.0], [0.3, 0.0, -1.0], [1.0, 0.0, 1e-12],
                        [0.3, 0.0, 1.0], [1.0, 0.0, -0.2]]))
    ns = np.where(dot(wo, up)[:, None] < 0, -up, up)
    g = GlossyReceivers.from_bsdf(bsdf, wo, ns)
    assert g.mask.tolist() == [True, True, True, False, True]
    assert g.glass.tolist() == [True, True, True, False, True]
    np.testing.assert_allclose(g.eta[[0, 1]], [1.5, 1 / 1.5])
    assert g.kr[2] == 0.0 and np.all(g.kt[2] == 0.0) and g.kr[0] == 1.0
    np.testing.assert_allclose(np.linalg.norm(g.t[:2], axis=1), 1.0)
    sin_o = np.linalg.norm(np.cross(wo[:2], ns[:2]), axis=1)
    sin_t = np.linalg.norm(np.cross(g.t[:2], ns[:2]), axis=1)
    np.testing.assert_allclose(sin_o, g.eta[:2] * sin_t)            # Snell: sin θ_o = η'·sin θ_t
    assert np.all(dot(g.t[:2], ns[:2]) < 0)
    np.testing.assert_array_equal(g.t[4], -ns[4])                   # beyond the critical angle
    assert COS_EPS > 0
