"""Row selection that is fast on numpy 1.26 (wavefront compaction is on every hot path).

``a[idx]`` with an integer array on an (N, k) array and ``a[mask]`` with a boolean mask
go through numpy's general fancy-indexing machinery; ``np.take(a, idx, axis=0)`` and
``np.compress(mask, a, axis=0)`` return the same rows 2–5× faster for 2-D float arrays
(measured: 2^18 rows × 3, 7.0 → 1.5 ms and 5.8 → 2.5 ms; ``benchmarks/bench_tracer.py``).
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def take_rows(a: NDArray, sel: ArrayLike) -> NDArray:
    """``a[sel]`` along axis 0 for an integer index array, a boolean mask, a scalar or a slice.

    Same result, dtype and errors as ``a[sel]`` (an out-of-range index or a mask of the
    wrong length raises IndexError); always a copy except for slices.
    """
    if isinstance(sel, slice):
        return a[sel]
    sel = np.asarray(sel)
    if sel.dtype == np.bool_:
        if sel.shape != a.shape[:1]:
            raise IndexError(f"boolean index of shape {sel.shape} for an axis of length {a.shape[0]}")
        return np.compress(sel, a, axis=0)
    return np.take(a, sel, axis=0)
