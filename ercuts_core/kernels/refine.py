"""Compiled bookkeeping of the lock-step cut refinement (Walter et al. 2005; Yuksel 2019).

:func:`ercuts_core.integrators.ercuts.lightcuts.lightcut` and
:func:`~ercuts_core.integrators.ercuts.stochastic_lightcuts.stochastic_cut` refine every
shading point's cut in rounds; each round the numpy code re-sorts, re-sums and re-gathers
flat arrays of all live cut entries (``_criterion``, ``_prefix_threshold``, ``_select``,
``_retire``: 60–70 % of the gather at 1280×720, ``benchmarks/results/profile_gather.md``).
Here a round is two kernels over the entries *grouped by point* (point p owns the slots
``[start[p], start[p] + count[p])``), one loop over points each, and the work between
them — the new representatives' M·G, their shadow rays through embreex in one batch, the
children's bounds — stays batched over the whole round:

1. :func:`plan_round` — per point: estimate L̃ = Y(Σ retired) + Σ_C Y(M_r G_r V_r I_C),
   the stopping rule (``MODE_*``: every node's bound under ε·L̃; the Ercuts literal rule;
   the sum of bounds under ε/(1+ε)·L̃, eq. (5) of Zhu et al. / Walter et al.; or, for the
   stochastic cut, any positive bound), whether it holds yet (``unmet``), and the entries to
   split: those within the band err ≥ ``band``·max err, largest first, at most the point's
   remaining cut budget.
2. :func:`apply_round` — per point: the unsplit entries, then the children sharing the
   parent's representative, then the others (the numpy order); entries whose bound is 0
   leave the working set (lightcut: exact, accumulated; stochastic: leaves kept, empty
   clusters dropped).

Every per-point decision and every per-point sum is made in the same order as the numpy
code (including the global running sum of ``_prefix_threshold``), so cuts and radiance
agree with it up to the luminance dot product (numpy's BLAS may fuse multiply-adds):
``tests/test_kernels.py`` measures identical cuts and radiance within 1e-12 relative.
Units as in :mod:`ercuts_core.integrators.ercuts.lightcuts`.
"""
from __future__ import annotations

import numpy as np

from . import jit

#: Stopping rules (``lightcut(error_mode=…)``: 'bound', 'literal', 'total'; the stochastic cut).
MODE_BOUND, MODE_LITERAL, MODE_TOTAL, MODE_STOCHASTIC = 0, 1, 2, 3
_WR, _WG, _WB = 0.2126, 0.7152, 0.0722


@jit(inline=True)
def _lum(r: float, g: float, b: float) -> float:
    return r * _WR + g * _WG + b * _WB


@jit
def _errors(s, c, node, unit, bound, intensity, acc_rad_p, mode, max_error, abs_floor,
            run_sum, err, cand):
    """Per-entry error and candidate flag of one point's slots [s, s + c); returns the
    updated global running sum of the 'total' rule's normalised bounds."""
    total = 0.0
    if mode != MODE_STOCHASTIC:
        live = 0.0
        for k in range(s, s + c):
            i = node[k]
            est = _lum(unit[k, 0] * intensity[i, 0], unit[k, 1] * intensity[i, 1],
                       unit[k, 2] * intensity[i, 2])
            err[k] = max(bound[k] - est, 0.0) if mode == MODE_LITERAL else bound[k]
            live += est
        total = _lum(acc_rad_p[0], acc_rad_p[1], acc_rad_p[2]) + live
    else:
        for k in range(s, s + c):
            err[k] = bound[k]
    if mode == MODE_BOUND or mode == MODE_LITERAL:
        thr = max(max_error * total, abs_floor)
        for k in range(s, s + c):
            cand[k] = err[k] > thr
    elif mode == MODE_STOCHASTIC:
        for k in range(s, s + c):
            cand[k] = err[k] > 0.0
    else:
        run_sum = _prefix_candidates(s, c, bound, max(max_error / (1.0 + max_error) * total,
                                                      abs_floor), run_sum, cand)
    return run_sum


