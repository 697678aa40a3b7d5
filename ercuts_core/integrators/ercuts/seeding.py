"""Seed paths for the ER chains from fresh BDPT samples, ``seed_samples`` per pixel (paper
§3.2: "at each pixel a fresh bidirectional path"; Mitsuba's ``PathSampler::samplePaths``;
:func:`seed_pixels`).

The BDPT integrator reports every sampled path through its ``on_connections`` callback
(:class:`~ercuts_core.integrators.bdpt.Connection`); :class:`SeedCollector` rebuilds each
as an eye-first :class:`~ercuts_core.integrators.ercuts.paths.PathBatch` x0 … x_k.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ...film import Film
from ...sampling import luminance
from ...lights import AREA, ENV, SUN, TRI
from ...scene import BuiltScene
from ...settings import RenderSettings
from ..bdpt import BDPTIntegrator, Connection, Subpaths
from .paths import PathBatch, contribution, is_target, x1_or_x2_clear


class SeedCollector:
    """The ``on_connections`` callback that keeps every connection as a path.

    Attributes:
        batches: list of (paths, (R,) energies) per BDPT batch of lanes.
    """

    def __init__(self, scene: BuiltScene, n_slots: int):
        self.scene = scene
        self.n_slots = n_slots
        self.batches: list[tuple[PathBatch, NDArray]] = []

    def __call__(self, cam: Subpaths, lig: Subpaths, rows: list[Connection]) -> None:
        self.batches.append(self._paths(cam, lig, rows))

    def _paths(self, cam: Subpaths, lig: Subpaths, rows: list[Connection]) -> tuple[PathBatch, NDArray]:
        """The connection rows of one batch as eye-first paths x0 … x_k."""
        K = self.n_slots
        out = [(self._group(cam, lig, rec), rec.e) for rec in rows if len(rec.lane)]
        if not out:     # a strategy may have no rows in a batch (seen at max_depth <= 4)
            return PathBatch.empty(0, K), np.zeros(0)
        return PathBatch.concat([o[0] for o in out]), np.concatenate([o[1] for o in out])

    def _group(self, cam: Subpaths, lig: Subpaths, rec: Connection) -> PathBatch:
        lights = self.scene.lights
        lane, s, t = rec.lane, rec.s, rec.t
        R = len(lane)
        P = PathBatch.empty(R, self.n_slots)
        rows = np.arange(R)
        # Camera vertices x0 … x_{t−1}
        for j in range(int(t.max())):
            r = np.flatnonzero(t > j)
            _put_vertex(P, r, np.full(len(r), j), cam, np.full(len(r), j), lane[r])
        # Light surface vertices x_t … x_{t+s−2} = y_{s−1} … y_1
        for i in range(int(s.max()) - 1):
            r = np.flatnonzero(s - 1 - i >= 1)
            _put_vertex(P, r, t[r] + i, lig, s[r] - 1 - i, lane[r])
        # The light vertex x_k
        if rec.light_sample is not None:                           # s = 1: the light sample
            k, p_l, n_l, light = t, rec.light_sample.p, rec.light_sample.n, rec.light_sample.light
        elif (s == 0).all():                                       # s = 0: the emitter hit
            k = t - 1
            env = cam.at("env", k, lane)
            vr = cam.rows(k, lane)
            p_l = np.where(env[:, None], -vr.wo, vr.p)
            n_l = np.where(env[:, None], 0.0, vr.ng)
            light = np.full(R, max(lights.env_light, 0))
            light[~env] = lights.tri_light[cam.at("prim", k, lane)[~env]]
        else:                                                      # s ≥ 2: y_0
            k = t + s - 1
            kind = lig.kind0[lane]
            infinite = (kind == SUN) | (kind == ENV)
            on_surf = (kind == AREA) | (kind == TRI)
            p_l = np.where(infinite[:, None], lig.wo[1, lane], lig.p[0, lane])
            n_l = np.where(on_surf[:, None], lig.ng[0, lane], 0.0)
            light = lig.light[lane]
        P.p[rows, k], P.ng[rows, k], P.ns[rows, k] = lights.chain_vertex(light, p_l), n_l, n_l
        P.mat[rows, k] = 0
        P.k[:], P.light[:] = k, light
        P.raster[:] = rec.raster if rec.raster is not None else cam.raster[lane]
        if rec.eye is not None:                          # t = 1: the lens point connected to
            P.p[rows, 0] = rec.eye
        return P


def _put_vertex(P: PathBatch, r: NDArray, slot: NDArray, path: Subpaths, k: NDArray,
                lane: NDArray) -> None:
    """Path rows ``r``, slot ``slot``: vertex ``k`` of subpath ``lane``."""
    vr = path.rows(k, lane)
    P.p[r, slot], P.ng[r, slot], P.ns[r, slot] = vr.p, vr.ng, vr.ns
    P.mat[r, slot] = path.at("mat", k, lane)


def seed_paths(scene: BuiltScene, settings: RenderSettings, rng: np.random.Generator,
               pix: NDArray | None = None, clear_x1: bool = True) -> tuple[PathBatch, NDArray]:
    """Seed paths for the ER chains from one fresh BDPT sample per pixel.

    Every connection strategy with a non-zero, unoccluded MIS-weighted contribution w·C
    becomes one eye-first path (:mod:`~ercuts_core.integrators.ercuts.paths` conventions)
    with energy e = Y(w·C) in image units: camera-sample rows count toward their pixel,
    light-tracing (t = 1) rows are divided by the number of window pixels like their
    splats, so Σe is an unbiased estimate of the image energy Σ_pixels Y. Only target-class
    paths (x2 on a surface, :func:`~ercuts_core.integrators.ercuts.paths.is_target`; x2
    scattering unless ``settings.direct_light`` is 'VPL') with e > 0 are returned.

    Args:
        pix: window pixels to sample (default: all).
        clear_x1: keep paths whose x1 or x2 is on a mirror or glass (False when the gather
            follows the camera through them: :func:`~.paths.x1_or_x2_clear`).
    Returns:
        (S paths with ``settings.max_depth + 2`` slots, (S,) energies).
    """
    K = settings.max_depth + 2
    collect = SeedCollector(scene, K)
    bdpt = BDPTIntegrator(scene, settings, on_connections=collect)
    pix = np.arange(bdpt.window.n_pixels) if pix is None else np.asarray(pix)
    for start in range(0, len(pix), bdpt.max_lanes):
        bdpt.render_batch(Film(bdpt.window), pix[start:start + bdpt.max_lanes], rng)
    parts = [b for b in collect.batches if len(b[0])]
    if not parts:
        return PathBatch.empty(0, K), np.zeros(0)
    paths = PathBatch.concat([b[0] for b in parts])
    e = np.concatenate([b[1] for b in parts])
    keep = is_target(scene, paths, settings.direct_vpls) & (e > 0)
    if scene.has_delta:
        keep &= _no_delta_vertex(scene, paths)
    if not clear_x1:
        keep &= ~x1_or_x2_clear(scene, paths)
    return paths.take(keep), e[keep]


def seed_pixels(n: int, rate: float, rng: np.random.Generator) -> tuple[NDArray, float]:
    """The pixels (sorted, repeated for several samples) whose BDPT samples seed an
    iteration's chains, ``rate`` per pixel on average: every pixel ⌊rate⌋ times and a random
    subset of round(frac(rate)·n) pixels once more (at least one sample in all). Returns
    (the pixel indices, the realised rate q = their count / n): a seed's energy divided by q
    keeps Σ e an unbiased estimate of the image energy, as every pixel is sampled q times
    in expectation (paper §3.2 has one fresh path per pixel, rate 1)."""
    full = int(np.floor(rate + 1e-12))
    extra = int(round((rate - full) * n))
    pix = np.repeat(np.arange(n), full)
    if extra or full == 0:          # no draw at whole rates: rate 1 is the paper's, bit for bit
        pix = np.concatenate([pix, rng.permutation(n)[:max(1, extra)]])
    return np.sort(pix), len(pix) / n


def _no_delta_vertex(scene: BuiltScene, paths: PathBatch) -> NDArray:
    """(S,) False for paths through a mirror or smooth glass: their contribution, evaluated
    without delta lobes (:func:`.paths.contribution`), is 0. Such BDPT paths are no seeds —
    the chains live on paths without delta vertices and ERCUTS path-traces the others. (A
    vertex on a material mixing delta and continuous lobes keeps its continuous part.)"""
    return luminance(contribution(scene, paths)) > 0.0


#: Seed salt of the random order of the seed samples under a time limit (:func:`seed_order`).
SEED_ORDER_SALT = 0x5EED


def seed_order(pix: NDArray, seed: int) -> NDArray:
    """The seed samples ``pix`` (sorted pixel indices, :func:`seed_pixels`) in the
    random order a paced iteration traces them in, so that the samples traced when its seed
    deadline stops it are a uniform random subset of the image's pixels.

    Until stop 49 the *batches* of the sorted list were shuffled instead: the prefix was a
    few random bands of rows (a 1 024-pixel batch is 6 rows at 160×120), the chains started
    in those bands only, and the VPLs lit the image as the paths through those rows see it.
    In the lamp-behind-a-baffle scene at 60 s (4 seed samples per pixel, 64 500–68 600 of
    76 800 traced) that put blotches of +30 % under the baffle and −15 % on the floor; relMSE
    0.0135 / 0.0049 (seeds 0 / 1) against 0.0020 / 0.0016 with one seed sample per pixel,
    which the deadline did not stop."""
    return np.random.default_rng([int(seed), SEED_ORDER_SALT]).permutation(pix)
