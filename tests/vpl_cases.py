"""Random VPL sets shared by the light-tree, lightcut and glossy-bound tests."""
from __future__ import annotations

import numpy as np


def unit(v: np.ndarray) -> np.ndarray:
    """Rows of (N, 3) ``v`` scaled to unit length."""
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def random_vpls(n: int, seed: int, scale=4.0, shift=-2.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(positions uniform in shift + [0, scale)³, unit normals, RGB intensities with a
    log-normal spread) of ``n`` VPLs, deterministic per ``seed``."""
    rng = np.random.default_rng(seed)
    pos = rng.random((n, 3)) * scale + shift
    nrm = unit(rng.normal(size=(n, 3)))
    inten = rng.random((n, 3)) * rng.lognormal(0.0, 1.0, (n, 1))
    return pos, nrm, inten
