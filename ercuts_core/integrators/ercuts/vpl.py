"""Paper step 3 — VPLs from the chains, and their intensity normalisation.

Each VPL sits at a chain's x2 with the geometric normal facing x1 and emits like a small
diffuse patch: intensity I·max(0, n·ω) [Keller 1997]. The paper gives it raw intensity
k (its number of chain states) and real intensity k·P/(n·P*) with P* its rendered image
energy. Following algorithm.md §G.4 we measure P* at *unit* intensity, E1(v) = Σ_pixels
Y(image of v alone with colour c_v), so that I_v = k_v·e_d/E1(v)·c_v (e_d = P/n): every
chain state then carries exactly its share e_d of the image energy.

E1 is estimated by tracing the VPL's own emission one bounce to the camera, a share of the
samples paired with a pixel sample near the VPL's home pixel by the balance heuristic (for
VPLs whose emission mostly misses what the camera sees; :func:`estimate_e1_light_tracing`,
:data:`PIXEL_SAMPLE_RATE`), with the budget of M samples per VPL shared out by a
pilot so that VPLs whose light rarely reaches the camera get more
(:func:`estimate_e1_allocated`): 1/Ê1 has a Jensen bias E[1/Ê1] ≈ (1/E1)(1 + c_v/N_v) that
made the VPL image up to 25 % too bright in the S-corridor with 256 samples per VPL
(benchmarks/results/e1_bias.md); the allocation and a first-order correction
(:data:`E1_BIAS_CORRECTION`) remove most of it. Where nothing is found, M shading points drawn from a
mixture of the whole window and a neighbourhood of the VPL's home pixel (where the VPL
certainly shines), one-sample MIS over the mixture [Veach 1997 §9.2.2] (:func:`estimate_e1`).
The shading uses the *same* BRDF, visibility and geometry clamp as the final gather, as
the rule in algorithm.md §D.4 requires, and E1 is the sum of *pixel values* — integrals
over the pixel — which the gather estimates with jittered shading points
(:func:`build_gbuffer`). When the gather compensates the clamp (the default,
:mod:`.bias_compensation`) the gather's image is the unclamped one in expectation, so E1 is
estimated without the clamp (``gmax`` = inf): with the clamped E1 every VPL's clamped energy
was moved from the edges it lights at short range onto the rest of its image (the door
scene: a band 10–25 % too dark along every edge, the open walls ≈ 5 % too bright).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ...arrays import take_rows
from ...camera import Window
from ...sampling import luminance
from ...scene import BuiltScene, Surface
from ...vecmath import dot
from .er_sampling import ChainResult


@dataclass
class GBuffer:
    """First hits of camera rays: the shading points of the gather.

    Attributes:
        pixel: (Q,) window pixel index of each point (S points per pixel).
        p, ng, ns, wo: (Q, 3) hit position, normals (ns flipped toward wo), direction to eye.
        mat: (Q,) material row; valid: (Q,) the ray hit a surface.
        surf: the raw :class:`Surface` (unflipped normals, for emission lookups).
        samples: shading points per pixel (S).
        weight: (Q, 3) throughput of the perfect mirrors and smooth glass between the camera
            and the point (:func:`follow_specular`), None for first hits (weight 1).
        through: (Q,) bool, the point was reached through such surfaces (None: none was).
    """

    pixel: NDArray
    p: NDArray
    ng: NDArray
    ns: NDArray
    wo: NDArray
    mat: NDArray
    valid: NDArray
    surf: Surface
    samples: int
    weight: NDArray | None = None
    through: NDArray | None = None


#: Camera rays per G-buffer chunk (≈ 0.35 s of tracing and shading on 2 cores).
GBUFFER_CHUNK = 1 << 19


def build_gbuffer(scene: BuiltScene, samples: int, rng: np.random.Generator,
                  jitter: NDArray | None = None, poll=None) -> tuple[GBuffer, NDArray]:
    """Trace ``samples`` jittered camera rays per window pixel; returns the G-buffer and rays' d.

    ``poll(fraction)`` is called once the camera rays are generated and after every
    :data:`GBUFFER_CHUNK` rays (a 1080p G-buffer takes ≈ 1.4 s on 2 cores: progress and Esc
    stay responsive); it may raise to stop.

    ``jitter``: (n_pixels·samples, 2) positions in the pixel, in [0, 1)² (default: uniform
    random from ``rng``; progressive renders pass stratified ones,
    :func:`~.progressive.stratified_jitter`).

    Jittered also for one sample per pixel: the pixel value is then an unbiased estimate of
    the pixel's integral — what the rough BDPT image (P) and the light-traced Ê1 measure. A
    point at the pixel centre samples the image instead, which misses or over-weights
    sub-pixel light (a VPL lighting a sliver beside a silhouette) and biased the VPL image
    energy by −12 % (Cornell box) to +11 % (door scene) (benchmarks/results/e1_bias.md).
    """
    w = scene.camera.window
    pix = np.repeat(np.arange(w.n_pixels), samples)
    raster = w.raster(pix).astype(np.float64)
    raster += rng.random((len(pix), 2)) if jitter is None else jitter
    o, d = scene.camera.generate_rays(raster, scene.camera.lens_samples(rng, len(pix)))
    if poll is not None:
        poll(0.0)
    parts = []
    for start in range(0, max(len(pix), 1), GBUFFER_CHUNK):
        parts.append(scene.intersect(o[start:start + GBUFFER_CHUNK], d[start:start + GBUFFER_CHUNK]))
        if poll is not None:
            poll(min(start + GBUFFER_CHUNK, len(pix)) / max(len(pix), 1))
    surf = parts[0] if len(parts) == 1 else Surface.concat(parts)
    wo = -d
    flip = dot(surf.ng, wo) < 0
    sign = np.where(flip, -1.0, 1.0)[:, None]
    return GBuffer(pix, surf.p, surf.ng * sign, surf.ns * sign, wo, surf.mat, surf.valid, surf, samples), d


#: Perfect mirrors and glass surfaces followed from the camera at most (:func:`follow_specular`);
#: a point still on one after as many is dropped (its light is lost: a hall of mirrors).
SPECULAR_BOUNCES = 16


def follow_specular(scene: BuiltScene, g: GBuffer, rng: np.random.Generator,
                    max_bounces: int = SPECULAR_BOUNCES) -> GBuffer:
    """Move ``g``'s points on perfect mirrors and glass (smooth or rough: every lobe a delta
    or a dielectric lobe, :attr:`~ercuts_core.bsdf.Bsdf.is_specular_or_glass`) along the camera
    path to the first surface that is not one (algorithm.md §G.3; Keller's and pbrt-v2's IGI
    follow SpecularReflect/Transmit the same way), so that the gather shades what a mirror
    shows or a window lets through with the VPLs instead of leaving it to a path tracer (a
    VPL cannot shine through glass: a glass ball gathered at its surface stayed dark).
    Returns ``g``, changed in place (a copy would cost ≈ 200 bytes per point, 400 MiB at
    1080p): take what needs the first hits (AOVs, alpha) before.

    At every such point the BSDF is sampled once (glass: reflection or refraction with the
    Fresnel probability) and ``weight`` (Q, 3) multiplies the sample weights f·|cos|/pdf
    (the mirror's F, the glass tint and 1/η² of radiance transport; the estimate of the pixel
    stays unbiased, Veach 1997 §5.2). Points whose path leaves the scene, is absorbed or is still on
    a delta surface after ``max_bounces`` become invalid: what they see — emitters, the world,
    lights in the mirror — and the direct light at the point reached are the direct-light
    passes' (``PathIntegrator(paths='direct_and_late_delta')``). Materials with a diffuse or
    opaque specular lobe besides (a smooth coat on a diffuse base) are not followed: their
    delta event stays a path-traced path. ``through`` marks the moved points (see :func:`first_hits_only`)."""
    g.weight, g.through = np.ones((len(g.pixel), 3)), np.zeros(len(g.pixel), bool)
    if not scene.has_specular_or_glass:
        return g
    surf, wo, weight, through = g.surf, g.wo, g.weight, g.through
    lanes = np.flatnonzero(surf.valid)
    for bounce in range(max(max_bounces, 0) + 1):
        if len(lanes) == 0:
            break
        bsdf = scene.bsdf(surf.mat[lanes], surf.ns[lanes], surf.ng[lanes], surf.p[lanes])
        clear = bsdf.is_specular_or_glass
        lanes, bsdf = lanes[clear], bsdf.subset(clear)
        if len(lanes) == 0 or bounce == max_bounces:
            surf.valid[lanes] = False
            break
        bs = bsdf.sample(wo[lanes], rng.random((len(lanes), 3)))
        weight[lanes] *= bs.weight
        through[lanes] = True
        ok = bs.valid & (weight[lanes].max(axis=1) > 0)
        surf.valid[lanes[~ok]] = False
        lanes, wi = lanes[ok], bs.wi[ok]
        nxt = scene.intersect(scene.tracer.offset(surf.p[lanes], surf.ng[lanes], wi), wi)
        surf.valid[lanes[~nxt.valid]] = False
        hit = np.flatnonzero(nxt.valid)
        lanes, nxt = lanes[hit], nxt.subset(hit)
        for name in ("p", "ng", "ns", "prim", "mat"):
            getattr(surf, name)[lanes] = getattr(nxt, name)
        surf.t[lanes] += nxt.t
        wo[lanes] = -wi[hit]
        sign = np.where(dot(nxt.ng, wo[lanes]) < 0, -1.0, 1.0)[:, None]
        g.p[lanes], g.ng[lanes], g.ns[lanes], g.mat[lanes] = nxt.p, nxt.ng * sign, nxt.ns * sign, nxt.mat
    g.valid = surf.valid
    weight[~g.valid] = 0.0
    return g


def first_hits_only(g: GBuffer) -> GBuffer:
    """``g`` without the points :func:`follow_specular` moved (a view: they are invalid): the
    shading points of delta-free camera paths, which E1 measures (P leaves the others out)."""
    if g.through is None or not g.through.any():
        return g
    return dataclasses.replace(g, valid=g.valid & ~g.through)


def g_clamp(scene: BuiltScene, clamp: float) -> float:
    """Geometry-term clamp: cosθ_v/d² ≤ 1/(clamp·diagonal)²; 0 disables (returns inf)."""
    if clamp <= 0:
        return np.inf
    return 1.0 / (clamp * 2.0 * scene.scene_radius) ** 2


def clamp_factor(gmax: float, d2: NDArray, cos_v: NDArray) -> NDArray:
    """(n,) min(1, g_max·d²/cosθ_v): the share of a VPL's geometry term cosθ_v/d² that the
    clamp g_max keeps; 1 without a clamp (g_max = inf, where inf·0 would give NaN)."""
    if not np.isfinite(gmax):
        return np.ones(np.shape(d2))
    return np.minimum(1.0, gmax * d2 / np.maximum(cos_v, 1e-300))


def vpl_radiance(scene: BuiltScene, g: GBuffer, pts: NDArray, pos: NDArray, normal: NDArray,
                 intensity: NDArray, gmax: float) -> tuple[NDArray, NDArray]:
    """Radiance at shading points ``pts`` from VPLs (pos, normal, intensity), one pair per row.

    Returns:
        (n, 3) f·|cos_x|·min(cos_v/d², gmax)·V·I, and (n,) the luminance removed by the clamp.
    """
    x = g.p[pts]
    d = pos - x
    dist2 = dot(d, d)
    wi = d / np.sqrt(np.maximum(dist2, 1e-300))[:, None]
    cos_v = np.maximum(-dot(normal, wi), 0.0)
    geo = cos_v / np.maximum(dist2, 1e-300)
    geo_c = np.minimum(geo, gmax)
    bsdf = scene.bsdf(g.mat[pts], g.ns[pts], g.ng[pts], g.p[pts])
    m = bsdf.eval(g.wo[pts], wi) * np.abs(dot(g.ns[pts], wi))[:, None]
    L = m * (geo_c[:, None] * intensity)
    test = g.valid[pts] & (L.max(axis=1) > 0)
    vis = np.zeros(len(pts), bool)
    if test.any():
        t = np.flatnonzero(test)
        vis[t] = scene.tracer.visible(x[t], g.ng[pts[t]], pos[t], normal[t])
    L = L * vis[:, None]
    lost = luminance(m * ((geo - geo_c)[:, None] * intensity)) * vis
    return L, lost


@dataclass
class VPLSet:
    """Normalised VPLs ready for the light tree.

    Attributes:
        position, normal: (V, 3); intensity: (V, 3) RGB [W/sr at normal incidence].
        count: (V,) deposits; e1: (V,) estimated image energy at unit intensity.
        fallback: (h·w, 3) image of the states whose VPL lit no sampled pixel (splatted
            ERPT-style at their home pixel so that no energy is lost).
        emitter: (V,) bool, the VPL sits on its paths' light vertex (carries direct light).
        fallback_emitter: (h·w, 3) the part of ``fallback`` from such VPLs.
    """

    position: NDArray
    normal: NDArray
    intensity: NDArray
    count: NDArray
    e1: NDArray
    fallback: NDArray
    emitter: NDArray | None = None
    fallback_emitter: NDArray | None = None

    def __len__(self) -> int:
        return len(self.count)


def _chunks(V: int, n_samples, chunk: int):
    """Yield (v, vv, s): VPL ids of a chunk, each repeated ``n_samples`` times (an int, or
    (V,) counts per VPL), and its start; a chunk holds about ``chunk`` samples (≥ 1 VPL)."""
    if np.ndim(n_samples) == 0:
        per = max(1, chunk // int(n_samples))
        for s in range(0, V, per):
            v = np.arange(s, min(V, s + per))
            yield v, np.repeat(v, n_samples), s
        return
    counts = np.asarray(n_samples, np.int64)
    cum = np.concatenate([[0], np.cumsum(counts)])
    s = 0
    while s < V:
        e = max(s + 1, int(np.searchsorted(cum, cum[s] + chunk, side="right")) - 1)
        v = np.arange(s, min(V, e))
        yield v, np.repeat(v, counts[v]), s
        s = min(V, e)


#: Half-width [pixels] of the neighbourhood of a VPL's home pixel (its x1 when the chain
#: made it, where it certainly shines) that its pixel samples favour (:class:`PixelMixture`),
#: for a window :data:`HOME_RADIUS_WIDTH` pixels wide; wider windows scale it
#: (:func:`home_radius`).
HOME_RADIUS = 8
#: Window width [pixels] at which the neighbourhood's half-width is :data:`HOME_RADIUS`.
HOME_RADIUS_WIDTH = 160


def home_radius(window: Window) -> int:
    """The neighbourhood's half-width for ``window``: HOME_RADIUS · width / HOME_RADIUS_WIDTH,
    at least HOME_RADIUS, so that it covers the same share of a wide image as of a 160-wide one.

    With a fixed 8 pixels (stop 48 and before) it covered 1.5 % of a 160×120 image and
    0.09 % of a 640×480 one, and there the VPL image came out 25 % brighter than P (door,
    640×480, 60 s, seed 0: ``vpl_energy_ratio`` 1.245, image energy 1.22, relMSE 0.060
    against the 160×120 reference); bisected to the commit that added the pixel samples
    (ec7cb87). With the radius scaled (32 there): 1.018, 1.033, 0.013; without pixel samples
    (ρ = 0): 1.015, 1.03, 0.011. Renders up to HOME_RADIUS_WIDTH wide are unchanged."""
    return max(HOME_RADIUS, int(round(HOME_RADIUS * window.width / HOME_RADIUS_WIDTH)))


@dataclass
class PixelMixture:
    """The pixel density of a VPL's camera-side samples: half uniform over the window, half
    uniform over the (2r+1)² pixels around its home pixel (clipped to the window), the
    one-sample mixture of Veach 1997 §9.2.2. ``x0``, ``x1``, ``y0``, ``y1``, ``size``: (V,)
    the neighbourhoods' inclusive bounds (window columns and rows) and pixel counts."""

    window: Window
    x0: NDArray
    x1: NDArray
    y0: NDArray
    y1: NDArray
    size: NDArray

    @classmethod
    def around(cls, window: Window, home: NDArray, radius: int | None = None) -> "PixelMixture":
        """The mixtures of VPLs with home raster positions ``home`` (V, 2), their
        neighbourhoods ``radius`` pixels wide each way (default :func:`home_radius`)."""
        radius = home_radius(window) if radius is None else radius
        hx, hy = window.pixel_xy(home, clip=True)
        x0, x1 = np.maximum(hx - radius, 0), np.minimum(hx + radius, window.width - 1)
        y0, y1 = np.maximum(hy - radius, 0), np.minimum(hy + radius, window.height - 1)
        return cls(window, x0, x1, y0, y1, (x1 - x0 + 1) * (y1 - y0 + 1))

    def sample(self, vv: NDArray, rng: np.random.Generator) -> tuple[NDArray, NDArray]:
        """(n,) window column and row of one pixel per entry of ``vv`` (VPL ids)."""
        w, n = self.window, len(vv)
        local = rng.random(n) < 0.5
        px = np.where(local, self.x0[vv] + (rng.random(n) * (self.x1 - self.x0 + 1)[vv]).astype(np.int64),
                      rng.integers(0, w.width, n))
        py = np.where(local, self.y0[vv] + (rng.random(n) * (self.y1 - self.y0 + 1)[vv]).astype(np.int64),
                      rng.integers(0, w.height, n))
        return np.minimum(px, w.width - 1), np.minimum(py, w.height - 1)

    def pmf(self, vv: NDArray, px: NDArray, py: NDArray) -> NDArray:
        """(n,) probability of window pixel (px, py) under VPL ``vv``'s mixture."""
        inside = (px >= self.x0[vv]) & (px <= self.x1[vv]) & (py >= self.y0[vv]) & (py <= self.y1[vv])
        return 0.5 / self.window.n_pixels + 0.5 * inside / self.size[vv]


