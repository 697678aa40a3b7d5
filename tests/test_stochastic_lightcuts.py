"""Stochastic lightcuts (Yuksel 2019): the cut's expectation is the exact VPL sum, the
sampled estimate averages to it, and the cut obeys its size and bound rules."""
from __future__ import annotations

import numpy as np
import pytest

from ercuts_core.integrators.ercuts.light_tree import build_light_tree
from ercuts_core.integrators.ercuts.lightcuts import brute_force, cluster_bound, evaluate_lights
from ercuts_core.integrators.ercuts.stochastic_lightcuts import (leaf_cdf, sample_leaves, shared_cut,
                                                                 stochastic_cut,
                                                                 stochastic_lightcut)
from ercuts_core.sampling import luminance
from tests.test_lightcuts import cluster_truth, diffuse_points, per_light_luminance, room_scene
from tests.vpl_cases import random_vpls


@pytest.mark.parametrize("cut_size", [1, 8, 64])
def test_the_cut_partitions_every_lit_vpl(cut_size: int) -> None:
    """Σ over the cut of each node's exact light = the exact sum: the dropped nodes carry
    none and no VPL is counted twice (the estimator's expectation, by enumeration)."""
    lights, pts = random_vpls(3000, 9), diffuse_points(200, 9, occluder=True)
    tree = build_light_tree(*lights, seed=0)
    contrib = per_light_luminance(lights, pts)
    pt, node = stochastic_cut(tree, pts, cut_size)
    got = np.bincount(pt, cluster_truth(tree, contrib, pt, node), pts.count)
    exact = contrib.sum(axis=1)
    np.testing.assert_allclose(got, exact, rtol=1e-9, atol=1e-12)
    assert np.bincount(pt, minlength=pts.count).max() == cut_size
    assert np.all(np.diff(pt) >= 0)


def test_the_cut_splits_the_largest_bounds_first() -> None:
    """Refining further never raises a point's largest remaining bound (the nodes split
    are the ones with the largest bounds, so a cut of 64 has a smaller or equal maximum
    than a cut of 8)."""
    lights, pts = random_vpls(3000, 4), diffuse_points(50, 4)
    tree = build_light_tree(*lights, seed=0)
    pt8, node8 = stochastic_cut(tree, pts, 8)
    b8 = cluster_bound(tree, node8, pts, pt8)
    pt64, node64 = stochastic_cut(tree, pts, 64)
    b64 = cluster_bound(tree, node64, pts, pt64)
    for p in range(pts.count):
        assert b64[pt64 == p].max() <= b8[pt8 == p].max() * (1 + 1e-12)


def test_leaves_are_drawn_in_proportion_to_luminance() -> None:
    lights = random_vpls(500, 2)
    tree = build_light_tree(*lights, seed=0)
    cdf = leaf_cdf(tree)
    rng = np.random.default_rng(5)
    n = 200_000
    vpl, w = sample_leaves(tree, cdf, np.full(n, tree.root), rng.random(n))
    y = luminance(lights[2])
    p = y / y.sum()
    freq = np.bincount(vpl, minlength=len(y)) / n
    # multinomial: |freq − p| ≤ 5σ per VPL
    assert np.all(np.abs(freq - p) <= 5 * np.sqrt(p * (1 - p) / n) + 1e-12)
    np.testing.assert_allclose(w, y.sum() / y[vpl], rtol=1e-9)


@pytest.mark.parametrize("cut_size", [8, 32])
def test_the_estimate_averages_to_the_exact_sum(cut_size: int) -> None:
    """Mean of 300 independent estimates within 4.5 standard errors of the brute force sum
    at every point (room with VPLs on the walls; the per-point spread is measured)."""
    lights, pts = room_scene(5000, 60, 3)
    tree = build_light_tree(*lights, seed=0)
    exact = luminance(brute_force(*lights, pts))
    rng = np.random.default_rng(11)
    runs = np.array([luminance(stochastic_lightcut(tree, *lights, pts, rng, cut_size=cut_size).radiance)
                     for _ in range(300)])
    mean, se = runs.mean(axis=0), runs.std(axis=0, ddof=1) / np.sqrt(len(runs))
    assert np.all(np.abs(mean - exact) <= 4.5 * se + 1e-9 * exact)
    assert np.all(runs.std(axis=0) > 0)                      # really random


