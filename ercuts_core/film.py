"""The film: per-pixel accumulation of camera samples and light-tracing splats.

Camera samples use a box filter (a sample counts for the pixel it lies in). Splats (BDPT's
t = 1 strategy) land at their own raster position and are normalised by the number of
light subpaths, which is one per camera sample (pbrt-v3 ``Film::WriteImage(1/spp)``).
Non-finite samples are replaced by zero and counted (pbrt/Cycles policy); tests assert
the counter stays at zero.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .camera import Window


class Film:
    """Accumulators for the rendered window.

    Attributes:
        window: the rendered window (full-frame coordinates, y from the top).
        color: (h·w, 3) float64 sum of camera-sample radiance.
        splat: (h·w, 3) float64 sum of splatted radiance.
        alpha: (h·w,) float64 sum of coverage.
        aov_sum: name → (h·w, C) float64 sums of first-hit AOVs.
        passes_done: complete passes (samples per pixel) accumulated.
        nonfinite: number of dropped non-finite samples.
    """

    def __init__(self, window: Window):
        self.window = window
        n = window.n_pixels
        self.color = np.zeros((n, 3))
        self.splat = np.zeros((n, 3))
        self.alpha = np.zeros(n)
        self.aov_sum: dict[str, NDArray] = {}
        self.passes_done = 0
        self.nonfinite = 0

    def _finite(self, L: NDArray) -> NDArray:
        ok = np.isfinite(L).all(axis=1)
        bad = int((~ok).sum())
        if bad:
            self.nonfinite += bad
            L = np.where(ok[:, None], L, 0.0)
        return L

    def _add(self, target: NDArray, pix: NDArray, values: NDArray) -> None:
        """target[pix] += values with repeated indices (bincount per channel is fastest)."""
        n = len(target)
        if values.ndim == 1:
            target += np.bincount(pix, weights=values, minlength=n)
            return
        for c in range(values.shape[1]):
            target[:, c] += np.bincount(pix, weights=values[:, c], minlength=n)

    def add_samples(self, pix: NDArray, L: NDArray, alpha: NDArray) -> None:
        """Accumulate camera samples: ``pix`` (N,) window pixel index, ``L`` (N, 3), ``alpha`` (N,)."""
        self._add(self.color, pix, self._finite(L))
        self._add(self.alpha, pix, alpha)

    def add_splats(self, raster: NDArray, L: NDArray) -> None:
        """Splat (N, 3) radiance at full-frame raster positions (N, 2); outside-window ones are dropped."""
        w = self.window
        ix = np.floor(raster[:, 0]).astype(np.int64) - w.x0
        iy = np.floor(raster[:, 1]).astype(np.int64) - w.y0
        ok = (ix >= 0) & (ix < w.width) & (iy >= 0) & (iy < w.height)
        if not ok.any():
            return
        self._add(self.splat, iy[ok] * w.width + ix[ok], self._finite(L[ok]))

    def add_aov(self, name: str, pix: NDArray, values: NDArray) -> None:
        """Accumulate a first-hit AOV (N, C) (averaged over passes in :meth:`aovs`)."""
        if name not in self.aov_sum:
            self.aov_sum[name] = np.zeros((self.window.n_pixels, values.shape[1]))
        self._add(self.aov_sum[name], pix, values)

    def merge(self, other: "Film") -> None:
        """Add a film of the same window holding one pass."""
        self.color += other.color
        self.splat += other.splat
        self.alpha += other.alpha
        for k, v in other.aov_sum.items():
            self.aov_sum[k] = self.aov_sum.get(k, 0) + v
        self.nonfinite += other.nonfinite
        self.passes_done += 1

    def image(self) -> NDArray[np.float32]:
        """(h, w, 4) float32 linear RGBA, top row first: mean camera estimate + splats."""
        w = self.window
        spp = max(self.passes_done, 1)
        # One light subpath per camera sample: spp·n_pixels light paths in all.
        rgb = self.color / spp + self.splat / (spp * w.n_pixels)
        a = self.alpha / spp
        out = np.concatenate([rgb, a[:, None]], axis=1).reshape(w.height, w.width, 4)
        return out.astype(np.float32)

    def aovs(self) -> dict[str, NDArray[np.float32]]:
        spp = max(self.passes_done, 1)
        w = self.window
        return {k: (v / spp).reshape(w.height, w.width, -1).astype(np.float32)
                for k, v in self.aov_sum.items()}
