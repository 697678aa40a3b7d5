"""Paper step 1 — initialization: a rough BDPT image, its energy P, and seed paths.

P is the image energy (Σ over the window's pixels of the luminance) of the paths the VPLs
stand for: paths with a surface point x2 (algorithm.md §G.1). With ``direct_light='NEE'``
(the default) these are the indirect paths (x2 scatters), and P is the energy of the rough
BDPT image's indirect pass (:func:`indirect_energy`); with 'VPL' (the paper) it is the rough
image's energy minus that of the classes the ERCUTS integrator renders itself — light seen
directly and direct light from point, spot, sun and environment lights.

Seed paths come from fresh samples, one per pixel (paper §3.2: "at each pixel a fresh
bidirectional path"): every connection strategy of a BDPT sample with a non-zero
MIS-weighted contribution is a seed with energy e = Y(w·C) in pixel units (Mitsuba's
``PathSampler::samplePaths``). :func:`seeds_from_path_tracer` is a unidirectional
alternative (Cline et al. 2005 seeded ERPT with a path tracer) used when BDPT seeding is
switched off and by tests.
"""
from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np
from numpy.typing import NDArray

from ...camera import Camera, Window
from ...description import CameraDesc
from ...film import Film
from ...lights import AREA, ENV, POINT, SUN, TRI
from ...sampling import luminance, power_heuristic
from ...scene import BuiltScene
from ...vecmath import dot
from .paths import PathBatch, is_target, x1_or_x2_clear

#: Camera samples of the rough BDPT image per iteration at most (issue 17): ``rough_samples``
#: per pixel while that fits (160×120 keeps its 16), else the image is rendered at a lower
#: resolution (:func:`rough_factor`), so its cost and P's noise do not grow with the pixels.
ROUGH_SAMPLE_BUDGET = 1 << 19


def rough_factor(n_pixels: int, spp: int) -> int:
    """Downscale factor k ≥ 1 of the rough image: 1 while ``spp``·``n_pixels`` fits in
    :data:`ROUGH_SAMPLE_BUDGET`, else ⌈√(spp·n_pixels / budget)⌉ (1920×1080 at 16 spp: 8,
    a 240×135 rough image)."""
    need = spp * max(n_pixels, 1)
    return 1 if need <= ROUGH_SAMPLE_BUDGET else int(math.ceil(math.sqrt(need / ROUGH_SAMPLE_BUDGET)))


#: The rough BDPT stops once P is known to this relative standard error (issue 17): P scales
#: the whole VPL image, so its error adds ≈ err² to the relMSE (0.01: 1e-4, 4 % of the door
#: scene's at 1280×720 in 300 s and < 1 % of the indirect scenes' at 160×120), and passes
#: beyond it only take time from the gather. Measured on the door at 1280×720: one pass's P
#: has a relative spread of 2.5 % (0.68 % after 14 passes), so ≈ 7 passes instead of the 14
#: its 45 s time share allowed; at 160×120 a pass's spread is several % (BDPT's fireflies)
#: and the rule seldom binds.
ROUGH_P_ERROR = 0.01
#: Passes before :data:`ROUGH_P_ERROR` may stop the rough BDPT (a spread from fewer passes is
#: itself too uncertain to trust).
ROUGH_MIN_PASSES = 4


def p_relative_error(energies: list[float]) -> float:
    """Relative standard error of P's mean over independent passes with energies
    ``energies`` (each an unbiased estimate of P): s/(√n·mean), inf below two passes or at
    P = 0."""
    e = np.asarray(energies, np.float64)
    if len(e) < 2 or e.mean() <= 0:
        return float("inf")
    return float(e.std(ddof=1) / np.sqrt(len(e)) / e.mean())


def rough_camera(desc: CameraDesc, k: int) -> CameraDesc:
    """``desc`` at 1/``k`` of its resolution with the same view: the pixel aspect absorbs the
    rounding, so the image plane (Blender's sensor fit of width·aspect_x : height·aspect_y) and
    the border fractions are unchanged."""
    w, h = max(1, round(desc.width / k)), max(1, round(desc.height / k))
    return dataclasses.replace(desc, width=w, height=h,
                               pixel_aspect_x=desc.pixel_aspect_x * desc.width / w,
                               pixel_aspect_y=desc.pixel_aspect_y * desc.height / h)


def scene_with_camera(scene: BuiltScene, desc: CameraDesc) -> BuiltScene:
    """A view of ``scene`` (same tracer, lights, materials) seen by another camera; it is never
    closed itself (the scene owns the tracer)."""
    view = copy.copy(scene)
    view.camera = Camera(desc)
    return view