def test_a_wrong_pdf_is_detected() -> None:
    """The averaging test can fail: with the weight of a uniform pdf (|C| instead of
    1/p_v) the same check finds the bias."""
    lights, pts = room_scene(5000, 60, 3)
    tree = build_light_tree(*lights, seed=0)
    exact = luminance(brute_force(*lights, pts))
    rng = np.random.default_rng(11)
    pt, node = stochastic_cut(tree, pts, 8)
    cdf = leaf_cdf(tree)
    runs = []
    for _ in range(300):
        vpl, w = sample_leaves(tree, cdf, node, rng.random(pt.size))
        w = np.full_like(w, 1.0) * tree.leaf_count[node]       # wrong: uniform-pdf weight
        unit, _, _ = evaluate_lights(pts, pt, vpl, lights[0], lights[1])
        runs.append(np.bincount(pt, luminance(unit * lights[2][vpl]) * w, pts.count))
    runs = np.array(runs)
    mean, se = runs.mean(axis=0), runs.std(axis=0, ddof=1) / np.sqrt(len(runs))
    assert np.any(np.abs(mean - exact) > 4.5 * se)


def test_same_generator_state_same_image_and_empty_inputs() -> None:
    lights, pts = room_scene(2000, 30, 1)
    tree = build_light_tree(*lights, seed=0)
    a = stochastic_lightcut(tree, *lights, pts, np.random.default_rng(3), cut_size=16)
    b = stochastic_lightcut(tree, *lights, pts, np.random.default_rng(3), cut_size=16)
    np.testing.assert_array_equal(a.radiance, b.radiance)
    assert a.shadow_rays <= 16 * pts.count and not a.unmet.any()
    with pytest.raises(ValueError):
        stochastic_lightcut(tree, *lights, pts, np.random.default_rng(3), cut_size=0)


def _block_refs(n: int, block: int) -> np.ndarray:
    j = np.arange(n)
    return j - j % block


@pytest.mark.parametrize("backend", ["numba", "numpy"])
def test_a_shared_cut_partitions_every_vpl_at_every_sharing_point(backend: str) -> None:
    """Cut sharing (``stochastic_cut_sharing``): each point uses its block head's cut with the
    empty clusters kept, so Σ over the cut of each node's exact light = the exact sum at every
    point of the block, not only at the head (the estimator's expectation, by enumeration)."""
    from ercuts_core import kernels
    lights, pts = random_vpls(3000, 19), diffuse_points(200, 19, occluder=True)
    tree = build_light_tree(*lights, seed=0)
    contrib = per_light_luminance(lights, pts)
    ref = _block_refs(pts.count, 4)
    with kernels.backend(backend):
        pt, node = shared_cut(tree, pts, ref, 16)
    got = np.bincount(pt, cluster_truth(tree, contrib, pt, node), pts.count)
    np.testing.assert_allclose(got, contrib.sum(axis=1), rtol=1e-9, atol=1e-12)
    assert np.all(np.diff(pt) >= 0)
    # the members of a block hold their head's nodes
    for p in (1, 2, 3, 41):
        assert np.array_equal(node[pt == p], node[pt == ref[p]])
    # the head's refined nodes are its own cut's; the kept empty clusters come on top
    with kernels.backend(backend):
        own_pt, own_node = stochastic_cut(tree, pts, 16)
    for p in np.unique(ref)[:20]:
        assert set(own_node[own_pt == p]) <= set(node[pt == p])


