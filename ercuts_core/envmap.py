"""Equirectangular environment maps: radiance lookup and importance sampling, vectorized.

Coordinates follow Cycles' Environment Texture with the default equirectangular range
(``blender/cycles src/kernel/camera/projection.h``: ``direction_to_equirectangular`` =
``direction_to_equirectangular_range(dir, (−2π, π, −π, π))``). For a unit direction
``d = (x, y, z)`` in *map space* (``d_map = rotation · d_world``):

    u = 0.5 − atan2(y, x) / (2π)                  (u = 0.5 looks along +X, u = 0.75 along +Y)
    v = 0.5 + atan2(z, hypot(x, y)) / π = 1 − acos(z)/π   (v = 1 is the zenith +Z)

and the inverse φ = π − 2πu, elevation e = π(v − 0.5), d = (cos e cos φ, cos e sin φ, sin e).
Texel (row i, column j) of the (H, W, 3) array is centred on u = (j + ½)/W, v = (i + ½)/H,
so **row 0 is the bottom (nadir) row**, as Blender stores ``Image.pixels``.

Lookup is bilinear between the four nearest texel centres with periodic wrap in both
directions, as Cycles' default *Linear* interpolation with the *Repeat* extension of
environment textures (``x = u·W − ½``, ``y = v·H − ½``).

Importance sampling [pbrt-v3 §14.2.4 InfiniteAreaLight; pbrt-v4 ImageInfiniteLight]: a 2-D
piecewise-constant density p(s, t) over the unit square, sampled by inverting its marginal
(rows) and conditional (columns) cdfs, which keeps the stratification of (u₀, u₁). The
cells are the texel-centre *dual* grid (cell (i, j) spans texel centres i, i+1 × j, j+1,
wrapping), so (s, t) = (u − ½/W, v − ½/H) mod 1: the bilinear radiance inside a cell is the
blend of its four corner texels, hence the cell weight

    w_ij = mean(Y of the 4 corner texels) · H ∫_cell sin θ dv        (θ = π(1 − v), polar angle)

is positive wherever the looked-up radiance is (no bias from a zero-pdf region next to a
bright texel). The solid-angle density follows from dω = sin θ dθ dφ = 2π² sin θ du dv:

    pdf_ω(d) = p(s, t) / (2π² sin θ),  p(s, t) = w_ij · H·W / Σw.

Units: radiance [W·sr⁻¹·m⁻²], densities per steradian. All inputs and outputs are float64
(N, 3) directions / (N, 2) uniforms; no Python loop over lanes.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .sampling import ONE_MINUS_EPSILON, luminance

_TWO_PI_SQ = 2.0 * np.pi * np.pi


def direction_to_uv(d_map: NDArray) -> tuple[NDArray, NDArray]:
    """Cycles' equirectangular (u, v) in [0, 1] of (N, 3) map-space directions (module docstring)."""
    x, y, z = d_map[:, 0], d_map[:, 1], d_map[:, 2]
    u = 0.5 - np.arctan2(y, x) / (2.0 * np.pi)
    v = 0.5 + np.arctan2(z, np.hypot(x, y)) / np.pi
    return u, v


def uv_to_direction(u: NDArray, v: NDArray) -> NDArray:
    """(N, 3) unit map-space directions of equirectangular (u, v) (the inverse of
    :func:`direction_to_uv`: φ = π − 2πu, elevation π(v − ½))."""
    phi = np.pi - 2.0 * np.pi * u
    e = np.pi * (v - 0.5)
    ce = np.cos(e)
    return np.stack([ce * np.cos(phi), ce * np.sin(phi), np.sin(e)], axis=1)


def _row_sin_integral(H: int) -> NDArray:
    """(H,) H·∫ sin(πv) dv over dual-grid row i, v ∈ [(i+½)/H, (i+1½)/H] (the last row wraps
    over the pole: [1 − ½/H, 1] ∪ [0, ½/H]); the mean of sin θ over the row."""
    v0 = (np.arange(H) + 0.5) / H
    v1 = v0 + 1.0 / H
    out = (np.cos(np.pi * v0) - np.cos(np.pi * v1)) / np.pi
    out[-1] = 2.0 * (1.0 - np.cos(np.pi * 0.5 / H)) / np.pi
    return np.maximum(out, 0.0) * H


