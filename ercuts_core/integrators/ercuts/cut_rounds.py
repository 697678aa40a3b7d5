"""Lock-step cut refinement on the compiled kernels (:mod:`ercuts_core.kernels.refine`).

The driver shared by :func:`.lightcuts.lightcut` and :func:`.stochastic_lightcuts.stochastic_cut`
when numba is available: the cut entries of a batch of P shading points live in flat arrays
grouped by point; each round :func:`~ercuts_core.kernels.refine.plan_round` picks the
entries to split, the caller's ``children`` callback builds their children in one batch
(lightcut: one batched M·G evaluation and one embreex shadow-ray batch for the children
that need a new representative; both: the children's bounds), and
:func:`~ercuts_core.kernels.refine.apply_round` merges them and retires the exact ones.
The rounds, the order of the entries and every per-point decision are those of the numpy
code, so the results agree (module docstring of :mod:`ercuts_core.kernels.refine`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from ...kernels import refine
from ...sampling import LUMINANCE_WEIGHTS
from .light_tree import LightTree

#: ``children(pt (S,), node (S,), unit (S,3), loss (S,3))`` → (node (2S,), unit (2S,3),
#: loss (2S,3), bound (2S,), shadow rays): the children of the split entries, in the order
#: the numpy code builds them.
Children = Callable[[NDArray, NDArray, NDArray, NDArray], tuple]


@dataclass
class RoundsResult:
    """What the rounds leave: per point radiance (P,3) and cut size (P,) of every entry
    (retired and live), the clamp loss Σ Y, the cut entries (pt, node, unit, bound) grouped
    by point in the numpy order, ``unmet`` (P,) and the numbers of rounds and shadow rays."""

    radiance: NDArray
    count: NDArray
    loss: float
    pt: NDArray
    node: NDArray
    unit: NDArray
    bound: NDArray
    unmet: NDArray
    rounds: int
    rays: int


def run_rounds(tree: LightTree, n_pts: int, unit: NDArray, loss: NDArray, bound: NDArray,
               children: Children, *, mode: int, max_error: float = 0.0, abs_floor: float = 0.0,
               max_cut_size: int, band: float, on_round=None, keep_empty: bool = False) -> RoundsResult:
    """Refine the cuts of ``n_pts`` points that start at the root (its (P,3) ``unit`` and
    ``loss`` and (P,) ``bound``) in lock-step rounds until no point splits an entry or
    ``on_round()`` returns False (``mode``: ``refine.MODE_*``; ``keep_empty``: the stochastic
    cut keeps its empty clusters outside its size budget, for a cut shared with other points;
    ``count`` then excludes them)."""
    fate_empty = (3 if keep_empty else 0) if mode == refine.MODE_STOCHASTIC else 2
    acc_rad, acc_count = np.zeros((n_pts, 3)), np.zeros(n_pts, np.int64)
    ones = np.ones(n_pts, np.int64)
    live = (np.arange(n_pts, dtype=np.int64), ones, np.full(n_pts, tree.root, np.int64),
            np.ascontiguousarray(unit, np.float64), np.ascontiguousarray(loss, np.float64),
            np.ascontiguousarray(bound, np.float64))
    none = np.zeros(0, np.int64)
    live, retired = _apply(tree, live, none, (none, np.zeros((0, 3)), np.zeros((0, 3)),
                                               np.zeros(0)), fate_empty, acc_rad, acc_count)
    kept = [retired]
    unmet = np.zeros(n_pts, bool)
    rounds = rays = 0
    while live[2].size:
        start, count, node, u, lo, b = live
        sel = refine.plan_round(start, count, node, u, b, tree.intensity, acc_rad, acc_count, mode,
                                float(max_error), float(abs_floor), int(max_cut_size), float(band),
                                unmet)
        if sel.size == 0:
            break
        pt = np.repeat(np.arange(n_pts, dtype=np.int64), count)[sel]
        *kids, new_rays = children(pt, node[sel], u[sel], lo[sel])
        live, retired = _apply(tree, live, sel, kids, fate_empty, acc_rad, acc_count)
        kept.append(retired)
        rays += new_rays
        rounds += 1
        if on_round is not None and on_round() is False:
            break
    else:
        unmet[:] = False                      # every entry retired
    return _finish(tree, n_pts, live, kept, acc_rad, acc_count, unmet, rounds, rays)


def _apply(tree, live, sel, kids, empty, acc_rad, acc_count):
    """:func:`~ercuts_core.kernels.refine.apply_round`: (live arrays, retired arrays)."""
    kid_node, kid_unit, kid_loss, kid_bound = kids
    out = refine.apply_round(*live, sel, np.asarray(kid_node, np.int64),
                             np.ascontiguousarray(kid_unit, np.float64),
                             np.ascontiguousarray(kid_loss, np.float64),
                             np.ascontiguousarray(kid_bound, np.float64), tree.is_leaf,
                             empty, tree.intensity, acc_rad, acc_count)
    return out[:6], out[6:]


def _finish(tree, n_pts, live, kept, acc_rad, acc_count, unmet, rounds, rays) -> RoundsResult:
    """Add the live entries to the per-point sums (as numpy's ``_Accum.add``) and gather the
    cut entries (retired round by round, then the live ones, stable by point)."""
    start, count, node, unit, loss, bound = live
    pt = np.repeat(np.arange(n_pts, dtype=np.int64), count)
    rad = unit * tree.intensity[node]
    acc_rad += np.stack([np.bincount(pt, rad[:, c], n_pts) for c in range(3)], axis=1)
    acc_count += count
    kept.append((pt, node, unit, loss, bound))
    cpt, cnode, cunit, closs, cbound = (np.concatenate([k[i] for k in kept]) for i in range(5))
    # Y by columns, not light_tree.luminance's BLAS matmul: 21 ms per 5·10⁴ rows on the loaded
    # machine (OpenBLAS threads), 28 % of a shared stochastic gather; only a statistic
    lc = closs * tree.intensity[cnode]
    w = LUMINANCE_WEIGHTS
    loss_sum = float((lc[:, 0] * w[0] + lc[:, 1] * w[1] + lc[:, 2] * w[2]).sum())
    order = np.argsort(cpt, kind="stable")
    return RoundsResult(acc_rad, acc_count, loss_sum, cpt[order], cnode[order], cunit[order],
                        cbound[order], unmet, rounds, rays)