def test_dropping_empty_clusters_of_a_shared_cut_is_detected() -> None:
    """The partition check can fail: the head's own cut (empty clusters dropped) used at the
    other points of its block misses light that reaches them."""
    lights, pts = random_vpls(3000, 19), diffuse_points(200, 19, occluder=True)
    tree = build_light_tree(*lights, seed=0)
    contrib = per_light_luminance(lights, pts)
    ref = _block_refs(pts.count, 4)
    hpt, hnode = stochastic_cut(tree, pts, 16)               # every point's own cut
    keep = np.isin(hpt, np.unique(ref))
    hpt, hnode = hpt[keep], hnode[keep]
    c = np.bincount(hpt, minlength=pts.count)[ref]
    pt = np.repeat(np.arange(pts.count), c)
    starts = (np.cumsum(np.bincount(hpt, minlength=pts.count)) - np.bincount(hpt, minlength=pts.count))[ref]
    node = hnode[np.repeat(starts, c) + np.arange(pt.size) - np.repeat(np.cumsum(c) - c, c)]
    got = np.bincount(pt, cluster_truth(tree, contrib, pt, node), pts.count)
    assert np.any(np.abs(got - contrib.sum(axis=1)) > 1e-6 * contrib.sum(axis=1).max())


def test_shared_cut_estimate_averages_to_the_exact_sum() -> None:
    """With cuts shared over blocks of 4, the mean of 300 estimates is still within 4.5
    standard errors of the brute-force sum at every point."""
    lights, pts = room_scene(5000, 60, 3)
    tree = build_light_tree(*lights, seed=0)
    exact = luminance(brute_force(*lights, pts))
    rng = np.random.default_rng(12)
    ref = _block_refs(pts.count, 4)
    runs = np.array([luminance(stochastic_lightcut(tree, *lights, pts, rng, cut_size=8, ref=ref).radiance)
                     for _ in range(300)])
    mean, se = runs.mean(axis=0), runs.std(axis=0, ddof=1) / np.sqrt(len(runs))
    assert np.all(np.abs(mean - exact) <= 4.5 * se + 1e-9 * exact)


def test_share_refs_keep_edges_apart() -> None:
    """Blocks of 4 consecutive points share the head's cut on one plane; a point across a
    crease (another normal), off the head's plane, in another row or of another material
    uses its own."""
    from types import SimpleNamespace

    from ercuts_core.integrators.ercuts.gather import share_refs
    n = 16
    p = np.column_stack([np.arange(n) * 0.01, np.zeros(n), np.ones(n)])
    ns = np.tile([0.0, 0.0, 1.0], (n, 1))
    mat = np.zeros(n, np.int64)
    pixel = np.arange(n)
    ns[5] = [0.0, 0.6, 0.8]                  # crease: cos 0.8 to the head's normal
    p[6, 2] += 0.01                          # 1 cm off the head's plane at 2 cm distance
    mat[9] = 1                               # another material
    g = SimpleNamespace(p=p, ns=ns, mat=mat, pixel=pixel)
    ref = share_refs(g, np.arange(n), 4, width=14)   # pixels 14, 15: the next row
    expect = np.array([0, 0, 0, 0, 4, 5, 6, 4, 8, 9, 8, 8, 12, 12, 14, 15])
    assert np.array_equal(ref, expect)


def test_cut_sharing_in_a_render_is_unbiased_and_shares() -> None:
    """``stochastic_cut_sharing = 4`` through ``render``: most points share a cut
    (``shared_cut_fraction``), and the gathered light per pixel differs from the unshared
    render (same VPLs: same seed) by noise only — the mean difference over the pixels is
    within 4.5 standard errors of 0."""
    from ercuts_core import RenderSettings, render, scenes
    desc = scenes.cornell_box(48, 36)
    out = {}
    for k in (1, 4):
        res = render(desc, RenderSettings(gather="STOCHASTIC", stochastic_cut_sharing=k, seed=3,
                                          samples=4, direct_samples=4))
        out[k] = (luminance(res.aovs["indirect"].reshape(-1, 3)), res.stats)
    # 48-pixel rows, corners and the boxes break many blocks: about half the points share
    assert 0.3 < out[4][1]["shared_cut_fraction"] < 0.75 and "shared_cut_fraction" not in out[1][1]
    d = out[4][0] - out[1][0]
    assert np.abs(d.mean()) <= 4.5 * d.std(ddof=1) / np.sqrt(d.size)
    assert d.std() > 0                                   # really other draws
