"""The film: per-pixel accumulation of camera samples and light-tracing splats.

Camera samples use a box filter (a sample counts for the pixel it lies in). Splats (BDPT's
t = 1 strategy) land at their own raster position and are normalised by the number of
light subpaths, which is one per camera sample (pbrt-v3 ``Film::WriteImage(1/spp)``).
Non-finite samples are replaced by zero and counted (pbrt/Cycles policy); tests assert
the counter stays at zero.

Light passes (Blender's Emission / Direct / Indirect, api.md): every contribution is also
accumulated by its *path class*, the number of scattering vertices between camera and
emitter clamped to 2 (:data:`LIGHT_PASSES`): 0 = an emitter or the world seen directly,
1 = light scattered once toward the camera, 2 = everything else. The classes partition
each sample, so emission + direct + indirect equals the image RGB up to float rounding.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .camera import Window

#: Light-pass AOV names, indexed by path class (scattering vertices, clamped to 2).
LIGHT_PASSES = ("emission", "direct", "indirect")
#: :meth:`Film._add` bincounts over the span of the pixel indices when it is at most this many
#: times the number of samples, else adds them one by one (``np.add.at``: 0.08 ms per 4096
#: samples and channel, a 2-M-pixel bincount 3.6 ms).
ADD_SPAN = 4


def path_class(n_scatter: NDArray) -> NDArray:
    """(N,) light-pass index of paths with ``n_scatter`` scattering vertices (0, 1, ≥2 → 0, 1, 2)."""
    return np.minimum(np.asarray(n_scatter, np.int64), 2)


class Film:
    """Accumulators for the rendered window.

    Attributes:
        window: the rendered window (full-frame coordinates, y from the top).
        color: (h·w, 3) float64 sum of camera-sample radiance.
        splat: (h·w, 3) float64 sum of splatted radiance.
        alpha: (h·w,) float64 sum of coverage.
        aov_sum: name → (h·w, C) float64 sums of first-hit AOVs.
        color_parts: (3, h·w, 3) float64 camera samples plus splats / (h·w), split by path
            class (:data:`LIGHT_PASSES`): ``color_parts.sum(0) == color + splat / (h·w)``
            up to rounding (splats are pre-divided so that one array serves both).
        classified: every contribution so far came with its path class (else the light
            passes are not reported).
        passes_done: complete passes (samples per pixel) accumulated.
        nonfinite: number of dropped non-finite samples.
        pooled: (3, h·w, 3) float64 or None: sums of the *pooled* part of the image, by path
            class — ERCUTS's direct-light passes, whose every pass is an independent estimate
            of the same light: each iteration adds the sum of its ``pooled_passes`` passes
            (:meth:`set_pixels`), and the image holds their mean over all passes of all
            iterations (:meth:`light_parts`), not the mean of the iterations' means. An
            iteration's own passes vary with the time it had (Ercuts, directly lit scene at
            60 s: 64 and 258), and the mean of means has the variance σ²(1/64 + 1/258)/4 =
            σ²/205 where the pooled mean has σ²/322 (the minimum-variance combination of
            unbiased estimates weights each by its inverse variance, here its pass count).
        pooled_passes: passes summed in :attr:`pooled` (0: nothing pooled).
    """

    def __init__(self, window: Window):
        self.window = window
        n = window.n_pixels
        self.color = np.zeros((n, 3))
        self.splat = np.zeros((n, 3))
        self.alpha = np.zeros(n)
        self.color_parts = np.zeros((3, n, 3))
        self.classified = True
        self.aov_sum: dict[str, NDArray] = {}
        self.passes_done = 0
        self.nonfinite = 0
        self.pooled: NDArray | None = None
        self.pooled_passes = 0

    def _finite(self, L: NDArray, parts: NDArray | None = None) -> tuple[NDArray, NDArray | None]:
        """Zero (and count) samples whose value or any path-class part is not finite."""
        ok = np.isfinite(L).all(axis=1)
        if parts is not None:
            ok &= np.isfinite(parts).all(axis=(0, 2))
        bad = int((~ok).sum())
        if bad:
            self.nonfinite += bad
            L = np.where(ok[:, None], L, 0.0)
            if parts is not None:
                parts = np.where(ok[None, :, None], parts, 0.0)
        return L, parts

    def _add(self, target: NDArray, pix: NDArray, values: NDArray) -> None:
        """target[pix] += values with repeated indices, in time proportional to the samples,
        not the film: a bincount per channel over the span of ``pix`` when the samples fill
        it (a batch of camera samples: consecutive pixels), else an unbuffered ``np.add.at``
        per channel (scattered splats). A bincount over the whole film per batch made a pass
        quadratic in the pixel count: 1.35 s per 640×480 direct-light pass, 60 s at
        1920×1080 (door scene, 4096-pixel batches; :data:`ADD_SPAN`)."""
        if len(pix) == 0:
            return
        lo, hi = int(pix.min()), int(pix.max()) + 1
        cols = [(target, values)] if values.ndim == 1 else \
            [(target[:, c], values[:, c]) for c in range(values.shape[1])]
        if hi - lo > ADD_SPAN * len(pix):
            for t, v in cols:
                np.add.at(t, pix, v)
            return
        local = pix - lo
        for t, v in cols:
            t[lo:hi] += np.bincount(local, weights=v, minlength=hi - lo)

    def add_samples(self, pix: NDArray, L: NDArray, alpha: NDArray, parts: NDArray | None = None) -> None:
        """Accumulate camera samples: ``pix`` (N,) window pixel index, ``L`` (N, 3), ``alpha`` (N,);
        ``parts`` (3, N, 3): ``L`` split by path class (``parts.sum(0) == L``)."""
        L, parts = self._finite(L, parts)
        self._add(self.color, pix, L)
        self._add(self.alpha, pix, alpha)
        if parts is None:
            self.classified = False
            return
        for c in range(3):
            self._add(self.color_parts[c], pix, parts[c])

    def add_splats(self, raster: NDArray, L: NDArray, cls: NDArray | None = None) -> None:
        """Splat (N, 3) radiance at full-frame raster positions (N, 2); outside-window ones are
        dropped. ``cls`` (N,): path class of each splat (:func:`path_class`)."""
        w = self.window
        pix, ok = w.pixel(raster)
        if cls is None:
            self.classified = False
        if not ok.any():
            return
        pix = pix[ok]
        L = self._finite(L[ok])[0]
        self._add(self.splat, pix, L)
        if cls is not None:
            cls = np.asarray(cls)[ok]
            # One bincount over (class, pixel) cells: class c of pixel p is cell c·n + p.
            self._add(self.color_parts.reshape(-1, 3), cls * w.n_pixels + pix, L / w.n_pixels)

    def set_pixels(self, parts: NDArray, alpha: NDArray, pooled: NDArray | None = None,
                   pooled_passes: int = 0) -> None:
        """Replace the film by one finished pass: ``parts`` (3, h·w, 3) per-pixel radiance by
        path class, ``alpha`` (h·w,) coverage (integrators that do not accumulate samples);
        ``pooled`` (3, h·w, 3): the sum of ``pooled_passes`` > 0 passes of an estimate whose
        passes are pooled over the iterations (:attr:`pooled`), the image being ``parts``
        plus their mean."""
        self.color_parts[:] = parts
        self.color[:] = parts.sum(axis=0)
        self.splat[:] = 0.0
        self.alpha[:] = alpha
        self.passes_done = 1
        self.pooled, self.pooled_passes = (None, 0) if not pooled_passes else (pooled, int(pooled_passes))

    def add_aov(self, name: str, pix: NDArray, values: NDArray) -> None:
        """Accumulate a first-hit AOV (N, C) (averaged over passes in :meth:`aovs`)."""
        if name not in self.aov_sum:
            self.aov_sum[name] = np.zeros((self.window.n_pixels, values.shape[1]))
        self._add(self.aov_sum[name], pix, values)

    def merge(self, other: "Film") -> None:
        """Add a film of the same window holding one pass (a fresh film filled by batches) or
        ``other.passes_done`` merged passes."""
        self.color += other.color
        self.splat += other.splat
        self.alpha += other.alpha
        self.color_parts += other.color_parts
        self.classified &= other.classified
        for k, v in other.aov_sum.items():
            self.aov_sum[k] = self.aov_sum.get(k, 0) + v
        self.nonfinite += other.nonfinite
        self.passes_done += max(other.passes_done, 1)
        if other.pooled_passes:
            self.pooled = other.pooled.copy() if self.pooled is None else self.pooled + other.pooled
            self.pooled_passes += other.pooled_passes

    def image(self) -> NDArray[np.float32]:
        """(h, w, 4) float32 linear RGBA, top row first: mean camera estimate + splats."""
        w = self.window
        spp = max(self.passes_done, 1)
        # One light subpath per camera sample: spp·n_pixels light paths in all.
        rgb = self.color / spp + self.splat / (spp * w.n_pixels)
        if self.pooled_passes:
            rgb = rgb + self.pooled.sum(axis=0) / self.pooled_passes
        a = self.alpha / spp
        out = np.concatenate([rgb, a[:, None]], axis=1).reshape(w.height, w.width, 4)
        return out.astype(np.float32)

    def aovs(self) -> dict[str, NDArray[np.float32]]:
        """Per-pixel AOVs (h, w, C) float32: the first-hit ones and, when every contribution was
        classified, the light passes 'emission', 'direct', 'indirect' (same normalisation as
        :meth:`image`, so they sum to its RGB)."""
        spp = max(self.passes_done, 1)
        w = self.window
        out = {k: (v / spp).reshape(w.height, w.width, -1).astype(np.float32)
               for k, v in self.aov_sum.items()}
        if self.classified:
            parts = self.light_parts()
            for c, name in enumerate(LIGHT_PASSES):
                out[name] = parts[c].reshape(w.height, w.width, 3).astype(np.float32)
        return out

    def light_parts(self) -> NDArray:
        """(3, h·w, 3) float64 mean radiance per light pass (:data:`LIGHT_PASSES`), normalised
        like :meth:`image` (the pooled part included)."""
        parts = self.color_parts / max(self.passes_done, 1)
        if self.pooled_passes:
            parts = parts + self.pooled / self.pooled_passes
        return parts
