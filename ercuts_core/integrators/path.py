"""Reference unidirectional path tracer with next-event estimation and MIS (the oracle).

Wavefront: all paths of a batch advance one bounce per iteration; each bounce is one
``intersect`` call and one ``occluded`` call for the shadow rays. At every vertex the
light is sampled (``LightSet.illuminate``) and the BSDF is sampled; emission found by a
BSDF-sampled ray is weighted against next-event estimation with the power heuristic
[Veach 1997 §9.2; pbrt-v3 PathIntegrator]; after a delta lobe (mirror, smooth glass), which
light sampling cannot produce, the emission gets weight 1 [pbrt-v4 §13.3.1
``specularBounce``]. Lights that cannot be hit by rays (point,
spot, sun, area) get MIS weight 1 in next-event estimation. Russian roulette starts after
``rr_depth`` bounces with survival probability min(1, max(β)) [Arvo & Kirk 1990].

Depth convention (pbrt): ``max_depth`` = number of scattering vertices; 1 = direct light.
Light passes: emission found after ``depth`` bounces has ``depth`` scattering vertices and
next-event estimation at bounce ``depth`` has ``depth + 1``; each is added to the film's
path class (:func:`~ercuts_core.film.path_class`: emission / direct / indirect).
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..bsdf import Bsdf
from ..film import Film
from ..lights import AREA, POINT, SUN
from ..qmc import PassSequence, PixelSequence
from ..sampling import luminance, power_heuristic
from ..vecmath import dot
from .base import Integrator


#: Which paths :class:`PathIntegrator` adds to the film (see its docstring).
PATH_SETS = ("all", "direct_and_delta", "delta", "direct_and_late_delta", "direct_through_prefix",
             "late_delta")
#: The sets classified by the prefix of mirrors and glass from the camera on (class docstring):
#: 'direct_and_late_delta' is the union of the other two, which are disjoint.
PREFIX_SETS = ("direct_and_late_delta", "direct_through_prefix", "late_delta")
#: Most light samples at the first hit (:func:`next_event_stratified`).
MAX_LIGHT_SAMPLES = 8


class PathIntegrator(Integrator):
    """Path tracing with NEE + MIS; see the module docstring.

    ``light_samples`` > 1 averages that many next-event estimates at the first camera hit
    (:func:`next_event_stratified`), sharing the camera ray, the hit and the BSDF sample
    among several shadow rays (ERCUTS's direct-light passes, where soft shadows are most of
    their variance).

    ``paths`` selects the light paths whose contributions are added (the others are still
    traced, so that later vertices are found): 'all'; 'delta', the paths with at least one
    delta vertex (a mirror or smooth glass event: what ERCUTS's VPLs cannot carry); and
    'direct_and_delta', those plus the paths with at most one scattering vertex (light seen
    directly and scattered once: ERCUTS's direct-light passes). 'direct_and_late_delta' is
    the complement of what ERCUTS's gather renders when it follows the camera through
    mirrors and glass (:func:`~.ercuts.vpl.follow_specular`): a path's *prefix* is its run of
    vertices on mirrors and glass (``Bsdf.is_specular_or_glass``) from the camera on, x_d the
    first vertex after it; the set holds the paths with at most one scattering vertex outside
    the prefix (light seen directly, in a mirror or through a window, and direct light at
    x_d), and those with a *late* event: a delta event outside the prefix (caustics, a lamp
    behind glass) or the vertex after x_d on a mirror or glass (where no VPL can sit). It is
    the union of two disjoint sets: 'direct_through_prefix', its paths without a late event,
    and 'late_delta', those with one (ERCUTS renders the first by path tracing, the second
    by BDPT: :mod:`~.ercuts.late_paths`). Without delta materials in the scene
    (``BuiltScene.has_delta``; for the last three sets, without mirrors and glass,
    ``has_specular_or_glass``) these sets stop after the first bounce.
    """

    def __init__(self, scene, settings, paths: str = "all", light_samples: int = 1):
        super().__init__(scene, settings)
        if paths not in PATH_SETS:
            raise ValueError(f"unknown path set {paths!r}; expected one of {PATH_SETS}")
        self.paths = paths
        #: light samples of next-event estimation at the first camera hit (one elsewhere):
        #: :func:`next_event_stratified`; may change between passes (:meth:`set_light_samples`)
        self.light_samples = 1
        #: (first padded point, first pass) of the passes with this many light samples
        self._light_run = (0, 0)
        self.set_light_samples(light_samples, 0)
        #: (h·w,) or None: when an array and light_samples ≥ 2, every pass adds each pixel's
        #: sample variance of one light sample's luminance at its first hit (the within-hit
        #: part of a pass's variance, :func:`~.ercuts.balance.light_samples_for`)
        self.light_spread: NDArray | None = None
        self.max_depth = settings.max_depth
        if paths != "all" and not (scene.has_specular_or_glass if paths in PREFIX_SETS
                                   else scene.has_delta):
            self.max_depth = min(self.max_depth, 1)

    def set_light_samples(self, k: int, passes_done: int) -> None:
        """Take ``k`` light samples at the first hit from pass ``passes_done`` on; its padded
        points continue where the earlier passes' ended (a consecutive run,
        :meth:`~ercuts_core.qmc.PixelSequence.padded`)."""
        if not 1 <= k <= MAX_LIGHT_SAMPLES:
            raise ValueError(f"light_samples must be in 1 … {MAX_LIGHT_SAMPLES}, got {k}")
        point, first = self._light_run
        self._light_run = (point + (passes_done - first) * self.light_samples, passes_done)
        self.light_samples = int(k)

    def _counted(self, scatter: int, seen: NDArray, late: NDArray, nd: NDArray) -> NDArray:
        """(N,) bool: which of a bounce's contributions with ``scatter`` scattering vertices
        are added, from ``seen`` (N,) (the path has a delta vertex), ``late`` (N,) (it has
        a late one, see the class docstring) and ``nd`` (N,) (its scattering vertices outside
        the prefix of mirrors and glass)."""
        if self.paths == "all":
            return np.ones(len(seen), bool)
        if self.paths == "delta":
            return seen
        if self.paths == "direct_and_late_delta":
            return late | (nd <= 1)
        if self.paths == "direct_through_prefix":
            return ~late & (nd <= 1)
        if self.paths == "late_delta":
            return late
        return seen | (scatter <= 1)

    def _may_still_count(self, late: NDArray, nd: NDArray, prefix_set: bool) -> NDArray | None:
        """(N,) bool: which paths, after a bounce, can still add to this path set (None: any
        may), from ``late`` (N,) and ``nd`` (N,) (:meth:`_counted`); ``prefix_set``: the set
        is one of :data:`PREFIX_SETS`. 'direct_through_prefix' counts nothing after x_(d+1)
        and no late path; the other prefix sets, in a scene without delta lobes, count nothing
        after x_(d+1) unless the path is late already, which nothing after it can make it."""
        if self.paths == "direct_through_prefix":
            return ~late & (nd < 2)
        if prefix_set and not self.scene.has_delta:
            return late | (nd < 2)
        return None

    def render_batch(self, film: Film, pix: NDArray, rng: np.random.Generator,
                     sequence: PassSequence | None = None) -> None:
        """One sample per pixel ``pix`` (N,) into ``film``; its numbers come from ``sequence``
        (the pass's randomised Sobol point, :mod:`ercuts_core.qmc`) when given, else from
        ``rng`` alone."""
        scene, s = self.scene, self.settings
        lights, tracer = scene.lights, scene.tracer
        n = len(pix)
        u = sequence.bind(pix, rng) if sequence is not None else None
        o, d = self.camera_rays(pix, rng, u)
        L = np.zeros((3, n, 3))            # radiance by path class (emission, direct, indirect)
        beta = np.ones((n, 3))
        idx = np.arange(n)                 # lane → sample
        prev_pdf = np.zeros(n)             # BSDF pdf of the ray that led here (0: camera ray)
        prev_delta = np.zeros(n, bool)     # that ray came from a delta lobe (no MIS: weight 1)
        seen = np.zeros(n, bool)           # the path so far has a delta vertex
        late = np.zeros(n, bool)           # … a late event (class docstring)
        nd = np.zeros(n, np.int64)         # vertices so far outside that prefix
        prev_p = np.zeros((n, 3))
        alpha = None
        for depth in range(self.max_depth + 1):
            counted = self._counted(depth, seen, late, nd)
            surf = scene.intersect(o, d)
            if depth == 0:
                alpha = self.alpha(surf)
            hit = surf.valid
            if depth > 0 and lights.has_shapes and prev_delta.any():
                self._lights_seen(L[min(depth, 2)], idx, o, d, surf, prev_delta & counted, beta)
            # Emission seen by this ray: environment on misses, emissive triangles on hits.
            if lights.env_light >= 0 and (~hit).any():
                m = ~hit
                Le = lights.env_radiance(d[m])
                w = np.ones(int(m.sum()))
                if depth > 0:
                    w = np.where(prev_delta[m], 1.0,
                                 power_heuristic(prev_pdf[m], lights.pdf_illuminate_env(d[m])))
                visible_env = not (depth == 0 and s.film_transparent)
                w = w * counted[m]
                if visible_env:
                    L[min(depth, 2), idx[m]] += beta[m] * Le * w[:, None]
            if hit.any() and len(lights.emissive_tris):
                Le = scene.emission(surf)
                em = hit & (Le.max(axis=1) > 0)
                if em.any():
                    w = np.ones(int(em.sum()))
                    if depth > 0:
                        pdf_l = lights.pdf_illuminate_tri(prev_p[em], surf.prim[em], surf.p[em], surf.ng[em])
                        w = np.where(prev_delta[em], 1.0, power_heuristic(prev_pdf[em], pdf_l))
                    w = w * counted[em]
                    L[min(depth, 2), idx[em]] += beta[em] * Le[em] * w[:, None]
            # Keep only paths that hit something and may scatter again.
            if depth == self.max_depth:
                if depth == 0:
                    keep = np.flatnonzero(hit)
                    self.record_first_hit(film, pix, keep, surf.subset(keep), None)
                break
            keep = np.flatnonzero(hit)
            surf, d, beta, idx = surf.subset(keep), d[keep], beta[keep], idx[keep]
            seen, late, nd = seen[keep], late[keep], nd[keep]
            wo = -d
            bsdf = scene.bsdf(surf.mat, surf.ns, surf.ng, surf.p)
            if depth == 0:
                self.record_first_hit(film, pix, keep, surf, bsdf)
            if len(idx) == 0:
                break
            clear = bsdf.is_specular_or_glass if self.paths in PREFIX_SETS else None
            if clear is not None:       # a VPL cannot sit on the mirror or glass after x_d
                late = late | (clear & (nd == 1))
            nee = self._counted(depth + 1, seen, late, nd + 1)
            k = self.light_samples if depth == 0 else 1
            if not lights.empty and nee.any():
                record = depth == 0 and k >= 2 and self.light_spread is not None
                start = None if u is None else self._light_run[0] + (u.seq.index - self._light_run[1]) * k
                L_nee, var = next_event_stratified(scene, surf, wo, bsdf, rng, k, u, idx, spread=record,
                                                   start=start)
                L[min(depth + 1, 2), idx] += beta * L_nee * nee[:, None]
                if record:
                    self.light_spread += np.bincount(pix[idx], weights=var * nee,
                                                     minlength=len(self.light_spread))
            elif u is not None:         # drawn either way: fixed dimensions
                u.take(idx, 3)
            # Sample the BSDF for the next bounce.
            bs = bsdf.sample(wo, rng.random((len(idx), 3)) if u is None else u.take(idx, 3))
            beta = beta * bs.weight
            alive = bs.valid & (beta.max(axis=1) > 0)
            if depth + 1 >= s.rr_depth:
                q = np.minimum(1.0, beta.max(axis=1))
                survive = (rng.random(len(idx)) if u is None else u.take(idx, 1)[:, 0]) < q
                beta = beta / np.where(survive, q, 1.0)[:, None]
                alive &= survive
            keep = np.flatnonzero(alive)
            if len(keep) == 0:
                break
            surf, beta, idx = surf.subset(keep), beta[keep], idx[keep]
            prefix = clear & (nd == 0) if clear is not None else np.zeros(len(nd), bool)
            late = (late | (bs.is_delta & ~prefix))[keep]
            nd = (nd + ~prefix)[keep]
            go = self._may_still_count(late, nd, clear is not None)
            if go is not None:
                go = np.flatnonzero(go)
                surf, beta, idx, keep = surf.subset(go), beta[go], idx[go], keep[go]
                late, nd = late[go], nd[go]
            seen = seen[keep] | bs.is_delta[keep]
            d = bs.wi[keep]
            prev_pdf, prev_p, prev_delta = bs.pdf[keep], surf.p, bs.is_delta[keep]
            o = tracer.offset(surf.p, surf.ng, d)
        film.add_samples(pix, L.sum(axis=0), alpha, parts=L)

    def _lights_seen(self, L: NDArray, idx: NDArray, o: NDArray, d: NDArray, surf, lanes: NDArray,
                     beta: NDArray) -> None:
        """Add to L[idx] the area, soft point and sun-cone lights that the rays (o, d) of
        ``lanes`` (N,) bool meet before their hit: after a delta event next-event estimation
        cannot reach them, so this is their only estimator there (weight 1)."""
        r = np.flatnonzero(lanes)
        if len(r) == 0:
            return
        t = np.where(surf.valid[r], surf.t[r], np.inf)
        L[idx[r]] += beta[r] * self.scene.lights.radiance_along(o[r], d[r], t)


def next_event_stratified(scene, surf, wo: NDArray, bsdf: Bsdf, rng: np.random.Generator, k: int,
                          u: PixelSequence | None = None, lanes: NDArray | None = None,
                          spread: bool = False, start: int | None = None) -> tuple[NDArray, NDArray | None]:
    """The mean of ``k`` ≤ :data:`MAX_LIGHT_SAMPLES` next-event estimates (:func:`next_event`,
    with MIS) at the same surfaces, and with ``spread`` their sample variance.

    With the pass's quasi-random numbers ``u`` the k estimates take points ``start`` …
    ``start`` + k − 1 of the samples ``lanes``' (N,) padded Sobol sequence in the next three
    dimensions (:meth:`~ercuts_core.qmc.PixelSequence.padded`: stratified with one another and
    with the light samples of the other passes), else k independent ones from ``rng``. Every
    estimate is unbiased and keeps its one-sample MIS weight against the BSDF sample, so the
    weights of a path still sum to one and the mean is unbiased (weights with k·p_light, the
    multi-sample heuristic of Veach 1997 §9.2.4, would be slightly better). k = 1 is
    :func:`next_event` with the pass's next three dimensions.

    Returns:
        ((N, 3) the mean, (N,) the estimates' sample variance of luminance (Σ (Y_j − Ȳ)²/(k − 1),
        an estimate of one light sample's variance; None unless ``spread`` and k ≥ 2)).
    """
    if k == 1:
        return next_event(scene, surf, wo, bsdf, rng, u=None if u is None else u.take(lanes, 3)), None
    points = [None] * k if u is None else u.padded(lanes, 3, k, start)
    total, y1, y2 = np.zeros((len(wo), 3)), np.zeros(len(wo)), np.zeros(len(wo))
    for p in points:
        e = next_event(scene, surf, wo, bsdf, rng, u=p)
        total += e
        if spread:
            y = luminance(e)
            y1 += y
            y2 += y * y
    var = np.maximum(y2 - y1 * y1 / k, 0.0) / (k - 1) if spread else None
    return total / k, var


def next_event(scene, surf, wo: NDArray, bsdf: Bsdf, rng: np.random.Generator, mis: bool = True,
               u: NDArray | None = None) -> NDArray:
    """(N, 3) direct light at the surfaces ``surf`` (p, ns, ng) toward ``wo``: f·|cos|·Li·V·w/pdf,
    one light sample each. ``w`` is the power heuristic against BSDF sampling for lights a
    BSDF-sampled ray can hit (emissive triangles, the world) [Veach 1997 §9.2]; with ``mis``
    False it is 1 — the whole direct light by light sampling, for callers that do not also
    trace BSDF rays to the lights (the clamp's bias compensation, :mod:`.ercuts.bias_compensation`).
    ``u`` (N, 3): the light choice's and the light point's uniforms (default: from ``rng``)."""
    lights, tracer = scene.lights, scene.tracer
    n = len(wo)
    u_sel, u_pos = (rng.random(n), rng.random((n, 2))) if u is None else (u[:, 0], u[:, 1:3])
    ls = lights.illuminate(surf.p, u_sel, u_pos)
    f, pdf_bsdf = bsdf.eval_pdf(wo, ls.wi)
    cos = np.abs(dot(surf.ns, ls.wi))
    contrib = f * (cos / np.where(ls.valid, ls.pdf_w, 1.0))[:, None] * ls.Li
    if mis:
        kind = lights.kind[ls.light]
        nee_only = (kind == POINT) | (kind == SUN) | (kind == AREA)
        contrib *= np.where(nee_only, 1.0, power_heuristic(ls.pdf_w, pdf_bsdf))[:, None]
    test = ls.valid & (contrib.max(axis=1) > 0)
    out = np.zeros((n, 3))
    if test.any():
        t = np.flatnonzero(test)
        infinite = ~np.isfinite(ls.dist[t])
        target = np.where(infinite[:, None], surf.p[t] + ls.wi[t] * 4.0 * scene.scene_radius, ls.p[t])
        # Surface emitters (area, tri) need their end offset; points and infinite lights do not.
        on_surface = ~infinite & (np.abs(ls.n[t]).sum(axis=1) > 0)
        vis = np.empty(len(t), bool)
        if on_surface.any():
            a = np.flatnonzero(on_surface)
            vis[a] = tracer.visible(surf.p[t[a]], surf.ng[t[a]], target[a], ls.n[t[a]])
        if (~on_surface).any():
            b = np.flatnonzero(~on_surface)
            vis[b] = tracer.visible(surf.p[t[b]], surf.ng[t[b]], target[b], None)
        out[t[vis]] = contrib[t[vis]]
    return out


def emission_found(scene, o: NDArray, d: NDArray, pdf: NDArray, delta: NDArray, surf) -> NDArray:
    """(N, 3) the emission that BSDF-sampled rays (o, d) find — the world on a miss, an
    emissive triangle at the hit ``surf`` — weighted by the power heuristic against
    :func:`next_event`'s light sample (weight 1 after a delta lobe) [Veach 1997 §9.2]: the
    BSDF half of the MIS estimate of the direct light at the rays' origins. ``pdf`` (N,) the
    rays' solid-angle densities, ``delta`` (N,) bool."""
    lights = scene.lights
    out = np.zeros((len(d), 3))
    miss = ~surf.valid
    if lights.env_light >= 0 and miss.any():
        w = power_heuristic(pdf[miss], lights.pdf_illuminate_env(d[miss]))
        out[miss] = lights.env_radiance(d[miss]) * np.where(delta[miss], 1.0, w)[:, None]
    if len(lights.emissive_tris) and surf.valid.any():
        Le = scene.emission(surf)
        em = np.flatnonzero(surf.valid & (Le.max(axis=1) > 0))
        if len(em):
            pdf_l = lights.pdf_illuminate_tri(o[em], surf.prim[em], surf.p[em], surf.ng[em])
            w = np.where(delta[em], 1.0, power_heuristic(pdf[em], pdf_l))
            out[em] = Le[em] * w[:, None]
    return out
