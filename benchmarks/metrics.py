"""Image-error metrics of the benchmark report (style-and-testing.md §2.8).

All take linear RGB images ``x`` (test) and ``r`` (reference) of shape (h, w, 3) and average
over every pixel and channel; no firefly discarding or per-pixel clamping.
"""
from __future__ import annotations

import numpy as np

#: ε of relMSE: mean((x − r)² / (r² + ε)), the common RelativeMSE(eps=0.01).
EPS = 1e-2
#: ε of SMAPE's denominator.
SMAPE_EPS = 1e-3


def relmse(x: np.ndarray, r: np.ndarray) -> float:
    """Relative MSE (MRSE): mean((x − r)² / (r² + 0.01))."""
    return float(np.mean((np.asarray(x, np.float64) - r) ** 2 / (np.asarray(r, np.float64) ** 2 + EPS)))


def rmse(x: np.ndarray, r: np.ndarray) -> float:
    """Root mean squared error sqrt(mean((x − r)²))."""
    return float(np.sqrt(np.mean((np.asarray(x, np.float64) - r) ** 2)))


def smape(x: np.ndarray, r: np.ndarray) -> float:
    """Symmetric MAPE: mean(|x − r| / (|x| + |r| + 1e-3)) (KiRaRay's form), in [0, 1]."""
    x = np.asarray(x, np.float64)
    r = np.asarray(r, np.float64)
    return float(np.mean(np.abs(x - r) / (np.abs(x) + np.abs(r) + SMAPE_EPS)))


def energy_ratio(x: np.ndarray, r: np.ndarray) -> float:
    """Mean image value (all channels) relative to the reference's."""
    return float(np.mean(x, dtype=np.float64) / np.mean(r, dtype=np.float64))


def reference_floor(r: np.ndarray, var: np.ndarray) -> dict[str, float]:
    """What the reference's own noise adds in expectation to relMSE and MSE (per-pixel
    variance ``var`` of the reference mean; independent of the test image)."""
    return dict(relmse=float(np.mean(var / (np.asarray(r, np.float64) ** 2 + EPS))),
                mse=float(np.mean(var)))


def hdr_flip(x: np.ndarray, r: np.ndarray) -> float | None:
    """Mean HDR-FLIP (NVlabs FLIP, linear-sRGB input, default 67 ppd) of ``x`` against ``r``;
    None when the optional ``flip-evaluator`` package is not installed."""
    try:
        import flip_evaluator
    except ImportError:
        return None
    _, mean, _ = flip_evaluator.evaluate(np.ascontiguousarray(np.maximum(r, 0), np.float32),
                                         np.ascontiguousarray(np.maximum(x, 0), np.float32),
                                         "HDR", applyMagma=False)
    return float(mean)