class EnvMap:
    """An equirectangular environment light: lookup, sampling and pdf (module docstring).

    Args:
        radiance: (H, W, 3) linear RGB radiance [W·sr⁻¹·m⁻²], finite, ≥ 0; row 0 = nadir.
        rotation: (3, 3) orthonormal world → map-space matrix (d_map = rotation · d_world).

    Attributes:
        integral_Y: ∫ Y(L(ω)) dω over the sphere [W·m⁻²] (luminance), from the cell weights.
        mean_rgb: (3,) solid-angle-weighted mean radiance (the map's "average colour").
    """

    def __init__(self, radiance: NDArray, rotation: NDArray | None = None):
        L = np.ascontiguousarray(np.asarray(radiance, np.float32))
        self.H, self.W = int(L.shape[0]), int(L.shape[1])
        self.L = L
        self.rotation = np.eye(3) if rotation is None else np.asarray(rotation, np.float64).reshape(3, 3)
        H, W = self.H, self.W
        Y = luminance(L)                                                   # (H, W)
        corners = 0.25 * (Y + np.roll(Y, -1, axis=1) + np.roll(Y, -1, axis=0)
                          + np.roll(np.roll(Y, -1, axis=0), -1, axis=1))
        self._sin_row = _row_sin_integral(H)
        w = corners * self._sin_row[:, None]                               # (H, W)
        total = float(w.sum())
        self.total = total
        self.integral_Y = _TWO_PI_SQ * total / (H * W)
        rgb_rows = L.astype(np.float64).mean(axis=1)                       # texel rows (H, 3)
        sin_texel = np.sin(np.pi * (np.arange(H) + 0.5) / H)
        self.mean_rgb = (rgb_rows * sin_texel[:, None]).sum(0) / max(float(sin_texel.sum()), 1e-300)
        # p(s, t) per cell (float32: 4 bytes a texel), marginal (rows) and conditional
        # (columns) cdfs; row i's conditional cdf is stored shifted by 2i, so that one
        # searchsorted serves all rows (values in [0, 2H), float64: 8 bytes a texel).
        self.cell_pdf = (w * (H * W / total) if total > 0 else np.zeros_like(w)).astype(np.float32)
        row = w.sum(axis=1)
        self.row_pmf = row / total if total > 0 else np.zeros(H)
        self.row_cdf = np.concatenate([[0.0], np.cumsum(self.row_pmf)])
        self.row_cdf[-1] = 1.0
        cdf = np.zeros((H, W + 1))
        np.cumsum(w / np.where(row > 0, row, 1.0)[:, None], axis=1, out=cdf[:, 1:])
        cdf[:, -1] = np.where(row > 0, 1.0, 0.0)
        cdf += 2.0 * np.arange(H)[:, None]
        self._col_flat = cdf.reshape(-1)

    @property
    def nbytes(self) -> int:
        """Memory held by the texels and the sampling tables [bytes]."""
        return int(self.L.nbytes + self.cell_pdf.nbytes + self._col_flat.nbytes)

    # ------------------------------------------------------------------ frames
    def to_map(self, d_world: NDArray) -> NDArray:
        """(N, 3) map-space directions of world directions (rotation · d)."""
        return d_world @ self.rotation.T

    def to_world(self, d_map: NDArray) -> NDArray:
        """(N, 3) world directions of map-space ones (rotationᵀ · d)."""
        return d_map @ self.rotation

    # ------------------------------------------------------------------ radiance
    def lookup(self, d_world: NDArray) -> NDArray:
        """(N, 3) float64 radiance arriving from world directions ``d_world`` (N, 3) (toward the
        environment), bilinear with periodic wrap (Cycles Linear + Repeat)."""
        d = np.asarray(d_world, np.float64).reshape(-1, 3)
        return self.lookup_uv(*direction_to_uv(self.to_map(d)))

    def lookup_uv(self, u: NDArray, v: NDArray) -> NDArray:
        """(N, 3) bilinear radiance at equirectangular coordinates (N,) ``u``, ``v`` (wrapping)."""
        u, v = np.asarray(u, np.float64).reshape(-1), np.asarray(v, np.float64).reshape(-1)
        x = u * self.W - 0.5
        y = v * self.H - 0.5
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]
        j0 = x0.astype(np.int64) % self.W
        i0 = y0.astype(np.int64) % self.H
        j1, i1 = (j0 + 1) % self.W, (i0 + 1) % self.H
        L = self.L.reshape(-1, 3)                   # flat takes: ~4× faster than L[i, j]
        r0, r1 = i0 * self.W, i1 * self.W
        top = L.take(r1 + j0, axis=0) * (1.0 - fx) + L.take(r1 + j1, axis=0) * fx
        bottom = L.take(r0 + j0, axis=0) * (1.0 - fx) + L.take(r0 + j1, axis=0) * fx
        return bottom * (1.0 - fy) + top * fy

    # ------------------------------------------------------------------ sampling
    def sample(self, u: NDArray) -> tuple[NDArray, NDArray]:
        """Directions toward the environment, distributed ∝ p(s, t)/(2π² sin θ).

        Args:
            u: (N, 2) uniforms in [0, 1): u[:, 0] picks the column, u[:, 1] the row.
        Returns:
            d_world: (N, 3) unit directions; pdf: (N,) solid-angle density [sr⁻¹]
            (0 where the map is black or at the poles).
        """
        u = np.asarray(u, np.float64).reshape(-1, 2)
        n = len(u)
        H, W = self.H, self.W
        if self.total <= 0:
            return np.tile([0.0, 0.0, 1.0], (n, 1)), np.zeros(n)
        u0 = np.clip(u[:, 0], 0.0, ONE_MINUS_EPSILON)
        u1 = np.clip(u[:, 1], 0.0, ONE_MINUS_EPSILON)
        i = np.clip(np.searchsorted(self.row_cdf, u1, side="right") - 1, 0, H - 1)
        di = (u1 - self.row_cdf[i]) / np.where(self.row_pmf[i] > 0, self.row_pmf[i], 1.0)
        shifted = u0 + 2.0 * i
        # Sorted queries: searchsorted narrows each search from the previous one (5× faster
        # than random queries into a multi-megabyte table)
        order = np.argsort(shifted)
        flat = np.empty(n, np.int64)
        flat[order] = np.searchsorted(self._col_flat, shifted[order], side="right") - 1
        j = np.clip(flat - i * (W + 1), 0, W - 1)
        base = i * (W + 1) + j
        c0 = self._col_flat[base]
        pj = self._col_flat[base + 1] - c0
        dj = (shifted - c0) / np.where(pj > 0, pj, 1.0)
        s = (j + np.clip(dj, 0.0, ONE_MINUS_EPSILON)) / W
        t = (i + np.clip(di, 0.0, ONE_MINUS_EPSILON)) / H
        uu = np.mod(s + 0.5 / W, 1.0)
        vv = np.mod(t + 0.5 / H, 1.0)
        d_map = uv_to_direction(uu, vv)
        sin_theta = np.cos(np.pi * (vv - 0.5))
        p = self.cell_pdf[i, j].astype(np.float64)
        ok = (sin_theta > 0) & (p > 0)
        pdf = np.where(ok, p / (_TWO_PI_SQ * np.where(ok, sin_theta, 1.0)), 0.0)
        return self.to_world(d_map), pdf

    def pdf(self, d_world: NDArray) -> NDArray:
        """(N,) solid-angle density with which :meth:`sample` returns world directions (N, 3)."""
        d = np.asarray(d_world, np.float64).reshape(-1, 3)
        if self.total <= 0:
            return np.zeros(len(d))
        dm = self.to_map(d)
        u, v = direction_to_uv(dm)
        s = np.mod(u - 0.5 / self.W, 1.0)
        t = np.mod(v - 0.5 / self.H, 1.0)
        j = np.clip((s * self.W).astype(np.int64), 0, self.W - 1)
        i = np.clip((t * self.H).astype(np.int64), 0, self.H - 1)
        sin_theta = np.hypot(dm[:, 0], dm[:, 1]) / np.maximum(np.linalg.norm(dm, axis=1), 1e-300)
        p = self.cell_pdf[i, j].astype(np.float64)
        ok = sin_theta > 0
        return np.where(ok, p / (_TWO_PI_SQ * np.where(ok, sin_theta, 1.0)), 0.0)
