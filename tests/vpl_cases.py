"""Random VPL sets and lightcut receivers shared by the light-tree, lightcut and bound tests."""
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


def receiver_points(table, x: np.ndarray, n: np.ndarray, wo: np.ndarray,
                    transmissive: np.ndarray | None = None, glossy: bool = True):
    """Lightcut ``ShadingPoints`` of one receiver per row of ``table`` at positions x (N, 3) with
    unit normals n (N, 3) on wo's side and views wo (N, 3), as the gather builds them: the
    renderer's BSDF, its ``bsdf_max_value`` bound, every VPL visible; ``glossy`` adds the
    per-cluster ``GlossyReceivers`` bound (False: the constant bound only)."""
    from ercuts_core.bsdf import Bsdf, bsdf_max_value
    from ercuts_core.integrators.ercuts.lightcuts import GlossyReceivers, ShadingPoints

    idx = np.arange(len(table.names))
    bsdf = Bsdf.from_table(table, idx, n, n)

    def eval_f(i: np.ndarray, wi: np.ndarray) -> np.ndarray:
        return bsdf.subset(i).eval(wo[i], wi)

    return ShadingPoints(x, n, wo, bsdf_max_value(table, idx), eval_f,
                         lambda i, q, qn: np.ones(len(i), bool), transmissive=transmissive,
                         glossy=GlossyReceivers.from_bsdf(bsdf, wo, n) if glossy else None)