def estimate_e1(scene: BuiltScene, g: GBuffer, window: Window, pos: NDArray, normal: NDArray,
                color: NDArray, home: NDArray, gmax: float, n_samples: int, rng: np.random.Generator,
                radius: int | None = None, chunk: int = 1 << 18) -> NDArray:
    """(V,) Ê1: Σ over window pixels of Y(pixel value of a unit VPL), the pixels drawn from
    :class:`PixelMixture` and one of the G-buffer's shading points in each."""
    V = len(pos)
    S = g.samples
    mix = PixelMixture.around(window, home, radius)
    total = np.zeros(V)
    for v, vv, s in _chunks(V, n_samples, chunk):
        n = len(vv)
        px, py = mix.sample(vv, rng)
        q = mix.pmf(vv, px, py)
        pts = (py * window.width + px) * S + rng.integers(0, S, n)     # one of the pixel's points
        L, _ = vpl_radiance(scene, g, pts, pos[vv], normal[vv], color[vv], gmax)
        total[v] = np.bincount(vv - s, weights=luminance(L) / q, minlength=len(v)) / n_samples
    return total


def estimate_e1_light_tracing(scene: BuiltScene, pos: NDArray, normal: NDArray, color: NDArray,
                              gmax: float, n_samples: int, rng: np.random.Generator,
                              chunk: int = 1 << 18, keep_going=None, moments: bool = False,
                              clear_receivers: bool = True, halves: bool = False,
                              home: NDArray | None = None):
    """(V,) Ê1 by tracing the VPL's own cosine emission one bounce to the camera; with
    ``home`` (V, 2) (the VPLs' home raster positions) and a pinhole camera, a share
    :data:`PIXEL_SAMPLE_RATE` of the samples also take a pixel sample (:func:`_camera_side`,
    :class:`PixelMixture`), combined by the balance heuristic (Veach 1997 §9.2;
    :func:`uses_pixel_samples`).

    E1 = ∫_Ω f_r(y)·cosθ_v·|n_g(y)·ω_cam|·F(y)·V dω with F = 1/(A_pix·cos³θ·d_cam²) the
    camera connection factor (Camera.connect); with cosine sampling (pdf cosθ_v/π) a sample
    is π·f_r(y)·(|n_s·ω_in|/|n_g·ω_in|)·|n_g·ω_cam|·F(y)·V_cam, times min(1, g_max·d²/cosθ_v)
    for the geometry clamp. Bounded for diffuse receivers away from the lens, unlike
    sampling pixels, whose samples near the VPL carry the 1/d² peak.
    ``keep_going(fraction) -> bool`` is called after each chunk; False stops (the rest stay 0).
    With ``moments``, returns (Ê1, (V,) mean of the squared samples) instead, and with
    ``halves`` too, (Ê1, mean of squares, (2, V) means of each VPL's even- and odd-numbered
    samples: the jackknife's halves, :func:`jackknife_e1`). With ``clear_receivers`` False, receivers on mirrors and glass count 0 (the gather follows the
    camera through them, :func:`follow_specular`, so a VPL's image there is not its own).

    Light tracing alone is heavy-tailed where a VPL's emission mostly leaves the scene or
    lands out of view: a floor VPL of tests/blender/test_gltf_cycles.py's open scene hit
    anything with 0.6 % of its samples (relative variance 212 per sample), and 256 samples
    put its Ê1 at 0.0025 against 0.58 — that VPL alone made the image 15 % too bright. Its
    light lands where its chain's x1 was, so pixels around the home pixel find it.
    """
    from ...sampling import coordinate_system, sample_cosine_hemisphere, to_world
    cam = scene.camera
    V = len(pos)
    total = np.zeros(V)
    total2 = np.zeros(V)
    half = np.zeros((2, V))
    mix = PixelMixture.around(cam.window, home) if home is not None and uses_pixel_samples(cam) else None
    for v, vv, s in _chunks(V, n_samples, chunk):
        n = len(vv)
        local = sample_cosine_hemisphere(rng.random((n, 2)))
        nv = take_rows(normal, vv)
        t, b = coordinate_system(nv)
        w = to_world(local, t, b, nv)
        o = scene.tracer.offset(take_rows(pos, vv), nv, w)
        surf = scene.intersect(o, w)
        val = np.zeros(n)
        h = np.flatnonzero(surf.valid)
        if len(h):
            y = surf.subset(h)
            con = cam.connect(y.p, cam.lens_samples(rng, len(h)))
            ok = con.valid
            if ok.any():
                k = np.flatnonzero(ok)
                yk = y.subset(k)
                wcam = con.wi[k]
                flip = dot(yk.ng, wcam) < 0
                sg = np.where(flip, -1.0, 1.0)[:, None]
                ng, ns = yk.ng * sg, yk.ns * sg
                win = -w[h[k]]
                bsdf = scene.bsdf(yk.mat, ns, ng, yk.p)
                fr = luminance(bsdf.eval(wcam, win) * color[vv[h[k]]])
                if not clear_receivers:
                    fr = np.where(bsdf.is_specular_or_glass, 0.0, fr)
                cos_g_in = np.abs(dot(ng, win))
                ratio = np.abs(dot(ns, win)) / np.maximum(cos_g_in, 1e-12)
                cos_cam = np.abs(dot(ng, wcam))
                d2 = yk.t**2
                cos_v = local[h[k], 2]
                clamp = clamp_factor(gmax, d2, cos_v)
                contrib = np.pi * fr * ratio * cos_cam * con.factor[k] * clamp
                if mix is not None:     # balance heuristic against the pair's pixel sample
                    px, py = cam.window.pixel_xy(con.raster[k], clip=True)
                    p_cam = mix.pmf(vv[h[k]], px, py) * cos_cam * con.factor[k]
                    p_lt = cos_v / np.pi * cos_g_in / np.maximum(d2, 1e-300)
                    contrib = contrib * p_lt / np.maximum(p_lt + PIXEL_SAMPLE_RATE * p_cam, 1e-300)
                good = np.flatnonzero(contrib > 0)
                if len(good):
                    eye = con.origin[k[good]]           # the pinhole or the sampled lens point
                    vis = scene.tracer.visible(yk.p[good], ng[good], np.ascontiguousarray(eye), None)
                    val[h[k[good]]] = contrib[good] * vis
        if mix is not None:
            c = np.flatnonzero(rng.random(n) < PIXEL_SAMPLE_RATE)
            val[c] += _camera_side(scene, mix, pos, normal, color, vv[c], gmax, rng, clear_receivers)
        ns = n_samples if np.ndim(n_samples) == 0 else np.maximum(np.asarray(n_samples)[v], 1)
        total[v] = np.bincount(vv - s, weights=val, minlength=len(v)) / ns
        total2[v] = np.bincount(vv - s, weights=val * val, minlength=len(v)) / ns
        if halves:
            odd = _sample_parity(vv - s, len(v))
            for i, n_i in enumerate(((ns + 1) // 2, ns // 2)):
                half[i, v] = np.bincount(vv - s, weights=val * (odd == i), minlength=len(v)) / np.maximum(n_i, 1)
        if keep_going is not None and not keep_going((s + len(v)) / V):
            break
    if halves:
        return total, total2, half
    return (total, total2) if moments else total


#: ρ, the probability that a light-traced Ê1 sample comes with a pixel sample
#: (:func:`_camera_side`); the balance heuristic weighs the strategies by it (one model per
#: sample: E[sample] = ∫h·(p_lt + ρ·p_cam)/(p_lt + ρ·p_cam) = E1; the samples stay independent).
#: ``vpl_energy_ratio`` (64×48, seeds 1–8 / 1–4) with ρ = 0 / 0.25 / 1: the glTF test's open
#: scene 1.107 (1.003–1.294) / 1.007 (0.996–1.036, 4 seeds) / 1.005 (0.996–1.028); S-corridor
#: 1.009 / 1.006 / 1.003; door ajar 1.001 / 0.990 / 0.991 (spread ± 0.02); Cornell box 0.92
#: whatever ρ (that deficit is not Ê1's). A pixel sample costs about one light-traced one:
#: the VPL phase took 5.1–5.7 s with ρ = 0 and 9.9–12.2 s with ρ = 1 (Cornell box, 160×120,
#: 26 000 VPLs).
PIXEL_SAMPLE_RATE = 0.25


def uses_pixel_samples(camera) -> bool:
    """Ê1's samples are light-traced and pixel pairs for this camera (a pinhole: with depth
    of field or an orthographic camera, light tracing alone)."""
    return not camera.ortho and not camera.has_lens


def _camera_side(scene: BuiltScene, mix: PixelMixture, pos: NDArray, normal: NDArray, color: NDArray,
                 vv: NDArray, gmax: float, rng: np.random.Generator, clear_receivers: bool) -> NDArray:
    """(n,) one pixel sample of E1 per entry of ``vv`` (VPL ids), MIS-weighted against light
    tracing (:func:`estimate_e1_light_tracing`, balance heuristic with the share ρ of
    :data:`PIXEL_SAMPLE_RATE`): a pixel from ``mix``, a jittered pinhole ray, the first
    surface y it finds and the VPL's light there (:func:`vpl_radiance`, as the gather shades
    it), L_v(y)·|cos_y|·F / (ρ·p_cam + p_lt) with the area densities of y
    p_cam = q(pixel)·|cos_y|·F (:meth:`Camera.connect`: the pixel measure per unit area) and
    p_lt = (cosθ_v/π)·|cos_y,v|/d² (the VPL's cosine emission)."""
    cam, window, n = scene.camera, mix.window, len(vv)
    val = np.zeros(n)
    px, py = mix.sample(vv, rng)
    q = mix.pmf(vv, px, py)
    pix = py * window.width + px
    o, d = cam.generate_rays(window.raster(pix).astype(np.float64) + rng.random((n, 2)))
    surf = scene.intersect(o, d)
    h = np.flatnonzero(surf.valid)
    if len(h) == 0:
        return val
    y, wo = surf.subset(h), -d[h]
    sg = np.where(dot(y.ng, wo) < 0, -1.0, 1.0)[:, None]
    g = GBuffer(pix[h], y.p, y.ng * sg, y.ns * sg, wo, y.mat, np.ones(len(h), bool), y, 1)
    v = vv[h]
    L, _ = vpl_radiance(scene, g, np.arange(len(h)), pos[v], normal[v], color[v], gmax)
    f = luminance(L)
    if not clear_receivers:
        f = np.where(scene.bsdf(y.mat, g.ns, g.ng, y.p).is_specular_or_glass, 0.0, f)
    to_v = pos[v] - y.p
    d2 = np.maximum(dot(to_v, to_v), 1e-300)
    cos_v = np.maximum(-dot(normal[v], to_v), 0.0) / np.sqrt(d2)
    con = cam.connect(y.p)
    cos_y = np.abs(dot(g.ng, wo))
    p_cam = PIXEL_SAMPLE_RATE * q[h] * cos_y * con.factor
    p_lt = cos_v / np.pi * np.abs(dot(g.ng, to_v)) / (d2 * np.sqrt(d2))
    val[h] = np.where(p_cam > 0, f * cos_y * con.factor / np.maximum(p_cam + p_lt, 1e-300), 0.0)
    return val


def _sample_parity(owner: NDArray, n_owners: int) -> NDArray:
    """(n,) 0/1: whether each sample is its owner's even- or odd-numbered one; ``owner`` (n,)
    sorted owner ids in [0, n_owners) (each VPL's samples are contiguous, :func:`_chunks`)."""
    counts = np.bincount(owner, minlength=n_owners)
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    return (np.arange(len(owner)) - first[owner]) & 1


#: A second-stage Ê1 whose own relative variance (of the mean) exceeds this is *shaky*: it
#: rests on a few hits (std. error > 50 %, fewer than ≈ 4 hits of similar value) and 1/Ê1 has
#: a heavy tail — one VPL of Veach's room with 16 samples had Ê1 = 8.7e-5 against a true 14.9
#: and made the image 6.9× too bright. Such estimates get :func:`_redraw_shaky`'s extra samples.
SHAKY_RELATIVE_VARIANCE = 0.25
#: The shaky VPLs' extra samples together: at most this share of the second stage's budget
#: (each gets that budget's share of it, between ``n_samples`` and ``max_factor``·``n_samples``).
SHAKY_BUDGET = 0.25


def _redraw_shaky(scene: BuiltScene, pos: NDArray, normal: NDArray, color: NDArray, gmax: float,
                  counts: NDArray, e1: NDArray, e1_sq: NDArray, half: NDArray,
                  extra: tuple[int, int, float], rng: np.random.Generator, chunk: int, keep_going,
                  clear_receivers: bool, home: NDArray | None = None) -> None:
    """Re-estimate the shaky VPLs' Ê1 (:data:`SHAKY_RELATIVE_VARIANCE`) with m fresh samples
    each, in place: ``extra`` = (least, most, total), m = total / (number of shaky VPLs)
    clipped to [least, most] (and even for the jackknife's halves).

    ``e1``, ``e1_sq`` (V,): the second stage's means of the samples and of their squares over
    ``counts`` (V,) samples, ``half`` (2, V) the means of its halves (replaced too). A shaky VPL's Ê1 becomes the mean of the m fresh samples alone
    and its count m: the choice of the shaky VPLs depends on the second stage, so its samples
    are biased given that choice (few hits: Ê1 low), while the fresh ones are not; the
    jackknife then uses the fresh samples' halves, and where one is empty the pilot's ĉ_v
    (untouched here), independent of both, keeps the Jensen correction first-order unbiased. The earlier scheme pooled the second
    stage with the fresh samples and corrected with the second stage's ĉ_v, which is large
    exactly when that stage's Ê1 is small: it over-corrected, ``vpl_energy_ratio`` of the
    glass-sphere scene (issue 15) 0.974 ± 0.004 over 8 seeds; with this 0.991 ± 0.004
    (S-corridor 1.007 → 1.008, door ajar 0.997 → 1.004, 64×48, brute-force gather)."""
    n = np.maximum(counts, 1).astype(np.float64)
    hit = e1 > 0
    c2 = np.where(hit, np.maximum(e1_sq - e1 * e1, 0.0) / np.where(hit, e1 * e1, 1.0), 0.0)
    shaky = np.flatnonzero(hit & (c2 / n > SHAKY_RELATIVE_VARIANCE))
    if len(shaky) == 0 or (keep_going is not None and not keep_going(0.0)):
        return
    least, most, total = extra
    m = int(np.clip(total / len(shaky), least, most))
    if E1_BIAS_CORRECTION == "JACKKNIFE":
        m += m & 1                                        # two equal halves
    more, _, more_half = estimate_e1_light_tracing(scene, pos[shaky], normal[shaky], color[shaky], gmax, m,
                                                   rng, chunk, keep_going, clear_receivers=clear_receivers,
                                                   halves=True, home=None if home is None else home[shaky])
    e1[shaky] = more
    half[:, shaky] = more_half
    counts[shaky] = m


#: How :func:`estimate_e1_allocated` removes the first-order bias of 1/Ê1: 'JENSEN' (the
#: delta method with the pilot's relative variance ĉ_v), 'JACKKNIFE' (:func:`jackknife_e1`,
#: from the second stage's own samples: less bias at few samples, more variance — measured
#: there) or 'NONE' (the ablation). Measured ``vpl_energy_ratio`` at 64×48 (brute-force
#: gather), none → Jensen: S-corridor seeds 1–3 1.061/1.031/1.028 → 1.036/1.009/1.009, door
#: ajar 1.041 → 1.005, Cornell box 1.015 → 1.006.
E1_BIAS_CORRECTION = "JENSEN"


def jackknife_e1(e1: NDArray, half: NDArray, fallback: NDArray) -> NDArray:
    """(V,) Ê1 whose reciprocal is the jackknife estimate of 1/E1 [Quenouille 1956; Efron and
    Tibshirani 1993, ch. 10] over two equal halves of each VPL's samples.

    ``e1`` (V,) the mean of all samples, ``half`` (2, V) the means a, b of the two halves
    (Ê1 = (a + b)/2), ``fallback`` (V,) the value where a half found nothing. With c the
    relative variance of one sample and N the samples, E[1/Ê1] ≈ (1/E1)(1 + c/N) and
    E[1/a] ≈ (1/E1)(1 + 2c/N) (delta method), so 1/Ê1_J = 2/Ê1 − (1/a + 1/b)/2 has no 1/N
    term, measured from the samples that normalise the VPL rather than from the pilot's ĉ,
    which rests on a quarter of the samples and few hits for exactly the VPLs that need it.
    1/Ê1_J ≤ 1/Ê1 (arithmetic–harmonic mean inequality); it is kept ≥ ½/Ê1, the cap of the
    delta method's correction.

    ``vpl_energy_ratio`` (64×48, brute-force gather, seeds 1–6), pilot ĉ → jackknife: with
    64 samples per VPL (a short paced iteration's count) S-corridor 1.036 ± 0.007 → 1.003 ±
    0.007, door ajar 1.011 ± 0.005 → 0.997 ± 0.005; with 256 (the default) 1.008 ± 0.002 →
    0.998 ± 0.002 and 1.002 ± 0.006 → 0.993 ± 0.007. The glass-sphere scene's 1–2 % deficit
    (0.987 / 0.989 with the pilot's ĉ, 0.984 / 0.981 / 0.990 with the jackknife at 64 / 256 /
    1024 samples, 8 seeds, ± 0.003–0.01) does not fall as 1/N: another cause.

    Not the default: its correction is as noisy as it is large — at 136 samples per VPL
    (the directly lit scene, one iteration) it took over 9 % off 1/Ê1 for a quarter of the
    VPLs and over 46 % for 5 % (4.5 % clipped at ½; median 2.7 %) — and the
    directly lit scene with six paced iterations in 60 s (121–156 samples per VPL, seed 1,
    160×120) had 5.1× the gather's variance between iterations (8.7e-5 against 1.7e-5 of
    the relMSE) and relMSE 1.4e-4 against the pilot ĉ's 5.4e-5; used only where the second
    stage's relative variance of the mean is ≤ 0.05, still 3.2× (5.5e-5). On
    tests/test_e1.py's Cornell-box VPLs with 32 samples (400 estimates) the mean of E1/Ê1
    is 1.04–1.16 uncorrected, 1.00–1.10 with the pilot's ĉ and 0.98–1.08 with the jackknife."""
    a, b = half
    ok = (a > 0) & (b > 0)
    inv = 1.0 / np.where(ok, e1, 1.0)
    inv_j = 2.0 * inv - 0.5 * (1.0 / np.where(ok, a, 1.0) + 1.0 / np.where(ok, b, 1.0))
    return np.where(ok, 1.0 / np.maximum(inv_j, 0.5 * inv), fallback)


def estimate_e1_allocated(scene: BuiltScene, pos: NDArray, normal: NDArray, color: NDArray,
                          weight: NDArray, gmax: float, n_samples: int, rng: np.random.Generator,
                          chunk: int = 1 << 18, keep_going=None, pilot: float = 0.25,
                          max_factor: int = 16, clear_receivers: bool = True,
                          home: NDArray | None = None) -> NDArray:
    """(V,) Ê1 by light tracing with the budget ``n_samples``·V spent where 1/Ê1 is biased.

    The normalisation divides by Ê1, and E[1/Ê1] ≈ (1/E1)(1 + c_v/N_v) (Jensen; c_v the
    relative variance of one sample, N_v the samples): VPLs whose emission rarely reaches a
    camera-visible point (few hits) carry most of that bias — the S-corridor's VPLs around
    the bend: +5..+9 % of the image energy with 256 samples each (benchmarks/results/
    e1_bias.md). A pilot of ``pilot``·n_samples samples per VPL estimates c_v (only); the
    rest of the budget is then given ∝ sqrt(weight_v·c_v) — which minimises the weighted
    bias Σ weight_v·c_v/N_v — at least the pilot's count and at most ``max_factor``·n_samples
    per VPL, and Ê1 is the mean of these second samples alone, so it stays unbiased (the
    allocation depends on the pilot only). VPLs whose pilot found nothing get the most.
    With :data:`E1_BIAS_CORRECTION` the estimate is returned so that its reciprocal loses the
    first-order bias: as Ê1/(1 − ĉ_v/N_v) (ĉ_v/N_v capped at 0.5), whose ĉ_v comes from the
    pilot, independent of the second-stage samples (delta method; the default), or by the
    jackknife over the halves of the second stage (:func:`jackknife_e1`; the counts are made
    even; the delta method where a half found nothing). A
    second-stage estimate resting on a few hits is replaced by fresh samples first
    (:func:`_redraw_shaky`). ``keep_going``, ``clear_receivers`` and ``home`` as in
    :func:`estimate_e1_light_tracing` (fractions over both stages).
    """
    V = len(pos)
    n1 = max(4, int(round(n_samples * pilot)))
    if V == 0 or n_samples <= 2 * n1:
        return estimate_e1_light_tracing(scene, pos, normal, color, gmax, n_samples, rng, chunk, keep_going,
                                         clear_receivers=clear_receivers, home=home)
    f1 = n1 / n_samples
    stop = [False]

    def stage(lo, hi):
        if keep_going is None:
            return None

        def kg(f):
            ok = keep_going(lo + (hi - lo) * f)
            stop[0] |= not ok
            return ok
        return kg

    m, m2 = estimate_e1_light_tracing(scene, pos, normal, color, gmax, n1, rng, chunk,
                                      stage(0.0, f1), moments=True, clear_receivers=clear_receivers, home=home)
    if stop[0]:
        return np.zeros(V)
    hit = m > 0
    c = np.where(hit, np.maximum(m2 - m * m, 0.0) / np.where(hit, m * m, 1.0), np.nan)
    c = np.where(hit, c, np.nanmax(c, initial=0.0) if hit.any() else 1.0)   # nothing found: the most
    budget = (n_samples - n1) * V
    hi = max_factor * n_samples
    want = np.sqrt(np.maximum(weight, 0.0) * c)
    counts = np.full(V, n1, np.int64)
    if want.sum() > 0:
        # water-fill: scale so that Σ clip(t·want, n1, hi) = budget
        lo_t, hi_t = 0.0, 1.0
        while np.clip(hi_t * want, n1, hi).sum() < budget and hi_t < 1e30:
            hi_t *= 2.0
        for _ in range(60):
            t = 0.5 * (lo_t + hi_t)
            if np.clip(t * want, n1, hi).sum() < budget:
                lo_t = t
            else:
                hi_t = t
        counts = np.clip(lo_t * want, n1, hi).astype(np.int64)
    jackknife = E1_BIAS_CORRECTION == "JACKKNIFE"
    if jackknife:
        counts += counts & 1                              # two equal halves
    e1, e1_sq, half = estimate_e1_light_tracing(scene, pos, normal, color, gmax, counts, rng, chunk,
                                                stage(f1, 0.9), moments=True,
                                                clear_receivers=clear_receivers, halves=True, home=home)
    if not stop[0]:
        _redraw_shaky(scene, pos, normal, color, gmax, counts, e1, e1_sq, half,
                      (n_samples, hi, SHAKY_BUDGET * budget), rng, chunk, stage(0.9, 1.0), clear_receivers, home)
    if E1_BIAS_CORRECTION != "NONE":
        # E[1/Ê1] ≈ (1/E1)(1 + c_v/N_v) (delta method); the pilot's ĉ_v is independent of
        # the second stage, so (1/Ê1)(1 − ĉ_v/N_v) is unbiased to second order.
        jensen = e1 / (1.0 - np.minimum(c / np.maximum(counts, 1), 0.5))
        e1 = jackknife_e1(e1, half, jensen) if jackknife else jensen
    # Found nothing: once more with the largest count (before the pixel-mixture estimate of
    # make_vpls, whose rare tiny values made single VPLs several % of the image energy).
    miss = np.flatnonzero(e1 <= 0)
    if len(miss) and not stop[0] and (keep_going is None or keep_going(1.0)):
        e1[miss] = estimate_e1_light_tracing(scene, pos[miss], normal[miss], color[miss], gmax, hi, rng, chunk,
                                             clear_receivers=clear_receivers,
                                             home=None if home is None else home[miss])
    return e1


#: Fewest Ê1 samples per VPL a paced iteration normalises with; when its time holds fewer,
#: it keeps a random share of the VPLs instead (:func:`thin_vpls`). Directly lit scene,
#: 160×120, one iteration, seeds 0–2, relMSE of the indirect pass: 3.1e-4 / 3.5e-3 / 2.6e-4
#: with 64 samples (1/Ê1's heavy tail), 8.8 / 7.7 / 8.8e-5 with 128, 8.1 / 6.9 / 8.5e-5 with
#: 192, 7.7 / 6.9 / 8.3e-5 with 256 (the default), 7.5 / 6.9 / 7.9e-5 with 4096. The floor
#: was 128 until stop 50: from 640×480 up an iteration has 10⁵ VPLs or more and the time
#: share gave each ≈ 127, which biased the VPL image up through 1/Ê1's tail — the door at
#: 640×480 in 120 s (box-filtered to the 160×120 reference, seeds 1 / 0 / 0) had
#: ``vpl_energy_ratio`` 1.046 / 1.042 / 1.082 and relMSE 0.0057 / 0.0059 / 0.141 (the last
#: with a VPL behind the door drawn as a bright wedge over the ceiling); with 256 samples and
#: 45–48 % of the VPLs kept, 1.005 / 1.007 and 0.0025 / 0.0033.
PACED_E1_FLOOR = 256
#: Smallest share of the VPLs a paced iteration keeps to give each :data:`PACED_E1_FLOOR`
#: Ê1 samples (:func:`thin_vpls`); below it the samples per VPL fall instead.
MIN_VPL_SHARE = 1.0 / 16


def paced_vpl_share(samples: float, n_vpls: int, e1_samples: int) -> float:
    """The share of ``n_vpls`` VPLs a paced iteration keeps (:func:`thin_vpls`; ≥ 1: all)
    when its VPL phase has time for ``samples`` Ê1 samples in all: as many as leaves each
    min(``e1_samples``, :data:`PACED_E1_FLOOR`) samples, at least :data:`MIN_VPL_SHARE`."""
    floor = min(int(e1_samples), PACED_E1_FLOOR)
    return max(float(samples) / max(int(n_vpls), 1) / floor, MIN_VPL_SHARE)


def thin_vpls(chains: ChainResult, keep: float, rng: np.random.Generator) -> ChainResult:
    """The chains' VPL records with each kept with probability ``keep`` (Russian roulette)
    and a kept one's deposits weighted by 1/keep: the VPL image's expectation is unchanged
    (each record's energy k_v·e_d is kept in expectation) with fewer VPLs to normalise."""
    if keep >= 1.0:
        return chains
    kept = rng.random(len(chains.count)) < keep
    scale = np.where(kept, 1.0 / keep, 0.0)
    return dataclasses.replace(chains, count=chains.count * scale,
                               color_sum=chains.color_sum * scale[:, None])


def make_vpls(scene: BuiltScene, g: GBuffer, chains: ChainResult, e_d: float, gmax: float,
              n_samples: int, rng: np.random.Generator, chunk: int = 1 << 18,
              keep_going=None, clear_receivers: bool = True) -> VPLSet:
    """Normalise the chains' VPLs: I_v = k_v·e_d / Ê1(v) · c_v (module docstring); ``chunk``
    E1 samples are traced together (the memory budget's ``e1_chunk``); ``keep_going`` and
    ``clear_receivers`` as in :func:`estimate_e1_light_tracing` (when it stops, the VPL set
    is incomplete; ``g``'s valid points are the receivers of the pixel-sampled fallback)."""
    window = scene.camera.window
    used = chains.count > 0
    pos, normal = chains.position[used], chains.normal[used]
    count, home = chains.count[used], chains.home[used]
    color = chains.color_sum[used] / count[:, None]
    y = luminance(color)
    color = np.where(y[:, None] > 0, color / np.where(y > 0, y, 1.0)[:, None], 0.0)
    emitter = chains.emitter[used] if chains.emitter is not None else np.zeros(len(count), bool)
    e1 = estimate_e1_allocated(scene, pos, normal, color, count.astype(np.float64), gmax, n_samples,
                               rng, chunk, keep_going, clear_receivers=clear_receivers, home=home)
    miss = e1 <= 0
    # The emission found no camera-visible point: sample pixels instead (unless stopped).
    if miss.any() and (keep_going is None or keep_going(1.0)):
        e1[miss] = estimate_e1(scene, g, window, pos[miss], normal[miss], color[miss], home[miss],
                               gmax, n_samples, rng, chunk=chunk)
    lit = e1 > 0
    intensity = np.where(lit[:, None], (count * e_d / np.where(lit, e1, 1.0))[:, None] * color, 0.0)
    fallback = np.zeros((window.n_pixels, 3))
    fallback_emitter = np.zeros((window.n_pixels, 3))
    if (~lit).any():
        pix, _ = window.pixel(home[~lit], clip=True)
        val = (count[~lit] * e_d)[:, None] * color[~lit]
        for c in range(3):
            fallback[:, c] = np.bincount(pix, weights=val[:, c], minlength=window.n_pixels)
            fallback_emitter[:, c] = np.bincount(pix, weights=val[:, c] * emitter[~lit],
                                                 minlength=window.n_pixels)
    return VPLSet(pos[lit], normal[lit], intensity[lit], count[lit], e1[lit], fallback,
                  emitter[lit], fallback_emitter)