@jit
def _prefix_candidates(s, c, bound, limit, run_sum, cand):
    """The 'total' rule (lightcuts._prefix_threshold for one point): the largest bounds
    whose removal brings Σ L̄_C down to ``limit``; ∞ bounds always.  ``run_sum`` is the
    running sum over all points of the batch, as numpy's cumsum carries it."""
    order = np.argsort(-bound[s:s + c], kind="mergesort")
    bsum = 0.0
    for j in range(c):
        b = bound[s + order[j]]
        bsum += 0.0 if np.isinf(b) else b
    scale = bsum if bsum > 0.0 else 1.0
    excess = (bsum - limit) / scale
    first = 0.0
    for j in range(c):
        k = s + order[j]
        inf = np.isinf(bound[k])
        b = (0.0 if inf else bound[k]) / scale
        run_sum += b
        if j == 0:
            first = run_sum - b
        before = run_sum - b - first
        cand[k] = inf or before < excess
    return run_sum


@jit
def _choose(s, c, err, cand, budget, band, out, m):
    """Append to ``out`` (from position m) the point's candidates in the band, largest
    error first (stable), at most ``budget``; returns the new m (lightcuts._select)."""
    if budget <= 0:
        return m
    top = -np.inf
    n = 0
    for k in range(s, s + c):
        if cand[k]:
            n += 1
            top = max(top, err[k])
    if n == 0:
        return m
    idx = np.empty(n, np.int64)
    key = np.empty(n)
    n = 0
    for k in range(s, s + c):
        if cand[k] and (not (0.0 < band <= 1.0) or err[k] >= band * top):
            idx[n] = k
            key[n] = -err[k]
            n += 1
    order = np.argsort(key[:n], kind="mergesort")
    for j in range(min(n, budget)):
        out[m] = idx[order[j]]
        m += 1
    return m


@jit
def plan_round(start, count, node, unit, bound, intensity, acc_rad, acc_count, mode, max_error,
               abs_floor, max_cut_size, band, unmet):
    """Entries to split this round (step 1 of the module docstring).

    Args:
        start, count: (P,) int64 slot range of each point; node (K,) int64, unit (K,3)
            M_r·G_r·V_r, bound (K,) L̄_C of the live entries; intensity (n_nodes,3) I_C.
        acc_rad (P,3), acc_count (P,): radiance and number of the retired entries.
        unmet: (P,) bool, set here: the point's rule does not hold yet.

    Returns:
        (S,) int64 slots to split, grouped by point, each point's largest error first.
    """
    K = node.shape[0]
    err = np.empty(K)
    cand = np.zeros(K, np.bool_)
    out = np.empty(K, np.int64)
    m = 0
    run_sum = 0.0
    for p in range(start.shape[0]):
        s, c = start[p], count[p]
        unmet[p] = False
        if c == 0:
            continue
        run_sum = _errors(s, c, node, unit, bound, intensity, acc_rad[p], mode, max_error,
                          abs_floor, run_sum, err, cand)
        for k in range(s, s + c):
            if cand[k]:
                unmet[p] = True
                break
        m = _choose(s, c, err, cand, max_cut_size - acc_count[p] - c, band, out, m)
    return out[:m]


@jit
def _fate(b: float, leaf: bool, empty: int) -> int:
    """1: stays live (bound > 0); 2: retired (bound 0: exact, or a leaf); for an empty
    cluster (bound 0, not a leaf) ``empty``: 2 (lightcut: exact), 0 (the stochastic cut:
    dropped) or 3 (a shared stochastic cut: kept, outside the cut-size budget)."""
    if b > 0.0 or np.isnan(b):
        return 1
    if not leaf:
        return empty
    return 2


