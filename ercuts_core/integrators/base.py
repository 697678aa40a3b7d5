"""What all integrators share: camera-sample generation, first-hit AOVs, MIS helpers.

An integrator is constructed with a :class:`~ercuts_core.scene.BuiltScene` and
:class:`~ercuts_core.settings.RenderSettings` and renders one batch of camera samples at
a time (``render_batch(film, pix, rng)``), so that the driver (:mod:`ercuts_core.render`)
can honour the time limit and cancellation between batches.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ..film import Film
from ..scene import BuiltScene, Surface
from ..settings import RenderSettings

if TYPE_CHECKING:
    from ..bsdf import Bsdf


def dot(a: NDArray, b: NDArray) -> NDArray:
    """Row-wise dot product of (N, 3) arrays."""
    return np.einsum("ij,ij->i", a, b)


def power_heuristic(pdf_a: NDArray, pdf_b: NDArray) -> NDArray:
    """w_a = p_a² / (p_a² + p_b²) [Veach 1997 eq. 9.13, β = 2]; 0 where both are 0."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        r = pdf_b / pdf_a                      # computed as a ratio: no overflow of p²
        w = 1.0 / (1.0 + r * r)
    return np.where((pdf_a > 0) & np.isfinite(w), w, np.where(np.isinf(pdf_a) & (pdf_a > 0), 1.0, 0.0))


class Integrator:
    """Base class: holds the scene and settings, makes camera rays, records AOVs."""

    def __init__(self, scene: BuiltScene, settings: RenderSettings):
        self.scene = scene
        self.settings = settings
        self.camera = scene.camera
        self.window = scene.camera.window

    def camera_rays(self, pix: NDArray, rng: np.random.Generator) -> tuple[NDArray, NDArray]:
        """Jittered rays through window pixels ``pix`` (N,) (box filter)."""
        w = self.window
        raster = np.stack([w.x0 + pix % w.width, w.y0 + pix // w.width], axis=1).astype(np.float64)
        raster += rng.random((len(pix), 2))
        return self.camera.generate_rays(raster)

    def record_first_hit(self, film: Film, pix: NDArray, keep: NDArray, surf: Surface | None,
                         bsdf: "Bsdf | None") -> None:
        """First-hit AOVs of camera samples ``pix``: depth (ray distance, Blender's Z pass),
        shading normal and albedo; lanes ``keep`` hit ``surf`` (others: 1e10 and zeros)."""
        n = len(pix)
        depth = np.full((n, 1), 1e10)
        normal = np.zeros((n, 3))
        albedo = np.zeros((n, 3))
        if len(keep):
            depth[keep, 0] = surf.t
            normal[keep] = surf.ns
            if bsdf is not None:
                albedo[keep] = bsdf.albedo()
        film.add_aov("depth", pix, depth)
        film.add_aov("normal", pix, normal)
        film.add_aov("albedo", pix, albedo)

    def alpha(self, surf: Surface) -> NDArray:
        """(N,) coverage: 1 for hits, and for misses unless the film is transparent."""
        if self.settings.film_transparent:
            return surf.valid.astype(np.float64)
        return np.ones(len(surf.valid))

    def render_batch(self, film: Film, pix: NDArray, rng: np.random.Generator) -> None:
        raise NotImplementedError