class RoughImage:
    """Step 1's rough BDPT image, rendered into ``film`` over the window ``low``, which is the
    render's window ``full`` (k = 1) or the same view at 1/k of the resolution
    (:func:`rough_camera`). Energies are in full-resolution pixel units (each low-resolution
    pixel stands for (W/w)·(H/h) full ones); :meth:`full_film` is the image the render shows
    and falls back to (nearest low-resolution pixel)."""

    def __init__(self, film: Film, full: Window, full_size: tuple[int, int], low_size: tuple[int, int]):
        self.film, self.full = film, full
        (W, H), (w, h) = full_size, low_size
        self.pixel_area = (W / w) * (H / h)        # full pixels per low-resolution pixel
        #: indirect energy of the paths through delta lobes, of those outside the chains'
        #: domain and of those the direct-light passes path-trace when the gather follows
        #: mirrors and glass (set by the integrator from :attr:`BDPTIntegrator.delta_indirect`,
        #: ``outside_indirect``, ``traced_indirect``)
        self.delta_indirect = 0.0
        self.outside_indirect = 0.0
        self.traced_indirect = 0.0
        self.same = film.window == full
        self._full: tuple[int, Film] | None = None     # (passes_done, full_film()) cache
        if not self.same:
            pix = np.arange(full.n_pixels)
            raster = (full.raster(pix) + 0.5) * np.array([w / W, h / H])
            self.index = film.window.pixel(raster, clip=True)[0]

    @property
    def passes_done(self) -> int:
        return self.film.passes_done

    def energy(self) -> float:
        """Σ over the full window's pixels of Y (:func:`rough_image_energy`)."""
        return rough_image_energy(self.film.image()) * self.pixel_area

    def indirect_energy(self) -> float:
        """:func:`indirect_energy` of the rough image, in full-resolution pixels."""
        return indirect_energy(self.film.light_parts()) * self.pixel_area

    def full_parts(self, pix: NDArray | None = None) -> tuple[NDArray, NDArray]:
        """((3, n, 3) light passes, (n,) coverage) of full-window pixels ``pix`` (default:
        all), each its nearest low-resolution pixel's: what :meth:`full_film` holds, without
        building a film (at 1080p every pass over the (3, h·w, 3) float64 parts costs
        ≈ 0.1–0.3 s, which a cancel would wait for)."""
        low = self.film
        if self.same:
            index = slice(None) if pix is None else pix
        else:
            index = self.index if pix is None else self.index[pix]
        return low.light_parts()[:, index], (low.alpha / max(low.passes_done, 1))[index]

    def fill(self, film: Film) -> None:
        """Put the rough image into ``film`` of the full window: merged into it, or set as its
        one pass when it is empty (a cancel in the first iteration: one pass over the parts)."""
        if film.passes_done == 0 and not film.aov_sum and not self.same:
            film.set_pixels(*self.full_parts())          # = merging full_film() into it
            film.classified = self.film.classified
        else:
            film.merge(self.full_film())

    def full_film(self) -> Film:
        """The rough image as a film of the full window (itself when k = 1). Built once per
        state of the rough film (upsampling to 1080p takes ≈ 1 s, which the preview, the
        gather's fallback and a cancel would otherwise each pay again); read-only."""
        if self.same:
            return self.film
        low = self.film
        if self._full is not None and self._full[0] == low.passes_done:
            return self._full[1]
        out = Film(self.full)
        out.set_pixels(*self.full_parts())
        out.classified = low.classified
        self._full = (low.passes_done, out)
        return out


def rough_image_energy(image: NDArray) -> float:
    """Σ over pixels of Y(rgb) of an (h, w, ≥3) image."""
    return float(luminance(np.asarray(image, np.float64)[..., :3]).sum())


def indirect_energy(light_parts: NDArray) -> float:
    """Σ over pixels of Y of the indirect pass of (3, h·w, 3) light passes (paths with two or
    more scattering vertices, :data:`~ercuts_core.film.LIGHT_PASSES`)."""
    return float(luminance(np.asarray(light_parts, np.float64)[2]).sum())