@jit
def _sources(start, count, sel, bound, kid_node, kid_bound, is_leaf, empty, node):
    """Per slot of the merged list (unsplit entries then children, point by point): the
    source (≥ 0 an old slot, < 0 the child −1 − q) and its fate (:func:`_fate`)."""
    K, S = node.shape[0], sel.shape[0]
    picked = np.zeros(K, np.bool_)
    for j in range(S):
        picked[sel[j]] = True
    src = np.empty(K + S, np.int64)
    fate = np.empty(K + S, np.int8)
    pt = np.empty(K + S, np.int64)
    m = 0
    j0 = 0
    for p in range(start.shape[0]):
        s, c = start[p], count[p]
        for k in range(s, s + c):
            if not picked[k]:
                src[m], pt[m] = k, p
                fate[m] = _fate(bound[k], is_leaf[node[k]], empty)
                m += 1
        j1 = j0
        while j1 < S and sel[j1] < s + c:
            j1 += 1
        for half in range(2):
            for j in range(j0, j1):
                q = half * S + j
                src[m], pt[m] = -1 - q, p
                fate[m] = _fate(kid_bound[q], is_leaf[kid_node[q]], empty)
                m += 1
        j0 = j1
    return src[:m], fate[:m], pt[:m]


@jit
def apply_round(start, count, node, unit, loss, bound, sel, kid_node, kid_unit, kid_loss,
                kid_bound, is_leaf, empty, intensity, acc_rad, acc_count):
    """The next round's live entries and this round's retired ones (step 2).

    Args:
        start, count, node, unit, loss, bound: the live entries (grouped by point).
        sel: (S,) slots split this round (:func:`plan_round`).
        kid_node, kid_unit, kid_loss, kid_bound: (2S,) children, the ones sharing the
            parent's representative first, then the others, aligned with sel.
        is_leaf, intensity: (n_nodes,) and (n_nodes,3) of the tree.
        empty: what becomes of empty clusters (bound 0, not leaves), :func:`_fate`: 2
            retired (lightcut), 0 dropped (stochastic cut), 3 retired without counting in
            ``acc_count`` (a shared stochastic cut).
        acc_rad (P,3), acc_count (P,): updated in place with the retired entries
            (radiance Σ M_r G_r V_r I_C; the per-point sum starts at 0 as numpy's bincount).

    Returns:
        (start, count, node, unit, loss, bound) of the live entries and
        (pt, node, unit, loss, bound) of the retired ones (grouped by point).
    """
    P = start.shape[0]
    src, fate, pt = _sources(start, count, sel, bound, kid_node, kid_bound, is_leaf, empty, node)
    n_live = n_ret = 0
    for i in range(src.shape[0]):
        n_live += fate[i] == 1
        n_ret += fate[i] >= 2
    n_count = np.zeros(P, np.int64)
    n_node, n_bound = np.empty(n_live, np.int64), np.empty(n_live)
    n_unit, n_loss = np.empty((n_live, 3)), np.empty((n_live, 3))
    rpt, rnode, rbound = np.empty(n_ret, np.int64), np.empty(n_ret, np.int64), np.empty(n_ret)
    runit, rloss = np.empty((n_ret, 3)), np.empty((n_ret, 3))
    rad = np.zeros((P, 3))
    w = r = 0
    for i in range(src.shape[0]):
        f = fate[i]
        if f == 0:
            continue
        k = src[i]
        q = -1 - k
        nd = node[k] if k >= 0 else kid_node[q]
        b = bound[k] if k >= 0 else kid_bound[q]
        if f == 1:
            n_node[w], n_bound[w] = nd, b
            for j in range(3):
                n_unit[w, j] = unit[k, j] if k >= 0 else kid_unit[q, j]
                n_loss[w, j] = loss[k, j] if k >= 0 else kid_loss[q, j]
            n_count[pt[i]] += 1
            w += 1
        else:
            p = pt[i]
            rpt[r], rnode[r], rbound[r] = p, nd, b
            for j in range(3):
                runit[r, j] = unit[k, j] if k >= 0 else kid_unit[q, j]
                rloss[r, j] = loss[k, j] if k >= 0 else kid_loss[q, j]
                rad[p, j] += runit[r, j] * intensity[nd, j]
            acc_count[p] += f == 2
            r += 1
    n_start = np.zeros(P, np.int64)
    for p in range(1, P):
        n_start[p] = n_start[p - 1] + n_count[p - 1]
    for p in range(P):
        for j in range(3):
            acc_rad[p, j] = acc_rad[p, j] + rad[p, j]
    return n_start, n_count, n_node, n_unit, n_loss, n_bound, rpt, rnode, runit, rloss, rbound
