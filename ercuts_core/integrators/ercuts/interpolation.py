"""Screen-space interpolation of the VPL gather at high resolution (issue 17): the gather runs
at the *anchor* pixels of a grid of spacing k (one pixel in k×k, the grid shifted per
iteration) and at every point that cannot be interpolated; the other points take the
bilinear mean of their (up to four) surrounding anchors' light, each anchor's light scaled
by the ratio of the two points' reflectances.

This is the interpolation of irradiance caching (Ward, Rubinstein, Clear 1988) on the
screen's grid, and the "interpolate where the G-buffer is smooth" reconstruction of
Walter et al. 2005 (§6, reconstruction cuts) reduced to its simplest form: a point is
interpolated only from anchors on the same material, with a shading normal within
:data:`SIMILAR_COS` and lying within :data:`SIMILAR_PLANE`·distance of the point's tangent
plane (so silhouettes, creases and contact edges keep their own gather), and only when its
BSDF is reflection-only and diffuse or rough (roughness ≥ :data:`ROUGH`): there the VPL light
L = Σ_j f·G·V·I_j is, per channel, the reflectance times a smooth function of position, so

    L(x) ≈ Σ_a w_a · (ρ(x) / ρ(a)) · L(a),   Σ_a w_a = 1     (ρ: :meth:`Bsdf.albedo`),

which keeps a texture's detail while sharing the gather between k² pixels. Its error is a
bias of the size of the irradiance's curvature over k pixels (a blur of the indirect light,
not of the texture or the direct light, which the direct-light passes render at every
pixel); it is not part of the lightcut error bound, and the statistics report the share of
interpolated points (``gather_spacing`` = 1 turns it off; 0 chooses k from the resolution,
:func:`auto_spacing`).

With S > 1 shading points per pixel (``shading_samples``) the anchors are the *first* point
of each grid pixel and every other point is a target, also for k = 1: a pixel's S points
each take the light of their own pixel's first point (k = 1; their corners' first points
for k > 1) when they lie on its surface, and are gathered themselves where they do not —
at silhouettes, creases and contact edges. That is anti-aliasing of the gather at the cost
of one gather per pixel plus one per edge point (edge-adaptive supersampling): over the
iterations the anchors move through the pixel (stratified jitter), so a pixel's mean is
the footprint average of ρ(x)·E(x) up to the correlation of ρ and E within one pixel.
The statistics report the share of interpolated points (``gather_interpolated``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ...settings import HIGH_RESOLUTION_PIXELS
from .vpl import GBuffer

#: ``gather_spacing`` = 0: the spacing k for renders of at least this many pixels (largest
#: first); below the smallest, every point is gathered (k = 1).
AUTO_SPACING = ((HIGH_RESOLUTION_PIXELS, 2),)
#: Two points lie on one smooth surface (:func:`same_surface`; also the gather's cut
#: sharing) when they share the material, their shading normals are within this cosine …
SIMILAR_COS = 0.95
#: … and the second lies within this fraction of their distance from the first's tangent plane.
SIMILAR_PLANE = 0.05
#: Points whose specular lobe is rougher than this (or that have none) may be interpolated.
ROUGH = 0.5
#: A point is interpolated when its usable anchors' bilinear weights sum to at least this.
MIN_WEIGHT = 0.5
#: Reflectance below this (a channel) counts as black: its light is 0 whatever the anchor's.
RHO_MIN = 1e-3
#: Shading points per chunk while the reflectances are computed (bounds the BSDF temporaries).
CHUNK = 1 << 18


def auto_spacing(n_pixels: int) -> int:
    """The anchor spacing k for ``gather_spacing`` = 0 (:data:`AUTO_SPACING`)."""
    for pixels, k in AUTO_SPACING:
        if n_pixels >= pixels:
            return k
    return 1


def grid_offset(k: int, iteration: int) -> tuple[int, int]:
    """The anchor grid's offset (ox, oy) in [0, k)² for ``iteration``: the k² offsets in turn,
    so that over k² iterations every pixel is an anchor once."""
    i = iteration % (k * k)
    return i % k, i // k


@dataclass
class Interpolation:
    """The interpolated points of a G-buffer and their anchors.

    Attributes:
        target: (T,) G-buffer entries that are interpolated (not gathered).
        anchor: (T, 4) G-buffer entries of their grid corners (any valid entry where the
            weight is 0).
        weight: (T, 4) float32 bilinear weights of the usable corners, summing to 1 per row.
        rho: (Q, 3) float32 reflectance ρ of every point (0 where not needed).
    """

    target: NDArray
    anchor: NDArray
    weight: NDArray
    rho: NDArray

    def gathered(self, valid: NDArray) -> NDArray:
        """(Q,) bool: the points the gather must visit (the valid ones not interpolated)."""
        out = valid.copy()
        out[self.target] = False
        return out

    def fill(self, L: NDArray, done: NDArray) -> NDArray:
        """Set the light parts ``L`` (K, Q, 3) at the targets whose anchors are all ``done``
        (Q,) bool, in place (the others get 0); returns those targets' (T,) done flags."""
        ok = np.ones(len(self.target), bool)
        acc = np.zeros((L.shape[0], len(self.target), 3))
        rho_t = self.rho[self.target]
        for c in range(self.anchor.shape[1]):
            a, w = self.anchor[:, c], self.weight[:, c]
            ok &= done[a] | (w == 0)
            rho_a = self.rho[a]
            ratio = np.divide(rho_t, rho_a, out=np.zeros_like(rho_t), where=rho_a >= RHO_MIN)
            acc += L[:, a] * (ratio * w[:, None])[None]
        L[:, self.target] = acc * ok[None, :, None]
        return ok

    def fill_values(self, v: NDArray) -> None:
        """Set (Q,) per-point values ``v`` (the cut sizes) at the targets to their anchors'
        weighted mean, in place."""
        v[self.target] = (v[self.anchor] * self.weight).sum(axis=1)