def seeds_from_path_tracer(scene: BuiltScene, max_depth: int, rng: np.random.Generator,
                           pix: NDArray | None = None, direct: bool = True,
                           clear_x1: bool = True) -> tuple[PathBatch, NDArray]:
    """One path-traced sample per pixel; every NEE connection and BSDF-found emitter is a seed.

    Returns:
        (S paths, (S,) energies e = Y(w·C) in pixel units); target-class paths only
        (:func:`.paths.is_target` with ``direct``), and with ``clear_x1`` False only those
        whose x1 and x2 are not on mirrors or glass (:func:`.paths.x1_or_x2_clear`).
    """
    cam, tracer = scene.camera, scene.tracer
    w = cam.window
    pix = np.arange(w.n_pixels) if pix is None else pix
    n, K = len(pix), max_depth + 2
    raster = w.raster(pix) + rng.random((n, 2))
    o, d = cam.generate_rays(raster, cam.lens_samples(rng, n))
    base = PathBatch.empty(n, K)
    base.raster[:] = raster
    base.p[:, 0] = o
    beta = np.ones((n, 3))
    lanes = np.arange(n)
    prev_pdf = np.zeros(n)
    out_paths, out_e = [], []
    for depth in range(1, max_depth + 2):
        surf = scene.intersect(o, d)
        hit = surf.valid
        # BSDF-sampled rays that found an emitter (depth ≥ 2: x2 exists).
        if depth >= 2:
            _emitter_seeds(scene, base, lanes, surf, d, beta, prev_pdf, depth, out_paths, out_e)
        keep = np.flatnonzero(hit)
        if depth > max_depth or len(keep) == 0:
            break
        lanes, surf, d, beta = lanes[keep], surf.subset(keep), d[keep], beta[keep]
        base.p[lanes, depth], base.ng[lanes, depth] = surf.p, surf.ng
        base.ns[lanes, depth], base.mat[lanes, depth] = surf.ns, surf.mat
        wo = -d
        bsdf = scene.bsdf(surf.mat, surf.ns, surf.ng, surf.p)
        _nee_seeds(scene, base, lanes, surf, wo, bsdf, beta, depth, rng, out_paths, out_e)
        bs = bsdf.sample(wo, rng.random((len(lanes), 3)))
        beta = beta * bs.weight
        # a delta event ends the lane: paths through mirrors and glass are no seeds (the
        # chains live on paths without delta vertices; ERCUTS path-traces those)
        alive = np.flatnonzero(bs.valid & ~bs.is_delta & (beta.max(axis=1) > 0))
        lanes, surf, beta = lanes[alive], surf.subset(alive), beta[alive]
        d, prev_pdf = bs.wi[alive], bs.pdf[alive]
        o = tracer.offset(surf.p, surf.ng, d)
    if not out_paths:
        return PathBatch.empty(0, K), np.zeros(0)
    paths, e = PathBatch.concat(out_paths), np.concatenate(out_e)
    keep = is_target(scene, paths, direct) & (e > 0)
    if not clear_x1:
        keep &= ~x1_or_x2_clear(scene, paths)
    return paths.take(keep), e[keep]


def _nee_seeds(scene, base, lanes, surf, wo, bsdf, beta, depth, rng, out_paths, out_e):
    lights = scene.lights
    n = len(lanes)
    ls = lights.illuminate(surf.p, rng.random(n), rng.random((n, 2)))
    kind = lights.kind[ls.light]
    f, pdf_bsdf = bsdf.eval_pdf(wo, ls.wi)
    f = f * np.abs(dot(surf.ns, ls.wi))[:, None]
    nee_only = (kind == POINT) | (kind == SUN) | (kind == AREA)
    w = np.where(nee_only, 1.0, power_heuristic(ls.pdf_w, pdf_bsdf))
    C = beta * f * ls.Li / np.where(ls.valid, ls.pdf_w, 1.0)[:, None] * w[:, None]
    ok = ls.valid & (C.max(axis=1) > 0)
    if not ok.any():
        return
    r = np.flatnonzero(ok)
    paths = base.take(lanes[r])
    paths.k[:] = depth + 1
    paths.light[:] = ls.light[r]
    infinite = (kind[r] == SUN) | (kind[r] == ENV)
    paths.p[:, depth + 1] = np.where(infinite[:, None], ls.wi[r], lights.chain_vertex(ls.light[r], ls.p[r]))
    surf_l = ((kind[r] == AREA) | (kind[r] == TRI))[:, None]
    paths.ng[:, depth + 1] = np.where(surf_l, ls.n[r], 0.0)
    paths.ns[:, depth + 1] = paths.ng[:, depth + 1]
    vis = _visible_last(scene, paths)
    out_paths.append(paths.take(vis))
    out_e.append(luminance(C[r][vis]))


def _emitter_seeds(scene, base, lanes, surf, d, beta, prev_pdf, depth, out_paths, out_e):
    lights = scene.lights
    hit = surf.valid
    Le = np.zeros((len(lanes), 3))
    light = np.full(len(lanes), -1)
    pdf_l = np.zeros(len(lanes))
    if len(lights.emissive_tris) and hit.any():
        h = np.flatnonzero(hit)
        lt = lights.tri_light[surf.prim[h]]
        em = lt >= 0
        h = h[em]
        Le[h] = lights.tri_radiance(surf.prim[h], surf.p[h])
        light[h] = lt[em]
        prev = base.p[lanes[h], depth - 1]
        pdf_l[h] = lights.pdf_illuminate_tri(prev, surf.prim[h], surf.p[h], surf.ng[h])
    if lights.env_light >= 0 and (~hit).any():
        m = np.flatnonzero(~hit)
        Le[m] = lights.env_radiance(d[m])
        light[m] = lights.env_light
        pdf_l[m] = lights.pdf_illuminate_env(d[m])
    ok = light >= 0
    if not ok.any():
        return
    r = np.flatnonzero(ok)
    w = power_heuristic(prev_pdf[r], pdf_l[r])
    C = beta[r] * Le[r] * w[:, None]
    paths = base.take(lanes[r])
    paths.k[:] = depth
    paths.light[:] = light[r]
    env = ~hit[r]
    paths.p[:, depth] = np.where(env[:, None], d[r], surf.p[r])
    paths.ng[:, depth] = np.where(env[:, None], 0.0, surf.ng[r])
    paths.ns[:, depth] = paths.ng[:, depth]
    out_paths.append(paths)
    out_e.append(luminance(C))


def _visible_last(scene: BuiltScene, paths: PathBatch) -> NDArray:
    from .paths import edge_visible
    return edge_visible(scene, paths, paths.k - 1)


