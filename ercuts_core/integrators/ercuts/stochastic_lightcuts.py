"""Stochastic lightcuts: a cut of bounded size whose nodes are each evaluated with one VPL
drawn per shading point (Ercuts step 5 at production resolutions, issue 17).

Yuksel 2019 ("Stochastic Lightcuts", HPG 2019) replaces each cut node's fixed
representative by a light sampled for the shading point, which turns lightcuts' structured
error (every point under a cluster sees the same representative: streaks and blotches) into
noise that averages out, and makes the estimate unbiased for the given VPLs.  Here:

1. **Cut** (no shadow rays): from the root, every point splits its cut nodes with the largest
   error bounds L̄_C (:func:`.lightcuts.cluster_bound`, Walter et al. 2005) until the cut has
   ``cut_size`` nodes or no node has a positive bound.  A node whose bound is 0 receives no
   light at the point (the bound is conservative) and is dropped; leaves are exact.
2. **Sample**: in every non-leaf node C one VPL v of its subtree is drawn with probability
   p_v = Y(I_v)/Y(I_C) (Walter et al. 2005 §4.1 choose representatives ∝ intensity; here a
   fresh one per point and node, from the cumulative luminance over ``tree.leaf_order``: one
   ``searchsorted``), so

       L̂ = Σ_{C ∈ cut} M_v G_v V_v I_v / p_v,   E[L̂] = Σ_C Σ_{v ∈ C} M_v G_v V_v I_v = L,

   one shadow ray per cut node.  The cut depends only on the bounds, not on the samples, so
   the estimate is unbiased given the VPLs (up to the optional G clamp, which applies as in
   :func:`.lightcuts.lightcut`).

No per-point error bound holds: the error is noise with zero mean, which the progressive
iterations average away (each iteration draws new VPLs, a new tree and new samples).  The
cost per point is ``cut_size`` bound pairs and shadow rays, independent of the VPL count.

Units as in :mod:`.lightcuts`: intensities W/sr (RGB), radiance W·sr⁻¹·m⁻².
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ... import kernels
from ...arrays import take_rows
from ...kernels import refine
from ...sampling import LUMINANCE_WEIGHTS
from .cut_rounds import run_rounds
from .light_tree import LightTree, luminance
from .lightcuts import (LightcutResult, ShadingPoints, _Entries, _select, cluster_bound,
                        evaluate_lights)

#: Per-round selection band of the cut refinement (as in :mod:`.lightcuts`).
_BAND = 0.25


def stochastic_cut(tree: LightTree, pts: ShadingPoints, cut_size: int,
                   clamp: float = 0.0, keep_empty: bool = False) -> tuple[NDArray, NDArray]:
    """The cut of every point (step 1 of the module docstring): (C,) point indices and (C,)
    node ids, sorted by point, at most ``cut_size`` per point; nodes with a zero bound that
    are not leaves are dropped (they carry no light to the point), or with ``keep_empty``
    kept outside the ``cut_size`` budget (the same refined nodes, plus those: a partition of
    all VPLs, for other points to share, which may see light from them).  Lock-step rounds
    over flat arrays, no shadow rays."""
    n_pts = pts.count
    pidx = np.arange(n_pts)
    root = np.full(n_pts, tree.root, np.int64)
    e = _bare(tree, pts, pidx, root, clamp)
    if kernels.enabled():
        return _stochastic_cut_compiled(tree, pts, e, cut_size, clamp, keep_empty)
    final: list[_Entries] = []
    count = np.ones(n_pts, np.int64)          # cut entries per point (live + final)
    while e.pt.size:
        leaf = take_rows(tree.is_leaf, e.node)
        done = leaf | (e.bound <= 0.0)
        if np.any(done):
            final.append(e.take(np.flatnonzero(done if keep_empty else leaf)))
            count -= np.bincount(e.pt[done & ~leaf], minlength=n_pts)
            e = e.take(np.flatnonzero(~done))
        sel = _select(e, e.bound, np.zeros(e.pt.size), cut_size - count, _BAND)
        if sel.size == 0:
            break
        node, pt = take_rows(e.node, sel), take_rows(e.pt, sel)
        kids = _bare(tree, pts, np.concatenate([pt, pt]),
                     np.concatenate([take_rows(tree.left, node), take_rows(tree.right, node)]),
                     clamp)
        count += np.bincount(pt, minlength=n_pts)
        keep = np.ones(e.pt.size, bool)
        keep[sel] = False
        e = _Entries.cat([e.take(np.flatnonzero(keep)), kids])
    cut = _Entries.cat(final + [e])
    order = np.argsort(cut.pt, kind="stable")
    return cut.pt[order], cut.node[order]


def _stochastic_cut_compiled(tree: LightTree, pts: ShadingPoints, root: _Entries, cut_size: int,
                             clamp: float, keep_empty: bool) -> tuple[NDArray, NDArray]:
    """:func:`stochastic_cut` on the compiled kernels (:func:`.cut_rounds.run_rounds`, the
    same rounds and cut entries in the same order)."""
    def children(pt, node, unit, loss):
        kids = _bare(tree, pts, np.concatenate([pt, pt]),
                     np.concatenate([take_rows(tree.left, node), take_rows(tree.right, node)]), clamp)
        return kids.node, kids.unit, kids.loss, kids.bound, 0

    z = np.zeros((pts.count, 3))
    r = run_rounds(tree, pts.count, z, z, root.bound, children, mode=refine.MODE_STOCHASTIC,
                   max_cut_size=cut_size, band=_BAND, keep_empty=keep_empty)
    return r.pt, r.node


def shared_cut(tree: LightTree, pts: ShadingPoints, ref: NDArray, cut_size: int,
               clamp: float = 0.0) -> tuple[NDArray, NDArray]:
    """Cuts shared between points (``stochastic_cut_sharing``): point i uses the cut refined
    at point ``ref[i]`` (``ref[ref[i]] == ref[i]``), with its empty clusters kept, so it
    covers every VPL and each point's estimate stays unbiased; only the cut's *choice* (the
    bounds, hence the noise) is the reference point's.  Returns (C,) points, (C,) nodes
    sorted by point, like :func:`stochastic_cut`."""
    refs, local = np.unique(ref, return_inverse=True)
    rpt, rnode = stochastic_cut(tree, _subset(pts, refs), cut_size, clamp, keep_empty=True)
    count = np.bincount(rpt, minlength=len(refs))
    first = np.cumsum(count) - count
    c = count[local]
    pt = np.repeat(np.arange(pts.count), c)
    offset = np.arange(pt.size) - np.repeat(np.cumsum(c) - c, c)
    return pt, rnode[np.repeat(first[local], c) + offset]


def _subset(pts: ShadingPoints, idx: NDArray) -> ShadingPoints:
    """The points ``idx`` of ``pts`` for the bounds (the callbacks are not used by the cut)."""
    glossy = None if pts.glossy is None else pts.glossy.subset(idx)
    tr = None if pts.transmissive is None else np.asarray(pts.transmissive)[idx]
    return ShadingPoints(pts.p[idx], pts.n[idx], pts.wo[idx], pts.f_bound[idx], pts.eval_f,
                         pts.visible, transmissive=tr, glossy=glossy)


def _bare(tree: LightTree, pts: ShadingPoints, pt: NDArray, node: NDArray,
          clamp: float) -> _Entries:
    """Cut entries (pt, node) with their bounds and no evaluation."""
    z = np.zeros((pt.size, 3))
    node = np.asarray(node, np.int64)
    return _Entries(pt, node, z, z, cluster_bound(tree, node, pts, pt, clamp))


def leaf_cdf(tree: LightTree) -> NDArray:
    """(N + 1,) cumulative luminance of the VPL intensities in ``tree.leaf_order`` (the
    subtree of node c is the slot range [leaf_start[c], leaf_start[c] + leaf_count[c]))."""
    y = luminance(tree.intensity[tree.leaf_node[tree.leaf_order]])
    return np.concatenate([[0.0], np.cumsum(y)])


def sample_leaves(tree: LightTree, cdf: NDArray, node: NDArray, u: NDArray
                  ) -> tuple[NDArray, NDArray]:
    """One VPL per node, drawn ∝ luminance within the node's subtree (step 2).

    Args:
        cdf: :func:`leaf_cdf` of ``tree``.
        node: (K,) node ids; u: (K,) uniforms in [0, 1).

    Returns:
        vpl: (K,) VPL indices; weight: (K,) 1/p_v = Y(I_C)/Y(I_v) (0 where Y(I_C) = 0).
    """
    lo = take_rows(tree.leaf_start, node).astype(np.int64)
    hi = lo + take_rows(tree.leaf_count, node)
    a, b = cdf[lo], cdf[hi]
    slot = np.searchsorted(cdf, a + u * (b - a), side="right") - 1
    slot = np.clip(slot, lo, hi - 1)
    vpl = tree.leaf_order[slot]
    y = cdf[slot + 1] - cdf[slot]
    weight = np.divide(b - a, y, out=np.zeros_like(y), where=y > 0.0)
    return vpl, weight


def stochastic_lightcut(tree: LightTree, vpl_pos: NDArray, vpl_normal: NDArray,
                        vpl_intensity: NDArray, pts: ShadingPoints, rng: np.random.Generator,
                        *, cut_size: int = 32, clamp: float = 0.0,
                        cdf: NDArray | None = None, ref: NDArray | None = None) -> LightcutResult:
    """Stochastic-lightcut radiance at P shading points (module docstring).

    Args:
        tree, vpl_pos, vpl_normal, vpl_intensity, pts, clamp: as :func:`.lightcuts.lightcut`.
        rng: the generator of the VPL draws (deterministic per seed).
        cut_size: nodes per point at most (≥ 1).
        cdf: :func:`leaf_cdf` of ``tree`` when the caller keeps it (computed otherwise; it
            cost 6 % of the gather at 1280×720 when recomputed per batch).
        ref: optional (P,) reference point of each point's cut (:func:`shared_cut`).

    Returns:
        :class:`~.lightcuts.LightcutResult` with the cut entries (``cut_node`` is the
        *sampled leaf's* node, so per-VPL attributes such as the emitter share apply;
        ``cut_estimate`` its RGB contribution M·G·V·I_v/p_v); ``cut_size`` the nodes per
        point; ``unmet`` all False (there is no bound to meet).
    """
    if cut_size < 1:
        raise ValueError(f"cut_size must be >= 1, got {cut_size}")
    pos = np.asarray(vpl_pos, np.float64).reshape(-1, 3)
    nrm = np.asarray(vpl_normal, np.float64).reshape(-1, 3)
    inten = np.asarray(vpl_intensity, np.float64).reshape(-1, 3)
    n_pts = pts.count
    if n_pts == 0 or tree.root < 0:
        z = np.zeros(0, np.int64)
        return LightcutResult(np.zeros((n_pts, 3)), np.zeros(n_pts, np.int64), 0.0, 0, 0,
                              z, z, np.zeros((0, 3)), np.zeros(0), np.zeros(n_pts, bool))
    pt, node = (stochastic_cut(tree, pts, cut_size, clamp) if ref is None
                else shared_cut(tree, pts, ref, cut_size, clamp))
    vpl, weight = sample_leaves(tree, leaf_cdf(tree) if cdf is None else cdf, node,
                                rng.random(pt.size))
    unit, loss, rays = evaluate_lights(pts, pt, vpl, pos, nrm, clamp)
    scale = take_rows(inten, vpl) * weight[:, None]
    est = unit * scale
    rad = np.stack([np.bincount(pt, est[:, c], n_pts) for c in range(3)], axis=1)
    clamped = _clamped_energy(loss * scale) if clamp > 0.0 else 0.0   # loss = 0 unclamped
    return LightcutResult(rad, np.bincount(pt, minlength=n_pts), clamped,
                          rays, 0, pt, take_rows(tree.leaf_node, vpl), est, np.zeros(pt.size),
                          np.zeros(n_pts, bool))


def _clamped_energy(loss: NDArray) -> float:
    """Σ Y of (K,3) clamp losses (a statistic).  The compiled path sums Y by columns: the
    tree's BLAS matmul took 21 ms per 5·10⁴ rows on the loaded machine (14 % of a shared
    stochastic gather); the numpy path keeps its bits."""
    if not kernels.enabled():
        return float(luminance(loss).sum())
    w = LUMINANCE_WEIGHTS
    return float((loss[:, 0] * w[0] + loss[:, 1] * w[1] + loss[:, 2] * w[2]).sum())