def plan_interpolation(g: GBuffer, scene, width: int, height: int, k: int,
                       offset: tuple[int, int], keep_going=None) -> Interpolation | None:
    """The interpolated points of ``g`` (a window of ``width`` × ``height`` pixels, S points
    per pixel, entry q = pixel·S + s) on the anchor grid of spacing ``k`` shifted by
    ``offset`` (anchors: the grid pixels' points s = 0, module docstring); None for k ≤ 1
    with S = 1, when no point qualifies or when ``keep_going()`` (called
    after every chunk of work, for progress and Esc) returns False (module docstring)."""
    S = g.samples
    if k <= 1 and S <= 1:
        return None
    smooth = _smooth_points(g, scene, keep_going)
    if smooth is None:
        return None
    ok, rho = smooth
    q = np.arange(len(g.pixel))
    pix = q // S
    x, y = pix % width, pix // width
    dx, dy = (x - offset[0]) % k, (y - offset[1]) % k
    cand = np.flatnonzero(ok & ((dx != 0) | (dy != 0) | (q % S != 0)))
    if len(cand) == 0:
        return None
    x0, y0 = x[cand] - dx[cand], y[cand] - dy[cand]
    fx, fy = dx[cand] / k, dy[cand] / k
    anchor = np.zeros((len(cand), 4), np.int64)
    weight = np.zeros((len(cand), 4))
    for c, (ox, oy, w) in enumerate(((0, 0, (1 - fx) * (1 - fy)), (k, 0, fx * (1 - fy)),
                                     (0, k, (1 - fx) * fy), (k, k, fx * fy))):
        cx, cy = x0 + ox, y0 + oy
        inside = (cx >= 0) & (cx < width) & (cy >= 0) & (cy < height) & (w > 0)
        a = np.where(inside, (np.clip(cy, 0, height - 1) * width + np.clip(cx, 0, width - 1)) * S, cand)
        use = inside & ok[a] & _alike(g, rho, cand, a)
        anchor[:, c] = np.where(use, a, cand)
        weight[:, c] = np.where(use, w, 0.0)
        if keep_going is not None and not keep_going():
            return None
    total = weight.sum(axis=1)
    keep = total >= MIN_WEIGHT
    if not keep.any():
        return None
    return Interpolation(target=cand[keep], anchor=anchor[keep],
                         weight=(weight[keep] / total[keep, None]).astype(np.float32), rho=rho)


def _smooth_points(g: GBuffer, scene, keep_going=None) -> tuple[NDArray, NDArray] | None:
    """(Q,) bool points whose VPL light may be interpolated (valid, first hits, a
    reflection-only BSDF with no delta lobe and no specular lobe sharper than :data:`ROUGH`)
    and their (Q, 3) float32 reflectance ρ (:meth:`Bsdf.albedo`); None when stopped."""
    ok = g.valid.copy()
    if g.through is not None:
        ok &= ~g.through
    rho = np.zeros((len(g.pixel), 3), np.float32)
    idx = np.flatnonzero(ok)
    for lo in range(0, len(idx), CHUNK):
        h = idx[lo:lo + CHUNK]
        bsdf = scene.bsdf(g.mat[h], g.ns[h], g.ng[h], g.p[h])
        smooth = bsdf.reflect_only & ~(bsdf.delta & ((bsdf.p_spec > 0.0) | (bsdf.p_tr > 0.0)))
        if not bsdf.all_diffuse:
            smooth &= bsdf.is_diffuse | (scene.roughness(g.mat[h], g.p[h]) >= ROUGH)
        ok[h] = smooth
        rho[h] = bsdf.albedo()
        if keep_going is not None and not keep_going():
            return None
    return ok, rho


def same_surface(g: GBuffer, i: NDArray, j: NDArray) -> NDArray:
    """(N,) bool: G-buffer entries ``j`` lie on the smooth surface of entries ``i``: the same
    material, shading normals within :data:`SIMILAR_COS`, and within :data:`SIMILAR_PLANE`
    of their distance from i's tangent plane (not across a silhouette, crease or step)."""
    n_i = g.ns[i]
    d = g.p[j] - g.p[i]
    dist = np.sqrt(np.einsum("ij,ij->i", d, d))
    return ((g.mat[i] == g.mat[j]) & (np.einsum("ij,ij->i", n_i, g.ns[j]) >= SIMILAR_COS)
            & (np.abs(np.einsum("ij,ij->i", d, n_i)) <= SIMILAR_PLANE * dist))


def _alike(g: GBuffer, rho: NDArray, t: NDArray, a: NDArray) -> NDArray:
    """(N,) bool: anchor entries ``a`` may light targets ``t`` (:func:`same_surface`, and no
    channel black at the anchor that is not black at the target)."""
    rho_ok = ((rho[a] >= RHO_MIN) | (rho[t] < RHO_MIN)).all(axis=1)
    return same_surface(g, t, a) & rho_ok
