"""Binary light tree over oriented VPLs (Ercuts step 4).

Zhu, Xu, Pan 2010, §3.4: VPLs are paired by the weight

    w(i, j) = (Y_i + Y_j) · (2 − n_i·n_j) · |p_i − p_j|

(the smaller, the more similar), pairs become the next level of the tree, and the
representative of an internal node is one of its children's representatives, chosen
with probability Y_i / (Y_i + Y_j) (Walter et al. 2005, "Lightcuts", §4).

Construction (shared docs algorithm.md §E.3, §G.5) is level by level, in the spirit of
the *locally-ordered* clustering of Walter, Bala, Kulkarni, Pingali 2008 run in parallel
(PLOC): at each level every active cluster gets its K nearest spatial neighbours
(``scipy.spatial.cKDTree``), the symmetric candidate edges are ranked by the Ercuts
weight, and *mutual-best* rounds pick disjoint pairs.  Run to exhaustion, mutual-best
rounds give exactly the paper's greedy "cheapest pair first" matching on the candidate
graph (``pairing='greedy'``).  The default ``pairing='ploc'`` stops once half of the
clusters are paired and carries the rest up unchanged: a cluster whose best partner
was taken waits for a better partner one level up instead of pairing with a far-away
leftover.  Each level costs O(m log m) and shrinks the active set by ≥ 25 %, so the
build is O(N log N), with a Python loop over levels only.

Leaves are VPLs: oriented cosine emitters, the intensity toward ω is I·max(0, n·ω).
Node ids: leaves are ``0 … N−1`` (``leaf_node[v] == v``), internal nodes follow in
creation order, so a parent always has a larger id than its children.  Every internal
node has exactly two children, so ``n_nodes == 2N − 1`` (N ≥ 1).

Per node the tree stores what the Lightcuts bounds need (algorithm.md §E.2): the RGB
intensity sum, the axis-aligned bounding box of its VPL positions, and a normal cone
(axis, cos half-angle) that contains all its VPL normals, merged like pbrt-v4's
``DirectionCone::Union``.  Units: positions in scene units (m), intensity in W/sr
(RGB), luminance Y = 0.2126 R + 0.7152 G + 0.0722 B.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from ...sampling import LUMINANCE_WEIGHTS
from ...vecmath import normalize

#: Relative luminance added in the pairing weight so that Y = 0 pairs rank by distance.
_Y_EPS = 1e-9
#: Cluster count from which the K-nearest-neighbour queries use all cores.
_PARALLEL_KNN = 1 << 15
#: Angular padding (radians) added to freshly merged cones against round-off.
_CONE_PAD = 1e-7
#: Points per K-nearest-neighbour query chunk; ``keep_going`` is polled between chunks
#: (tens of ms each), so a cancel inside the first, largest level is noticed promptly.
_KNN_CHUNK = 1 << 16


class _Stopped(Exception):
    """``keep_going`` returned False during the build."""


def _poll(keep_going, fraction: float) -> None:
    if keep_going is not None and keep_going(fraction) is False:
        raise _Stopped


def luminance(rgb: NDArray) -> NDArray:
    """Y of (..., 3) linear Rec.709 RGB as the light tree and lightcuts round it: the matrix
    product with :data:`~ercuts_core.sampling.LUMINANCE_WEIGHTS`.

    :func:`ercuts_core.sampling.luminance` sums the same products in another order; the
    last-bit differences flip a few tree pairings (measured with
    ``benchmarks/same_image.py``: S-corridor pixels up to 10 % apart at the same seed), so
    the tree keeps this form until an intended image change merges the two.
    """
    return np.asarray(rgb, dtype=np.float64) @ LUMINANCE_WEIGHTS


@dataclass
class LightTree:
    """Flat (struct-of-arrays) binary light tree; ``n`` = ``n_nodes`` = 2N − 1.

    Attributes:
        left, right: (n,) int32 child node ids, −1 for leaves.
        parent: (n,) int32 parent node id, −1 for the root.
        rep: (n,) int32 representative VPL index (a leaf of the node's subtree).
        intensity: (n, 3) float64 RGB intensity sum of the subtree [W/sr].
        bmin, bmax: (n, 3) float64 bounding box of the subtree's VPL positions.
        cone_axis: (n, 3) float64 unit axis of the normal cone.
        cone_cos: (n,) float64 cosine of the cone half-angle (−1 = whole sphere).
        centroid: (n, 3) float64 luminance-weighted centroid (pairing position).
        is_leaf: (n,) bool.
        root: root node id, −1 for an empty tree.
        leaf_node: (N,) int32 node id of VPL v (identity: leaves come first).
        depth: (n,) int32 number of edges from the root.
        level: (n,) int32 build level that created the node (0 for leaves).
        leaf_count: (n,) int32 number of VPLs in the subtree.
        leaf_start: (n,) int32 first slot of the subtree in ``leaf_order``.
        leaf_order: (N,) int32 VPL indices in depth-first order; the subtree of node c
            is ``leaf_order[leaf_start[c] : leaf_start[c] + leaf_count[c]]``.
    """

    left: NDArray
    right: NDArray
    parent: NDArray
    rep: NDArray
    intensity: NDArray
    bmin: NDArray
    bmax: NDArray
    cone_axis: NDArray
    cone_cos: NDArray
    centroid: NDArray
    is_leaf: NDArray
    root: int
    leaf_node: NDArray
    depth: NDArray
    level: NDArray
    leaf_count: NDArray
    leaf_start: NDArray
    leaf_order: NDArray

    @property
    def n_nodes(self) -> int:
        """Number of nodes (2N − 1, or 0)."""
        return int(self.left.shape[0])

    @property
    def n_lights(self) -> int:
        """Number of VPLs N."""
        return int(self.leaf_node.shape[0])

    @property
    def height(self) -> int:
        """Largest leaf depth (edges root → leaf); 0 for N ≤ 1."""
        return int(self.depth.max()) if self.depth.size else 0


# ----------------------------------------------------------------------------- cones


def _angle_between(a: NDArray, b: NDArray) -> NDArray:
    """Angle (K,) between unit vectors a, b (K,3), accurate near 0 and π."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.einsum("ij,ij->i", a, b))


def cone_union(axis_a: NDArray, cos_a: NDArray, axis_b: NDArray, cos_b: NDArray,
               weight_a: NDArray | None = None, weight_b: NDArray | None = None
               ) -> tuple[NDArray, NDArray]:
    """Smallest cone (axis (K,3), cos (K,)) containing cones a and b (pbrt-v4 Union).

    Whole-sphere results get cos = −1 and, as axis, the normalized ``weight``-weighted
    mean of the two axes (used only for the pairing weight).
    """
    th_a = np.arccos(np.clip(cos_a, -1.0, 1.0))
    th_b = np.arccos(np.clip(cos_b, -1.0, 1.0))
    th_d = _angle_between(axis_a, axis_b)
    keep_a = np.minimum(th_d + th_b, np.pi) <= th_a
    keep_b = ~keep_a & (np.minimum(th_d + th_a, np.pi) <= th_b)
    th_o = 0.5 * (th_a + th_d + th_b) + _CONE_PAD
    perp = axis_b - axis_a * np.cos(th_d)[:, None]
    perp_len = np.linalg.norm(perp, axis=1)
    sphere = ~keep_a & ~keep_b & ((th_o >= np.pi) | (perp_len < 1e-12))
    general = ~keep_a & ~keep_b & ~sphere
    th_r = (th_o - th_a)[:, None]
    perp = perp / np.where(perp_len > 0, perp_len, 1.0)[:, None]
    axis = np.where(general[:, None], axis_a * np.cos(th_r) + perp * np.sin(th_r), axis_a)
    axis = np.where(keep_b[:, None], axis_b, axis)
    cos = np.where(general, np.cos(np.minimum(th_o, np.pi)), cos_a)
    cos = np.where(keep_b, cos_b, cos)
    cos = np.where(sphere, -1.0, cos)
    if np.any(sphere):
        wa = np.ones(len(cos)) if weight_a is None else weight_a + 1e-30
        wb = np.ones(len(cos)) if weight_b is None else weight_b + 1e-30
        mean = wa[:, None] * axis_a + wb[:, None] * axis_b
        ln = np.linalg.norm(mean, axis=1)
        mean = np.where(ln[:, None] > 1e-12, mean / np.maximum(ln, 1e-300)[:, None], axis_a)
        axis = np.where(sphere[:, None], mean, axis)
    return normalize(axis)[0], cos


# -------------------------------------------------------------------------- matching


def ercuts_weight(p_i: NDArray, n_i: NDArray, y_i: NDArray,
                  p_j: NDArray, n_j: NDArray, y_j: NDArray) -> NDArray:
    """Ercuts pairing weight (Y_i + Y_j)(2 − n_i·n_j)|p_i − p_j| for pairs (K,)."""
    dist = np.linalg.norm(p_i - p_j, axis=1)
    return (y_i + y_j) * (2.0 - np.einsum("ij,ij->i", n_i, n_j)) * dist


def _candidate_edges(pos: NDArray, k: int, keep_going=None,
                     fraction: float = 0.0) -> tuple[NDArray, NDArray]:
    """Symmetric, deduplicated K-nearest-neighbour edges (lo < hi) over (m,3) points
    (queried in chunks of :data:`_KNN_CHUNK`, polling ``keep_going(fraction)`` between)."""
    m = len(pos)
    kq = min(k + 1, m)
    workers = -1 if m >= _PARALLEL_KNN else 1
    kd = cKDTree(pos)
    nb = np.empty((m, kq), np.int64)
    for start in range(0, m, _KNN_CHUNK):
        _poll(keep_going, fraction)
        _, found = kd.query(pos[start:start + _KNN_CHUNK], k=kq, workers=workers)
        nb[start:start + _KNN_CHUNK] = np.asarray(found).reshape(-1, kq)
    src = np.repeat(np.arange(m), kq)
    dst = nb.ravel()
    ok = (dst != src) & (dst < m)
    lo = np.minimum(src[ok], dst[ok]).astype(np.int64)
    hi = np.maximum(src[ok], dst[ok]).astype(np.int64)
    key = np.unique(lo * m + hi)
    return key // m, key % m


def greedy_matching(n_nodes: int, lo: NDArray, hi: NDArray, weight: NDArray,
                    max_rounds: int = 64, min_pairs: float = np.inf
                    ) -> tuple[NDArray, NDArray]:
    """Disjoint pairs by repeated mutual-best rounds on a candidate graph.

    Edges are ranked by weight, ties in a fixed pseudo-random order (a strict total
    order; index-ordered ties would make mutual-best chains on regular grids resolve
    one pair per round).
    Each round matches every edge that is the best alive edge of both its endpoints,
    then drops the edges touching matched nodes.  One round is a PLOC round (mutual
    nearest neighbours); run to exhaustion it equals the sequential greedy "cheapest
    pair first" matching of Ercuts §3.4 on this graph.

    Args:
        n_nodes: number of nodes m; lo, hi: (E,) edge endpoints; weight: (E,).
        max_rounds: cap on the number of rounds.
        min_pairs: stop after the first round that brings the pair count to this.

    Returns:
        (a, b): (M,) node indices of the matched pairs.
    """
    shuffle = np.random.default_rng(len(lo)).permutation(len(lo))
    order = shuffle[np.argsort(weight[shuffle], kind="stable")]
    lo, hi = lo[order], hi[order]
    rank = np.arange(len(lo))
    matched = np.zeros(n_nodes, dtype=bool)
    out_a, out_b = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    n_pairs = 0
    for _ in range(max_rounds):
        if len(lo) == 0 or n_pairs >= min_pairs:
            break
        best = np.full(n_nodes, len(order), dtype=np.int64)
        np.minimum.at(best, lo, rank)
        np.minimum.at(best, hi, rank)
        mutual = (best[lo] == rank) & (best[hi] == rank)
        n_pairs += int(mutual.sum())
        out_a.append(lo[mutual])
        out_b.append(hi[mutual])
        matched[lo[mutual]] = True
        matched[hi[mutual]] = True
        alive = ~matched[lo] & ~matched[hi]
        lo, hi, rank = lo[alive], hi[alive], rank[alive]
    return np.concatenate(out_a), np.concatenate(out_b)


def _morton_pairs(pos: NDArray) -> tuple[NDArray, NDArray]:
    """Pair consecutive points (m,3) along a 3-D Morton curve (progress fallback)."""
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    q = ((pos - lo) / np.where(hi > lo, hi - lo, 1.0) * 1023).astype(np.uint64)
    code = np.zeros(len(pos), np.uint64)
    for bit in range(10):
        for ax in range(3):
            code |= ((q[:, ax] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + ax)
    order = np.argsort(code, kind="stable")
    half = len(order) // 2
    return order[0:2 * half:2], order[1:2 * half:2]


def _match_level(pos: NDArray, axis: NDArray, lum: NDArray, k: int, max_rounds: int,
                 min_pairs: float, keep_going=None, fraction: float = 0.0) -> tuple[NDArray, NDArray]:
    """Pairs (a, b) of active clusters for one tree level (local indices).

    If fewer than 1/4 of the clusters got paired (adversarial inputs: long chains of
    decreasing weights, or many coincident VPLs whose K nearest neighbours coincide),
    the unpaired ones are also paired along a Morton curve, so every level shrinks
    the active set by a constant factor.
    """
    lo, hi = _candidate_edges(pos, k, keep_going, fraction)
    lum = lum + _Y_EPS * max(float(lum.max()), 1e-300)      # Y = 0 pairs: by distance
    w = ercuts_weight(pos[lo], axis[lo], lum[lo], pos[hi], axis[hi], lum[hi])
    a, b = greedy_matching(len(pos), lo, hi, w, max_rounds, min_pairs)
    if 8 * len(a) < len(pos):
        rest = np.setdiff1d(np.arange(len(pos)), np.concatenate([a, b]))
        ra, rb = _morton_pairs(pos[rest])
        a, b = np.concatenate([a, rest[ra]]), np.concatenate([b, rest[rb]])
    return a, b


# ----------------------------------------------------------------------------- build


class _Builder:
    """Mutable flat arrays while building; see :func:`build_light_tree`."""

    def __init__(self, pos: NDArray, nrm: NDArray, inten: NDArray) -> None:
        n = len(pos)
        total = max(2 * n - 1, 0)
        self.left = np.full(total, -1, np.int32)
        self.right = np.full(total, -1, np.int32)
        self.parent = np.full(total, -1, np.int32)
        self.rep = np.full(total, -1, np.int32)
        self.level = np.zeros(total, np.int32)
        self.inten = np.zeros((total, 3))
        self.bmin = np.zeros((total, 3))
        self.bmax = np.zeros((total, 3))
        self.axis = np.zeros((total, 3))
        self.cos = np.ones(total)
        self.cen = np.zeros((total, 3))
        self.lum = np.zeros(total)
        self.rep[:n] = np.arange(n)
        self.inten[:n], self.bmin[:n], self.bmax[:n] = inten, pos, pos
        self.axis[:n], self.cen[:n], self.lum[:n] = nrm, pos, luminance(inten)
        self.next_id = n

    def merge(self, a: NDArray, b: NDArray, lvl: int, rng: np.random.Generator) -> NDArray:
        """Create parents of node pairs (a, b) (M,); returns their ids (M,)."""
        ids = np.arange(self.next_id, self.next_id + len(a))
        self.next_id += len(a)
        self.left[ids], self.right[ids], self.level[ids] = a, b, lvl
        self.parent[a] = ids
        self.parent[b] = ids
        self.inten[ids] = self.inten[a] + self.inten[b]
        self.bmin[ids] = np.minimum(self.bmin[a], self.bmin[b])
        self.bmax[ids] = np.maximum(self.bmax[a], self.bmax[b])
        ya, yb = self.lum[a], self.lum[b]
        ysum = ya + yb
        self.lum[ids] = ysum
        frac = np.where(ysum > 0, ya / np.where(ysum > 0, ysum, 1.0), 0.5)
        mid = 0.5 * (self.cen[a] + self.cen[b])
        wcen = frac[:, None] * self.cen[a] + (1.0 - frac)[:, None] * self.cen[b]
        self.cen[ids] = np.where((ysum > 0)[:, None], wcen, mid)
        self.axis[ids], self.cos[ids] = cone_union(self.axis[a], self.cos[a], self.axis[b],
                                                   self.cos[b], ya, yb)
        pick_a = rng.random(len(a)) < frac
        self.rep[ids] = np.where(pick_a, self.rep[a], self.rep[b])
        return ids


def _finish(bd: _Builder, n: int, root: int) -> LightTree:
    """Derive depth and leaf ranges (loops over levels only) and pack the tree."""
    total = bd.next_id
    depth = np.zeros(total, np.int32)
    count = np.zeros(total, np.int32)
    start = np.zeros(total, np.int32)
    count[:n] = 1
    levels = bd.level[:total]
    top = int(levels.max()) if total else 0
    for lvl in range(1, top + 1):                      # bottom-up: leaf counts
        ids = np.flatnonzero(levels == lvl)
        count[ids] = count[bd.left[ids]] + count[bd.right[ids]]
    for lvl in range(top, 0, -1):                      # top-down: depth and ranges
        ids = np.flatnonzero(levels == lvl)
        for child, off in ((bd.left[ids], 0), (bd.right[ids], count[bd.left[ids]])):
            depth[child] = depth[ids] + 1
            start[child] = start[ids] + off
    order = np.zeros(n, np.int32)
    order[start[:n]] = np.arange(n, dtype=np.int32)
    return LightTree(
        left=bd.left, right=bd.right, parent=bd.parent, rep=bd.rep, intensity=bd.inten,
        bmin=bd.bmin, bmax=bd.bmax, cone_axis=bd.axis, cone_cos=bd.cos, centroid=bd.cen,
        is_leaf=bd.left < 0, root=root, leaf_node=np.arange(n, dtype=np.int32),
        depth=depth, level=bd.level, leaf_count=count, leaf_start=start, leaf_order=order)


def build_light_tree(position: NDArray, normal: NDArray, intensity: NDArray, seed: int = 0,
                     *, k_neighbors: int = 8, pairing: str = "ploc",
                     max_match_rounds: int = 64, keep_going=None) -> LightTree | None:
    """Build the Ercuts light tree over N oriented VPLs.

    Args:
        position: (N, 3) VPL positions.
        normal: (N, 3) unit VPL normals (emission I·max(0, n·ω)).
        intensity: (N, 3) RGB intensities ≥ 0 [W/sr].
        seed: seed of the representative draws (the tree *structure* is deterministic).
        k_neighbors: K of the K-nearest-neighbour pairing candidates per level.
        pairing: ``'ploc'``: mutual-best rounds per level only until half of the
            clusters are paired (one or a few rounds), the rest carry up (parallel
            locally-ordered clustering, Walter 2008).  ``'greedy'``: mutual-best rounds
            until no candidate edge is left (the paper's "cheapest pair first" until all
            are paired); leftovers without an unpaired candidate carry up.
        max_match_rounds: cap on mutual-best rounds per level.
        keep_going: optional ``keep_going(fraction) -> bool | None``, polled between
            neighbour-query chunks and levels (``fraction`` ≈ share of the clusters
            merged so far); False stops the build.

    Returns:
        The :class:`LightTree` (empty, root −1, for N = 0), or None when ``keep_going``
        stopped the build.
    """
    if pairing not in ("ploc", "greedy"):
        raise ValueError(f"pairing must be 'ploc' or 'greedy', not {pairing!r}")
    pos = np.asarray(position, np.float64).reshape(-1, 3)
    nrm = np.asarray(normal, np.float64).reshape(-1, 3)
    inten = np.asarray(intensity, np.float64).reshape(-1, 3)
    n = len(pos)
    bd = _Builder(pos, nrm, inten)
    rng = np.random.default_rng(seed)
    active = np.arange(n)
    lvl = 0
    try:
        while len(active) > 1:
            lvl += 1
            min_pairs = len(active) / 4 if pairing == "ploc" else np.inf
            a, b = _match_level(bd.cen[active], bd.axis[active], bd.lum[active],
                                k_neighbors, max_match_rounds, min_pairs,
                                keep_going, 1.0 - len(active) / n)
            parents = bd.merge(active[a], active[b], lvl, rng)
            unmatched = np.ones(len(active), dtype=bool)
            unmatched[a] = False
            unmatched[b] = False
            active = np.concatenate([parents, active[unmatched]])
            _poll(keep_going, 1.0 - len(active) / n)
    except _Stopped:
        return None
    root = int(active[0]) if n else -1
    return _finish(bd, n, root)
