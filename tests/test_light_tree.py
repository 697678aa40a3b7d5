"""Invariants of the Ercuts light tree (Zhu, Xu, Pan 2010 §3.4; ercuts_core/light_tree.py)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binomtest, chisquare

from ercuts_core.integrators.ercuts.light_tree import LightTree, build_light_tree, cone_union
from ercuts_core.sampling import luminance
from tests.vpl_cases import random_vpls as _random_vpls
from tests.vpl_cases import unit as _unit


def random_vpls(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return _random_vpls(n, seed, scale=np.array([4.0, 3.0, 2.0]), shift=0.0)


def coincident_vpls() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """60 sites × 5 exact duplicates (same position and normal), some with zero intensity."""
    pos, nrm, inten = random_vpls(60, 7)
    rng = np.random.default_rng(8)
    inten = np.repeat(inten, 5, axis=0) * rng.random((300, 1))
    inten[::7] = 0.0
    return np.repeat(pos, 5, axis=0), np.repeat(nrm, 5, axis=0), inten


def all_same_vpls() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = 200
    return np.ones((n, 3)), np.tile([0.0, 0.0, 1.0], (n, 1)), np.ones((n, 3))


def subtree_pairs(t: LightTree) -> tuple[np.ndarray, np.ndarray]:
    """(node, vpl) for every VPL of every subtree, found by walking down from the root."""
    nodes_out, leaves_out = [], []
    front_node = np.array([t.root])
    front_top = np.array([t.root])
    while front_node.size:                       # loop over depth only
        leaf = t.is_leaf[front_node]
        nodes_out.append(front_top[leaf])
        leaves_out.append(front_node[leaf])
        inner = front_node[~leaf]
        top = front_top[~leaf]
        front_node = np.concatenate([t.left[inner], t.right[inner]])
        front_top = np.concatenate([top, top])
    return np.concatenate(nodes_out), np.concatenate(leaves_out)


def all_ancestor_pairs(t: LightTree) -> tuple[np.ndarray, np.ndarray]:
    """(ancestor-or-self node, vpl) for all pairs, by walking up the parent links."""
    n = t.n_lights
    anc, vpl = [], []
    cur = t.leaf_node.astype(np.int64)
    ids = np.arange(n)
    while cur.size:                              # loop over depth only
        anc.append(cur)
        vpl.append(ids)
        up = t.parent[cur]
        keep = up >= 0
        cur, ids = up[keep].astype(np.int64), ids[keep]
    return np.concatenate(anc), np.concatenate(vpl)


def check_invariants(t: LightTree, pos: np.ndarray, nrm: np.ndarray, inten: np.ndarray) -> None:
    n = len(pos)
    assert t.n_nodes == 2 * n - 1
    assert t.n_lights == n
    assert np.array_equal(t.leaf_node, np.arange(n))
    assert t.is_leaf[:n].all() and not t.is_leaf[n:].any()
    assert np.all((t.left >= 0) == ~t.is_leaf) and np.all((t.right >= 0) == ~t.is_leaf)
    assert t.parent[t.root] == -1 and np.count_nonzero(t.parent < 0) == 1
    inner = np.flatnonzero(~t.is_leaf)
    assert np.all(t.parent[t.left[inner]] == inner) and np.all(t.parent[t.right[inner]] == inner)
    assert np.all(t.depth[t.left[inner]] == t.depth[inner] + 1)
    # every leaf appears exactly once below the root
    _, leaves = subtree_pairs(t)
    assert np.array_equal(np.sort(leaves), np.arange(n))
    # (ancestor, vpl) pairs: sums, boxes, cones, representatives
    anc, vpl = all_ancestor_pairs(t)
    sums = np.zeros((t.n_nodes, 3))
    np.add.at(sums, anc, inten[vpl])
    np.testing.assert_allclose(t.intensity, sums, rtol=1e-12, atol=1e-12)
    assert np.all(t.bmin[anc] <= pos[vpl]) and np.all(t.bmax[anc] >= pos[vpl])
    lo = np.full((t.n_nodes, 3), np.inf)
    np.minimum.at(lo, anc, pos[vpl])
    np.testing.assert_array_equal(t.bmin, lo)          # boxes are tight
    cosang = np.einsum("ij,ij->i", t.cone_axis[anc], nrm[vpl])
    assert np.all(cosang >= t.cone_cos[anc] - 1e-9)
    np.testing.assert_allclose(np.linalg.norm(t.cone_axis, axis=1), 1.0, atol=1e-9)
    rep_ok = np.zeros(t.n_nodes, bool)
    rep_ok[anc[t.rep[anc] == vpl]] = True
    assert rep_ok.all()
    # depth-first leaf ranges agree with the subtrees
    slot = np.empty(n, np.int64)
    slot[t.leaf_order] = np.arange(n)
    assert np.all(slot[vpl] >= t.leaf_start[anc])
    assert np.all(slot[vpl] < t.leaf_start[anc] + t.leaf_count[anc])
    assert np.all(np.bincount(anc, minlength=t.n_nodes) == t.leaf_count)
    assert t.height == t.depth.max()


def test_empty_tree() -> None:
    t = build_light_tree(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), seed=0)
    assert t.root == -1 and t.n_nodes == 0 and t.height == 0 and t.n_lights == 0


def test_single_vpl() -> None:
    t = build_light_tree([[1.0, 2.0, 3.0]], [[0.0, 0.0, 1.0]], [[1.0, 2.0, 3.0]], seed=0)
    assert t.root == 0 and t.n_nodes == 1 and t.height == 0
    assert t.is_leaf[0] and t.rep[0] == 0 and t.left[0] == -1 and t.parent[0] == -1
    assert t.cone_cos[0] == 1.0 and np.all(t.bmin[0] == t.bmax[0])


@pytest.mark.parametrize("pairing", ["ploc", "greedy"])
@pytest.mark.parametrize("case", ["n2", "n3", "n1000", "coincident", "all_same", "zero"])
def test_invariants(case: str, pairing: str) -> None:
    if case == "coincident":
        pos, nrm, inten = coincident_vpls()
    elif case == "all_same":
        pos, nrm, inten = all_same_vpls()
    elif case == "zero":
        pos, nrm, _ = random_vpls(100, 3)
        inten = np.zeros((100, 3))
    else:
        pos, nrm, inten = random_vpls(int(case[1:]), 1)
    t = build_light_tree(pos, nrm, inten, seed=5, pairing=pairing)
    check_invariants(t, pos, nrm, inten)


@pytest.mark.parametrize("pairing", ["ploc", "greedy"])
def test_height_is_logarithmic(pairing: str) -> None:
    for n in (1000, 20000):
        t = build_light_tree(*random_vpls(n, 2), seed=0, pairing=pairing)
        assert t.height <= 3 * np.log2(n), (n, t.height)
        assert t.height >= np.ceil(np.log2(n))


def test_structure_does_not_depend_on_seed() -> None:
    pos, nrm, inten = random_vpls(500, 4)
    a = build_light_tree(pos, nrm, inten, seed=1)
    b = build_light_tree(pos, nrm, inten, seed=2)
    assert np.array_equal(a.left, b.left) and np.array_equal(a.right, b.right)
    assert not np.array_equal(a.rep, b.rep)


def test_representative_frequencies_follow_intensity() -> None:
    """rep(node) = leaf v with probability Y_v / Y_node (chi² over many seeds)."""
    pos = np.array([[0, 0, 0], [0.1, 0, 0], [1, 0, 0], [1.1, 0, 0], [0.5, 2, 0]], float)
    nrm = np.tile([0.0, 0.0, 1.0], (5, 1))
    inten = np.array([1.0, 2.0, 3.0, 4.0, 5.0])[:, None] * [1.0, 0.5, 0.25]
    trees = [build_light_tree(pos, nrm, inten, seed=s) for s in range(1200)]
    reps = np.array([t.rep for t in trees])              # (seeds, nodes)
    t0 = trees[0]
    y = luminance(inten)
    for node in np.flatnonzero(~t0.is_leaf):
        members = t0.leaf_order[t0.leaf_start[node]:t0.leaf_start[node] + t0.leaf_count[node]]
        counts = np.array([(reps[:, node] == v).sum() for v in members])
        assert counts.sum() == len(trees)
        expected = y[members] / y[members].sum() * len(trees)
        assert chisquare(counts, expected).pvalue > 1e-4, (node, counts, expected)


def test_zero_intensity_pair_picks_fifty_fifty() -> None:
    pos = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    nrm = np.tile([0.0, 0.0, 1.0], (2, 1))
    reps = [build_light_tree(pos, nrm, np.zeros((2, 3)), seed=s).rep[2] for s in range(600)]
    assert binomtest(int(np.sum(np.array(reps) == 0)), 600, 0.5).pvalue > 1e-4


def test_representative_never_zero_when_sibling_lit() -> None:
    pos = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    nrm = np.tile([0.0, 0.0, 1.0], (2, 1))
    inten = np.array([[0.0, 0, 0], [1.0, 1, 1]])
    assert all(build_light_tree(pos, nrm, inten, seed=s).rep[2] == 1 for s in range(200))


@pytest.mark.parametrize("pairing", ["ploc"])
@pytest.mark.parametrize("seed", range(6))
def test_pairing_separates_far_clusters(seed: int, pairing: str) -> None:
    rng = np.random.default_rng(seed)
    na, nb = (int(v) for v in rng.integers(5, 80, 2))
    pos = np.concatenate([rng.normal(size=(na, 3)) * 0.05,
                          rng.normal(size=(nb, 3)) * 0.05 + [10.0, 0, 0]])
    nrm = _unit(rng.normal(size=(na + nb, 3)))
    t = build_light_tree(pos, nrm, rng.random((na + nb, 3)), seed=0, pairing=pairing)
    for child in (t.left[t.root], t.right[t.root]):
        members = t.leaf_order[t.leaf_start[child]:t.leaf_start[child] + t.leaf_count[child]]
        assert np.all(members < na) or np.all(members >= na)


def test_pairing_prefers_similar_normals_and_dim_lights() -> None:
    """The (2 − n_i·n_j) and (Y_i + Y_j) factors of the Ercuts weight beat pure distance."""
    up, down = [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]
    # square: 0–1 close but opposite normals (w = 2·3·1), 0–2 farther, same normal (2·1·1.2)
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1.2, 0], [1, 1.2, 0]], float)
    t = build_light_tree(pos, np.array([up, down, up, down]), np.ones((4, 3)), seed=0)
    pairs = {tuple(sorted((int(t.left[c]), int(t.right[c])))) for c in (4, 5)}
    assert pairs == {(0, 2), (1, 3)}
    # line: a bright VPL in the middle; the two dim ones pair first (w = 2·2.2 < 101·1)
    pos = np.array([[0, 0, 0], [1, 0, 0], [2.2, 0, 0]], float)
    inten = np.array([1.0, 100.0, 1.0])[:, None] * np.ones(3)
    t = build_light_tree(pos, np.tile(up, (3, 1)), inten, seed=0)
    assert {int(t.left[3]), int(t.right[3])} == {0, 2}


def test_cone_union_contains_both_cones() -> None:
    rng = np.random.default_rng(11)
    k = 4000
    a, b = _unit(rng.normal(size=(k, 3))), _unit(rng.normal(size=(k, 3)))
    ca, cb = rng.uniform(-0.2, 1.0, k), rng.uniform(-0.2, 1.0, k)
    ca[:500] = 1.0                                      # point cones
    axis, cos = cone_union(a, ca, b, cb)
    # sample directions on the rim of each input cone: they must lie in the union
    for ax, c in ((a, ca), (b, cb)):
        t1 = _unit(np.cross(ax, rng.normal(size=(k, 3))))
        t2 = np.cross(ax, t1)
        phi = rng.uniform(0, 2 * np.pi, (k, 1))
        s = np.sqrt(1 - c**2)[:, None]
        d = c[:, None] * ax + s * (np.cos(phi) * t1 + np.sin(phi) * t2)
        assert np.all(np.einsum("ij,ij->i", axis, d) >= cos - 1e-9)
    # and it is not trivially the whole sphere
    assert np.mean(cos > -1.0) > 0.5


def test_keep_going_is_polled_and_can_stop_the_build() -> None:
    """The build polls keep_going between K-NN chunks and levels (fractions rising in
    [0, 1]); a False stops it (None); always True builds the same tree as no callback."""
    from ercuts_core.integrators.ercuts import light_tree

    rng = np.random.default_rng(4)
    n = 3 * light_tree._KNN_CHUNK // 2
    pos, nrm = rng.random((n, 3)), np.tile([0.0, 0.0, 1.0], (n, 1))
    inten = rng.random((n, 3))
    seen = []
    tree = build_light_tree(pos, nrm, inten, seed=1, keep_going=lambda f: seen.append(f) or True)
    plain = build_light_tree(pos, nrm, inten, seed=1)
    for name in ("left", "right", "rep", "intensity", "bmin", "bmax"):
        np.testing.assert_array_equal(getattr(tree, name), getattr(plain, name))
    assert seen[:2] == [0.0, 0.0]                        # two query chunks in the first level
    assert len(seen) >= 2 * tree.height and seen == sorted(seen) and 0 <= seen[-1] <= 1
    calls = []
    assert build_light_tree(pos, nrm, inten, keep_going=lambda f: calls.append(f) or len(calls) < 2) is None
    assert len(calls) == 2                               # stopped inside the first level
