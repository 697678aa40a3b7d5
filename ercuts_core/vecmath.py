"""Row-wise vector helpers on (N, 3) float64 arrays, used by every module that shades or
traces (one home each)."""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def dot(a: NDArray, b: NDArray) -> NDArray:
    """Row-wise dot product of (N, 3) arrays → (N,)."""
    return np.einsum("ij,ij->i", a, b)


def normalize(v: NDArray) -> tuple[NDArray, NDArray]:
    """(unit rows, (N,) lengths) of (N, 3) ``v``; zero rows stay zero."""
    length = np.linalg.norm(v, axis=1)
    return v / np.maximum(length, 1e-300)[:, None], length
