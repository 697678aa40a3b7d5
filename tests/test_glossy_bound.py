"""The lightcut material bound at glossy (GGX) receivers (issue 13, part 3).

The old bound of the specular lobe, F90/(4πα²) (``bsdf_max_value``: the lobe at normal
incidence), is exceeded at glossy receivers; the per-cluster bound of
``GlossyReceivers`` / ``ggx_cosine_bound`` must dominate every member of every cluster.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from ercuts_core.bsdf import Bsdf, ggx_cosine_bound, ggx_d, smith_lambda
from ercuts_core.description import MaterialTable
from ercuts_core.integrators.ercuts.light_tree import build_light_tree
from ercuts_core.integrators.ercuts.lightcuts import (
    GlossyReceivers,
    ShadingPoints,
    brute_force,
    cluster_bound,
    evaluate_lights,
    lightcut,
)
from ercuts_core.sampling import luminance

#: Principled roughness of the glossy receivers (alpha = roughness²).
ROUGHNESS = (0.05, 0.1, 0.2, 0.35, 0.5)


from ercuts_core.vecmath import dot as _dot
from tests.vpl_cases import random_vpls, receiver_points
from tests.vpl_cases import unit as _unit


def random_wo(nrm: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Unit wo above ``nrm``: a third grazing (n·wo ∈ [1e-3, 0.05]), the rest uniform."""
    n = len(nrm)
    cos = rng.random(n)
    graze = rng.random(n) < 1.0 / 3.0
    cos[graze] = 10.0 ** rng.uniform(-3.0, np.log10(0.05), graze.sum())
    t = _unit(np.cross(nrm, rng.normal(size=(n, 3))))
    return cos[:, None] * nrm + np.sqrt(1.0 - cos * cos)[:, None] * t


def glossy_points(n: int, seed: int, diffuse_share: float = 0.0, new_bound: bool = True
                  ) -> ShadingPoints:
    """Random receivers with the renderer's BSDF: GGX lobes of the ROUGHNESS values
    (random base colour, metallic, specular), random wo incl. grazing ones; a share of
    pure Lambert points.  ``new_bound=False`` gives the old constant material bound only."""
    rng = np.random.default_rng(seed + 2000)
    x = rng.random((n, 3)) * 6.0 - 3.0
    nrm = _unit(rng.normal(size=(n, 3)))
    wo = random_wo(nrm, rng)
    diffuse = rng.random(n) < diffuse_share
    table = MaterialTable([f"m{i}" for i in range(n)], rng.random((n, 3)),
                          np.where(diffuse, 1.0, np.array(ROUGHNESS)[np.arange(n) % len(ROUGHNESS)]),
                          np.where(diffuse, 0.0, (rng.random(n) < 0.5) * rng.random(n)),
                          np.where(diffuse, 0.0, rng.uniform(0.2, 1.0, n)), np.zeros((n, 3)))
    return receiver_points(table, x, nrm, wo, glossy=new_bound)


def memberships(tree) -> tuple[np.ndarray, np.ndarray]:
    """(node, vpl) for every VPL of every internal node's subtree."""
    node = np.repeat(np.arange(tree.n_nodes), tree.leaf_count)
    first = np.repeat(tree.leaf_start - np.cumsum(tree.leaf_count) + tree.leaf_count,
                      tree.leaf_count)
    vpl = tree.leaf_order[first + np.arange(len(node))]
    internal = ~tree.is_leaf[node]
    return node[internal], vpl[internal]


def worst_member(tree, lights, pts: ShadingPoints) -> np.ndarray:
    """(P, n_nodes) max over a cluster's VPLs of Y(f·cos θ_x·G ⊙ I_C), V = 1: the largest
    estimate any representative could give (every member evaluated)."""
    pos, nrm, _ = lights
    n_pts, n = pts.count, len(pos)
    pidx, vidx = np.repeat(np.arange(n_pts), n), np.tile(np.arange(n), n_pts)
    unit = evaluate_lights(pts, pidx, vidx, pos, nrm)[0].reshape(n_pts, n, 3)
    node, vpl = memberships(tree)
    out = np.zeros((n_pts, tree.n_nodes))
    for p in range(n_pts):
        y = luminance(unit[p, vpl] * tree.intensity[node])
        np.maximum.at(out[p], node, y)
    return out


def bound_table(tree, pts: ShadingPoints) -> np.ndarray:
    """(P, n_nodes) cluster bounds L̄_C."""
    node = np.tile(np.arange(tree.n_nodes), pts.count)
    pidx = np.repeat(np.arange(pts.count), tree.n_nodes)
    return cluster_bound(tree, node, pts, pidx).reshape(pts.count, tree.n_nodes)


def violations(bound: np.ndarray, worst: np.ndarray) -> tuple[int, int, float]:
    """(violating pairs, pairs with a non-zero member, worst ratio member/bound)."""
    lit = worst > 0
    ratio = np.where(lit, worst / np.where(bound > 0, bound, 1e-300), 0.0)
    ratio = np.where(np.isinf(bound), 0.0, ratio)
    bad = ratio > 1.0 + 1e-9
    return int(bad.sum()), int(lit.sum()), float(ratio.max())


# ------------------------------------------------------------------------------ tests


def test_ggx_cosine_bound_dominates_lobe_samples() -> None:
    """D·G2/(4 n·wo) ≤ ggx_cosine_bound(n·wo, α, r·wi) for random (wo, wi), incl. grazing."""
    rng = np.random.default_rng(0)
    k = 400_000
    n = np.tile([0.0, 0.0, 1.0], (k, 1))
    wo = random_wo(n, rng)
    wi = _unit(rng.normal(size=(k, 3)))
    wi[:, 2] = np.abs(wi[:, 2])
    near = rng.random(k) < 0.5                    # half of them close to the mirror direction
    r = 2.0 * wo[:, 2:3] * n - wo
    wi[near] = _unit(r[near] + rng.normal(size=(near.sum(), 3)) * 10.0 ** rng.uniform(-4, 0, (near.sum(), 1)))
    wi[:, 2] = np.abs(wi[:, 2])
    alpha = np.array(ROUGHNESS)[rng.integers(0, len(ROUGHNESS), k)] ** 2
    cos_o, cos_i = wo[:, 2], wi[:, 2]
    ok = cos_i > 1e-10
    h = _unit(wo + wi)
    g2 = 1.0 / (1.0 + smith_lambda(cos_o, alpha) + smith_lambda(cos_i, alpha))
    value = np.where(ok, ggx_d(h[:, 2], alpha) * g2 / (4.0 * cos_o), 0.0)
    bound = ggx_cosine_bound(cos_o, alpha, _dot(r, wi))
    assert np.all(value <= bound * (1 + 1e-12)), np.max(value / bound)
    assert np.all(np.isfinite(bound))
    np.testing.assert_allclose(ggx_cosine_bound(np.ones(1), np.full(1, 0.01), np.ones(1)),
                               1.0 / (4.0 * np.pi * 1e-4))      # peak: the old bound


@pytest.mark.parametrize("seed", [0, 1])
def test_cluster_bound_dominates_every_member_at_glossy_receivers(seed: int) -> None:
    """L̄_C ≥ max_{i∈C} Y(f_i cos θ_i G_i ⊙ I_C) for every (point, internal node); the old
    constant bound (lobe peak at normal incidence) fails it."""
    lights = random_vpls(500, 20 + seed)
    tree = build_light_tree(*lights, seed=seed)
    new = glossy_points(120, seed, diffuse_share=0.2)
    old = replace(new, glossy=None)
    worst = worst_member(tree, lights, new)
    bad_new, lit, ratio_new = violations(bound_table(tree, new), worst)
    bad_old, _, ratio_old = violations(bound_table(tree, old), worst)
    print(f"seed {seed}: {lit} lit (point, cluster) pairs; old bound exceeded in {bad_old} "
          f"(worst ×{ratio_old:.3g}), new in {bad_new} (worst ratio {ratio_new:.3g})")
    assert bad_new == 0, (bad_new, ratio_new)
    assert bad_old > 0 and ratio_old > 2.0      # the old bound is no bound (×2.7, ×33 here)
    # Diffuse points keep the constant bound exactly
    dif = ~new.glossy.mask
    assert dif.any()
    np.testing.assert_array_equal(bound_table(tree, new)[dif], bound_table(tree, old)[dif])


def test_glossy_bound_follows_the_lobe() -> None:
    """Clusters far from the mirror direction get a far smaller bound than the peak."""
    lights = random_vpls(500, 30)
    tree = build_light_tree(*lights, seed=0)
    pts = glossy_points(60, 30)
    b_new, b_old = bound_table(tree, pts), bound_table(tree, replace(pts, glossy=None))
    fin = np.isfinite(b_new) & (b_old > 0)
    sharp = (pts.glossy.alpha < 0.05)[:, None] & (pts.glossy.cos_o > 0.5)[:, None] & fin
    assert np.median(b_new[sharp] / b_old[sharp]) < 0.2


@pytest.mark.parametrize("max_error", [0.02, 0.1])
def test_total_mode_relative_error_at_glossy_receivers(max_error: float) -> None:
    """error_mode='total' keeps |L̃ − L| ≤ ε·L at glossy receivers with the new bound."""
    lights = random_vpls(800, 40)
    pts = glossy_points(150, 40, diffuse_share=0.2)
    tree = build_light_tree(*lights, seed=5)
    exact = luminance(brute_force(*lights, pts))
    res = lightcut(tree, *lights, pts, max_error=max_error, error_mode="total")
    got = luminance(res.radiance)
    assert np.all(np.abs(got - exact) <= max_error * exact + 1e-12 * exact.max())
    assert res.cut_size.mean() < 0.9 * len(lights[0])


def test_glossy_receivers_masks() -> None:
    """Diffuse lanes and normals that are not the lobe's keep the constant bound; a lightcut
    normal opposite to the lobe's (no reflected light) or a grazing wo gets no specular
    bound; the mirror direction is a unit vector."""
    up = np.tile([0.0, 0.0, 1.0], (5, 1))
    bsdf = Bsdf.from_params(np.full((5, 3), 0.5), [0.2, 0.2, 0.2, 0.2, 1.0], 0.0,
                            [0.5, 0.5, 0.5, 0.5, 0.0], up, up)
    wo = _unit(np.array([[0.3, 0.0, 1.0], [0.3, 0.0, 1.0], [1.0, 0.0, 1e-12],
                         [0.3, 0.0, 1.0], [0.3, 0.0, 1.0]]))
    n = up.copy()
    n[1] = -up[1]                                  # opposite of the lobe's normal
    n[3] = _unit(np.array([[0.0, 0.1, 1.0]]))[0]   # some other normal
    g = GlossyReceivers.from_bsdf(bsdf, wo, n)
    assert g.mask.tolist() == [True, True, True, False, False]
    assert np.all(g.spec[0] > 0) and np.all(g.spec[1:] == 0)
    np.testing.assert_allclose(np.linalg.norm(g.r, axis=1), 1.0)
    np.testing.assert_allclose(g.r[0], wo[0] * [-1, -1, 1])
