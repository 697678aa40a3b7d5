"""Bidirectional path tracing with multiple importance sampling, as a numpy wavefront.

Structure after pbrt-v3 ``src/integrators/bdpt.cpp`` [Veach 1997 ch. 10; shared docs,
algorithm.md §C]:

* **Subpaths.** Every camera sample traces one camera subpath (vertex 0 = the camera,
  up to ``max_depth + 1`` scattering/emitter vertices) and one light subpath (vertex 0 =
  a point on a light chosen by power, up to ``max_depth`` surface vertices). All
  subpaths of a batch advance in lock-step, one batched ``intersect`` per bounce. The
  vertices are stored vertex-major as structure-of-arrays ``(V, N, ...)``: position,
  geometric and shading normal, material, ``wo`` (unit direction toward the previous
  vertex), throughput ``beta`` and the forward/reverse sampling densities ``pdf_fwd``/
  ``pdf_rev``, both **area** densities (solid angle for the direction-like endpoints of
  infinite lights, pbrt's convention).
* **Strategies.** Every (s, t) with depth s + t − 2 ≤ ``max_depth`` except (1, 1) is
  evaluated for all paths at once. The strategies form four groups, each executed as
  one batch of "connection rows" (lane, s, t) over all its (s, t) pairs, with one
  batched BSDF evaluation and one batched shadow-ray query: s = 0 (the camera subpath
  hit an emitter), s = 1 (next-event estimation with a freshly sampled light point),
  t = 1 (light tracing, splatted to the film) and the general s, t ≥ 2 connection.
* **MIS.** Weights come from ratios of reverse to forward densities along the full path,
  as in pbrt-v3 ``MISWeight``, with the **power heuristic** (β = 2, Veach/Mitsuba;
  ``mis_power=1`` gives pbrt-v3's balance heuristic). The four densities that depend on
  the connection are recomputed per row; the rest are the values stored during the
  random walks. The ratio products run over padded (vertex, row) arrays so that rows of
  different (s, t) share one computation. Russian roulette is not part of the densities
  (as in pbrt-v3 and Mitsuba).

Conventions shared with the path tracer (:mod:`.path`, the oracle):

* ``max_depth`` = number of scattering vertices; Russian roulette from ``rr_depth`` on
  both subpaths (camera: survival min(1, max β) as in PATH; light: min(1, max β/max β₀),
  relative to the emitted throughput, since light-subpath β carries the light's power).
* Lights (:mod:`..lights`): POINT/SUN are delta lights; AREA lights cannot be hit by rays,
  so the s = 0 strategy does not exist for them and they are excluded from that MIS
  term exactly like delta lights. SUN/ENV light subpaths start on a disk of radius R
  (the scene's bounding sphere); as in pbrt-v3 the *direction* density (incl. selection)
  is stored as the endpoint's ``pdf_fwd`` and the disk density 1/(πR²)·|cos| as the
  next vertex's, so that infinite-light vertices are never converted by cos/d².
* Camera: the camera ray density for one sample spread over the rendered window
  (``Camera.pdf_area``) is the camera strategy's density; with one light subpath per
  camera sample, this is the matching normalization for the per-pixel splat importance
  of ``Camera.connect`` [pbrt-v3 PerspectiveCamera::Pdf_We / We]. Orthographic cameras
  are delta in direction: no t = 1 strategy.
* Shading normals: light-subpath vertices use Veach's adjoint correction
  |wo·ns||wi·ng| / (|wo·ng||wi·ns|) (pbrt-v3 ``CorrectShadingNormal``, Importance mode);
  connection cosines use the shading normal, densities the geometric normal.
* The BSDF has no delta lobes, so the only zero densities are delta light endpoints
  (whose MIS terms are skipped); a zero *reverse* density means that the other strategy
  cannot produce the path and is kept as 0 (pbrt's remap0 is not needed).

Debugging: ``BDPTIntegrator(..., debug_strategies=True)`` accumulates each strategy's
MIS-weighted contribution in ``strategy_images[(s, t)]`` ((n_window_pixels, 3) sums, in
units where ``sum(strategy_images.values()) / spp`` equals the image RGB).
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..bsdf import Bsdf
from ..film import Film
from ..lights import AREA, ENV, POINT, SUN, TRI
from ..scene import BuiltScene
from ..settings import RenderSettings
from .base import Integrator, dot

#: Upper bound of one density ratio and of the running ratio products in MIS.
_RATIO_MAX = 1e30
_PRODUCT_MAX = 1e300


def _eval_pdf(bsdf: Bsdf, wo: NDArray, wi: NDArray) -> tuple[NDArray, NDArray]:
    """(f(wo, wi) (N, 3), pdf(wo → wi) (N,)) in one BSDF evaluation.

    ``Bsdf.eval`` and ``Bsdf.pdf`` share one core; calling it once saves a third of the
    connection cost. Falls back to the public pair if the core is not available.
    """
    core = getattr(bsdf, "_eval_pdf", None)
    if core is None:
        return bsdf.eval(wo, wi), bsdf.pdf(wo, wi)
    with np.errstate(under="ignore"):
        f, pdf = core(wo, wi)[:2]
    return f, pdf


def _adjoint_correction(ns: NDArray, ng: NDArray, wo: NDArray, wi: NDArray) -> NDArray:
    """(N,) |wo·ns||wi·ng| / (|wo·ng||wi·ns|): shading-normal correction for importance
    transport [Veach 1997 §5.3; pbrt-v3 CorrectShadingNormal]; 0 where undefined."""
    num = np.abs(dot(wo, ns)) * np.abs(dot(wi, ng))
    den = np.abs(dot(wo, ng)) * np.abs(dot(wi, ns))
    out = np.zeros(len(num))
    np.divide(num, den, out=out, where=den > 0)
    return out


class _Subpaths:
    """Vertices of N subpaths, vertex-major structure of arrays (index [vertex, lane]).

    Attributes:
        p, ng, ns, wo, beta: (V, N, 3) position, unit geometric/shading normal, unit
            direction toward the previous vertex, throughput up to and including the vertex.
        mat, prim: (V, N) material row and triangle (−1: not a triangle).
        pdf_fwd: (V, N) density of the vertex as generated by this subpath (area measure).
        pdf_rev: (V, N) density as generated from the other end, set by the random walk.
        g_prev: (V, N) factor converting a solid-angle density at vertex k toward k − 1
            into an area density at k − 1 (|cos at k−1|/d², 1/d² or 1 for points/infinite).
        env: (V, N) camera vertex made by an escaped ray (an environment-light endpoint).
        count: (N,) number of vertices (vertex 0 always exists).
        on_surface0, infinite0: (N,) vertex 0 lies on a surface / is at infinity.
    """

    def __init__(self, n_vertices: int, n_lanes: int):
        V, N = n_vertices, n_lanes
        self.n_lanes = N
        self.p = np.zeros((V, N, 3))
        self.ng = np.zeros((V, N, 3))
        self.ns = np.zeros((V, N, 3))
        self.wo = np.zeros((V, N, 3))
        self.beta = np.zeros((V, N, 3))
        self.mat = np.zeros((V, N), np.int64)
        self.prim = np.full((V, N), -1, np.int64)
        self.pdf_fwd = np.zeros((V, N))
        self.pdf_rev = np.zeros((V, N))
        self.g_prev = np.zeros((V, N))
        self.env = np.zeros((V, N), bool)
        self.count = np.ones(N, np.int64)
        self.on_surface0 = np.zeros(N, bool)
        self.infinite0 = np.zeros(N, bool)

    def at(self, name: str, k: NDArray, lane: NDArray) -> NDArray:
        """Gather attribute ``name`` of vertex k[r] of lane[r] for connection rows r."""
        a = getattr(self, name)
        return a.reshape((-1,) + a.shape[2:])[k * self.n_lanes + lane]

    def surface(self, k: int) -> NDArray:
        """(N,) lanes whose vertex k exists and lies on a surface."""
        return (self.count > k) & ~self.env[k]


class _Rows:
    """Connection rows: one (lane, s, t) per candidate path of a strategy group."""

    def __init__(self, parts: list[tuple[int, int, NDArray]]):
        parts = [p for p in parts if len(p[2])]
        if parts:
            self.lane = np.concatenate([p[2] for p in parts])
            self.s = np.concatenate([np.full(len(p[2]), p[0], np.int64) for p in parts])
            self.t = np.concatenate([np.full(len(p[2]), p[1], np.int64) for p in parts])
        else:
            self.lane = self.s = self.t = np.zeros(0, np.int64)

    def __len__(self) -> int:
        return len(self.lane)

    def chunks(self, size: int):
        for a in range(0, len(self.lane), size):
            yield self.lane[a:a + size], self.s[a:a + size], self.t[a:a + size]


class BDPTIntegrator(Integrator):
    """Bidirectional path tracer; see the module docstring.

    Args:
        scene, settings: as for every integrator.
        debug_strategies: accumulate per-(s, t) MIS-weighted images in ``strategy_images``.
        mis_power: MIS heuristic exponent β (2 = power heuristic, 1 = balance heuristic).
        max_lanes: camera samples traced together (bounds the memory of the subpath arrays).
        max_rows: connection rows evaluated together (bounds the memory of a group).
    """

    def __init__(self, scene: BuiltScene, settings: RenderSettings, *,
                 debug_strategies: bool = False, mis_power: float = 2.0,
                 max_lanes: int = 1 << 15, max_rows: int = 1 << 17):
        super().__init__(scene, settings)
        lights = scene.lights
        self.mis_power = float(mis_power)
        self.max_lanes = int(max_lanes)
        self.max_rows = int(max_rows)
        self.strategy_images: dict[tuple[int, int], NDArray] | None = {} if debug_strategies else None
        self.has_env = lights.env_light >= 0
        # Without shading normals the adjoint correction is exactly 1.
        self.shading_normals = scene.has_normals
        # Emitters that camera rays can hit (only they need a last camera vertex: s = 0).
        hittable = self.has_env or len(lights.emissive_tris) > 0
        depth = settings.max_depth
        self.n_cam = depth + 2 if hittable else depth + 1
        # The last light vertex only serves t = 1, which an orthographic camera lacks.
        self.n_light = depth if self.camera.is_delta_direction else depth + 1
        self.env_pdf = float(lights.pdf_illuminate_env(1)[0])        # pmf(env)/(4π)
        self.inv_disk = 1.0 / (np.pi * lights.radius**2)             # infinite-light disk

    # ================================================================== driver
    def render_batch(self, film: Film, pix: NDArray, rng: np.random.Generator) -> None:
        for start in range(0, len(pix), self.max_lanes):
            self._render_lanes(film, pix[start:start + self.max_lanes], rng)

    def _render_lanes(self, film: Film, pix: NDArray, rng: np.random.Generator) -> None:
        n = len(pix)
        # Trace the camera and light subpaths
        cam, alpha = self._camera_subpaths(film, pix, rng)
        lig, no_s0 = self._light_subpaths(n, rng)
        L = np.zeros((n, 3))
        # Execute all connection strategies, one group of (s, t) pairs at a time
        with np.errstate(over="ignore", under="ignore"):
            for lane, s, t in self._rows_s0(cam).chunks(self.max_rows):
                self._accumulate(L, pix, lane, s, t, *self._hit_emitter(cam, lane, s, t))
            for lane, s, t in self._rows_s1(cam).chunks(self.max_rows):
                self._accumulate(L, pix, lane, s, t, *self._connect_light(cam, lane, s, t, rng))
            for lane, s, t in self._rows_general(cam, lig).chunks(self.max_rows):
                self._accumulate(L, pix, lane, s, t,
                                 *self._connect_vertices(cam, lig, no_s0, lane, s, t))
            if not self.camera.is_delta_direction:
                for lane, s, t in self._rows_t1(lig).chunks(self.max_rows):
                    self._connect_camera(film, lig, no_s0, lane, s, t)
        film.add_samples(pix, L, alpha)

    def _accumulate(self, L: NDArray, pix: NDArray, lane: NDArray, s: NDArray, t: NDArray,
                    keep: NDArray, c: NDArray) -> None:
        """L[lane[keep]] += c (rows of one lane may repeat across strategies)."""
        lane, s, t = lane[keep], s[keep], t[keep]
        if len(lane) == 0:
            return
        for ch in range(3):
            L[:, ch] += np.bincount(lane, weights=c[:, ch], minlength=len(L))
        if self.strategy_images is not None:
            self._record_strategies(s, t, pix[lane], c)

    def _record_strategies(self, s: NDArray, t: NDArray, pix: NDArray, c: NDArray) -> None:
        """Debug: add rows to the per-(s, t) images (window pixel indices ``pix``)."""
        ok = np.isfinite(c).all(axis=1)
        npix = self.window.n_pixels
        for key in np.unique(s * 1024 + t):
            m = ok & (s * 1024 + t == key)
            img = self.strategy_images.setdefault((int(key // 1024), int(key % 1024)),
                                                  np.zeros((npix, 3)))
            for ch in range(3):
                img[:, ch] += np.bincount(pix[m], weights=c[m, ch], minlength=npix)

    # ================================================================== subpaths
    def _camera_subpaths(self, film: Film, pix: NDArray, rng: np.random.Generator):
        """Camera subpaths for window pixels ``pix``; records alpha and first-hit AOVs."""
        n = len(pix)
        cam = _Subpaths(self.n_cam, n)
        o, d = self.camera_rays(pix, rng)
        cam.p[0] = o
        cam.beta[0] = 1.0
        alpha = self._random_walk(cam, np.arange(n), o, d, np.ones((n, 3)), np.zeros(n),
                                  rng, importance=False, film=film, pix=pix)
        return cam, alpha

    def _light_subpaths(self, n: int, rng: np.random.Generator):
        """One light subpath per lane, started with :meth:`LightSet.emit`.

        Returns:
            the subpaths and (N,) ``no_s0``: the path's light cannot be hit by camera rays
            (delta or AREA), so the s = 0 strategy does not exist for it.
        """
        lights, tracer = self.scene.lights, self.scene.tracer
        lig = _Subpaths(self.n_light, n)
        e = lights.emit(rng.random(n), rng.random((n, 2)), rng.random((n, 2)))
        no_s0 = (e.kind == POINT) | (e.kind == SUN) | (e.kind == AREA)
        lig.on_surface0 = (e.kind == AREA) | (e.kind == TRI)
        lig.infinite0 = e.is_infinite.copy()
        lig.p[0], lig.ng[0], lig.ns[0] = e.p, e.n, e.n
        lig.beta[0] = e.Le
        # Origin density incl. selection; for infinite lights the direction density
        # (pbrt-v3 InfiniteLightDensity: only ENV has one, the sun is a delta).
        lig.pdf_fwd[0] = np.where(e.kind == ENV, self.env_pdf, np.where(e.kind == SUN, 0.0, e.pdf_pos))
        ok = (e.beta.max(axis=1) > 0) & (e.pdf_pos > 0) & (e.pdf_dir > 0)
        lanes = np.flatnonzero(ok)
        if len(lanes) and self.n_light > 1:
            p, nl, d = e.p[lanes], e.n[lanes], e.d[lanes]
            on_surf = lig.on_surface0[lanes]
            o = np.where(on_surf[:, None], tracer.offset(p, nl, d), p)
            self._random_walk(lig, lanes, o, d, e.beta[lanes], e.pdf_dir[lanes], rng,
                              importance=True)
        return lig, no_s0

    def _random_walk(self, path: _Subpaths, lanes: NDArray, o: NDArray, d: NDArray,
                     beta: NDArray, pdf_dir: NDArray, rng: np.random.Generator,
                     importance: bool, film: Film | None = None, pix: NDArray | None = None):
        """Extend subpaths ``lanes`` from vertex 1 along rays (o, d) (pbrt-v3 RandomWalk).

        Args:
            beta: (M, 3) throughput of the rays; pdf_dir: (M,) solid-angle density of d.
            importance: light subpath (adjoint shading-normal correction, relative RR).
            film, pix: camera subpaths only: record alpha and the first-hit AOVs.
        Returns:
            (N,) alpha of the first hits when ``film`` is given, else None.
        """
        s, scene, tracer = self.settings, self.scene, self.scene.tracer
        n_vertices = path.p.shape[0]
        beta0 = np.maximum(beta.max(axis=1), 1e-300)       # for the light's relative RR
        alpha = None
        for k in range(1, n_vertices):
            if len(lanes) == 0:
                break
            surf = scene.intersect(o, d)
            hit = surf.valid
            if film is not None and k == 1:
                alpha = self.alpha(surf)
            # Escaped camera rays end on the environment light (an s = 0 vertex).
            if not importance and self.has_env and not hit.all():
                m = ~hit
                ln = lanes[m]
                path.env[k, ln] = True
                path.p[k, ln] = path.p[k - 1, ln] + d[m] * (2.0 * scene.scene_radius)
                path.wo[k, ln] = -d[m]
                path.beta[k, ln] = beta[m]
                path.pdf_fwd[k, ln] = pdf_dir[m]              # solid angle (infinite light)
                path.count[ln] = k + 1
            keep = np.flatnonzero(hit)
            if film is not None and k == 1 and len(keep) == 0:
                self._record_first(film, pix, keep, None, None)
            if len(keep) == 0:
                break
            lanes, d, beta, pdf_dir = lanes[keep], d[keep], beta[keep], pdf_dir[keep]
            beta0 = beta0[keep]
            surf = surf.subset(keep)
            p, ng, ns = surf.p, surf.ng, surf.ns
            wo = -d
            # Densities: forward (into this vertex) and the conversion toward the previous one
            prev_p = path.p[k - 1, lanes]
            d2 = np.maximum(np.einsum("ij,ij->i", p - prev_p, p - prev_p), 1e-300)
            cos_here = np.abs(dot(ng, d))
            if k == 1:
                if importance:
                    inf0 = path.infinite0[lanes]
                    fwd = np.where(inf0, self.inv_disk * cos_here, pdf_dir * cos_here / d2)
                    cos_prev = np.where(path.on_surface0[lanes], np.abs(dot(path.ng[0, lanes], d)), 1.0)
                    g_prev = np.where(inf0, 1.0, cos_prev / d2)
                else:
                    fwd = self.camera.pdf_area(d, np.sqrt(d2), cos_here)
                    g_prev = 1.0 / d2
            else:
                fwd = pdf_dir * cos_here / d2
                g_prev = np.abs(dot(path.ng[k - 1, lanes], d)) / d2
            path.p[k, lanes], path.ng[k, lanes], path.ns[k, lanes] = p, ng, ns
            path.wo[k, lanes], path.beta[k, lanes] = wo, beta
            path.mat[k, lanes], path.prim[k, lanes] = surf.mat, surf.prim
            path.pdf_fwd[k, lanes], path.g_prev[k, lanes] = fwd, g_prev
            path.count[lanes] = k + 1
            last = k == n_vertices - 1
            if last and not (film is not None and k == 1):
                break
            bsdf = Bsdf.from_table(scene.materials, surf.mat, ns, ng)
            if film is not None and k == 1:
                self._record_first(film, pix, keep, surf, bsdf)
            if last:
                break
            # Sample the BSDF for the next vertex
            bs = bsdf.sample(wo, rng.random((len(lanes), 3)))
            beta = beta * bs.weight
            if importance and self.shading_normals:
                beta = beta * _adjoint_correction(ns, ng, wo, bs.wi)[:, None]
            alive = bs.valid & (beta.max(axis=1) > 0)
            # Reverse density of the previous vertex (area measure there)
            path.pdf_rev[k - 1, lanes] = np.where(alive, bsdf.pdf(bs.wi, wo) * g_prev, 0.0)
            if k >= s.rr_depth:
                q = beta.max(axis=1)
                if importance:
                    q = q / beta0
                q = np.minimum(1.0, q)
                survive = rng.random(len(lanes)) < q
                beta = beta / np.where(survive, q, 1.0)[:, None]
                alive &= survive
            keep = np.flatnonzero(alive)
            lanes, beta, beta0 = lanes[keep], beta[keep], beta0[keep]
            d, pdf_dir = bs.wi[keep], bs.pdf[keep]
            o = tracer.offset(p[keep], ng[keep], d)
        return alpha

    def _record_first(self, film: Film, pix: NDArray, keep: NDArray, surf, bsdf: Bsdf) -> None:
        """First-hit AOVs as the path tracer records them (misses: depth 1e10, zeros)."""
        n = len(pix)
        depth = np.full((n, 1), 1e10)
        normal = np.zeros((n, 3))
        albedo = np.zeros((n, 3))
        if len(keep):
            depth[keep, 0] = surf.t
            normal[keep] = surf.ns
            albedo[keep] = bsdf.albedo()
        film.add_aov("depth", pix, depth)
        film.add_aov("normal", pix, normal)
        film.add_aov("albedo", pix, albedo)

    # ================================================================== MIS
    def _ratio_terms(self, rev: NDArray, fwd: NDArray, valid: NDArray, skip: NDArray) -> NDArray:
        """Σ_m (Π_{j ≤ m} rev_j/fwd_j)^β over the valid, non-skipped entries.

        Args:
            rev, fwd, valid, skip: (K, R) per subpath vertex and row, ordered from the
                connection vertex (m = 0) toward the subpath's start.
        """
        # fmin also maps nan (inf/inf from degenerate geometry) to the cap.
        ratio = np.fmin(rev / np.where(fwd != 0, fwd, 1.0), _RATIO_MAX)
        use = valid & ~skip
        total = np.zeros(rev.shape[1])
        r = np.ones(rev.shape[1])
        for m in range(rev.shape[0]):
            r = np.minimum(r * ratio[m], _PRODUCT_MAX)
            term = r if self.mis_power == 1.0 else r ** self.mis_power
            total += np.where(use[m], term, 0.0)
        return total

    def _mis_weight(self, cam: _Subpaths, lig: _Subpaths | None, lane: NDArray, s: NDArray,
                    t: NDArray, pt_rev: NDArray, ptm_rev: NDArray, qs_rev: NDArray | None = None,
                    qsm_rev: NDArray | None = None, qs_fwd: NDArray | None = None,
                    no_s0: NDArray | None = None) -> NDArray:
        """MIS weights of connection rows (pbrt-v3 MISWeight, vectorized over rows).

        ``pt_rev``/``ptm_rev`` replace pdf_rev of camera vertices t−1 and t−2,
        ``qs_rev``/``qsm_rev`` those of light vertices s−1 and s−2, and ``qs_fwd`` the
        forward density of light vertex s−1 (the sampled light for s = 1). Entries that do
        not apply to a row (e.g. ``ptm_rev`` when t = 2) are ignored. ``no_s0``: per row,
        the light cannot be reached by the s = 0 strategy.
        """
        total = np.zeros(len(lane))
        if len(lane) == 0:
            return total
        # Hypothetical strategies with fewer camera vertices: i = t−1 … 1
        t_max = int(t.max()) - 1
        if t_max >= 1:
            i = t[None, :] - 1 - np.arange(t_max)[:, None]
            valid = i >= 1
            ic = np.maximum(i, 0)
            rev, fwd = cam.at("pdf_rev", ic, lane), cam.at("pdf_fwd", ic, lane)
            rev[0] = pt_rev
            if t_max >= 2:
                rev[1] = ptm_rev
            # i = 1 is the t = 1 strategy, absent for a delta-direction (orthographic) camera
            skip = (i == 1) if self.camera.is_delta_direction else np.zeros_like(valid)
            total += self._ratio_terms(rev, fwd, valid, skip)
        # Hypothetical strategies with fewer light vertices: i = s−1 … 0
        s_max = int(s.max())
        if s_max >= 1:
            i = s[None, :] - 1 - np.arange(s_max)[:, None]
            valid = i >= 0
            il = np.maximum(i, 0)
            if lig is None:                              # s = 1 rows: only the light sample
                rev, fwd = np.zeros(i.shape), np.ones(i.shape)
            else:
                rev, fwd = lig.at("pdf_rev", il, lane), lig.at("pdf_fwd", il, lane)
            rev[0], fwd[0] = qs_rev, qs_fwd
            if s_max >= 2:
                rev[1] = qsm_rev
            # i = 0 is the s = 0 strategy: impossible for delta and AREA lights
            skip = (i == 0) & no_s0[None, :]
            total += self._ratio_terms(rev, fwd, valid, skip)
        return np.where(s + t == 2, 1.0, 1.0 / (1.0 + total))

    # ================================================================== connection rows
    def _rows_s0(self, cam: _Subpaths) -> _Rows:
        """s = 0: camera vertices on emissive triangles or escaped to the environment."""
        # Per-triangle light index, with a −1 sentinel for "no triangle" (prim = −1)
        tri_light = np.append(self.scene.lights.tri_light, -1)
        parts = []
        for t in range(2, self.n_cam + 1):
            k = t - 1
            emitter = (tri_light[cam.prim[k]] >= 0) & (cam.count > k)
            if not (t == 2 and self.settings.film_transparent):
                emitter |= cam.env[k] & (cam.count > k)
            parts.append((0, t, np.flatnonzero(emitter)))
        return _Rows(parts)

    def _rows_s1(self, cam: _Subpaths) -> _Rows:
        """s = 1: every surface vertex of the camera subpaths up to depth max_depth."""
        last = min(self.n_cam, self.settings.max_depth + 1)
        return _Rows([(1, t, np.flatnonzero(cam.surface(t - 1))) for t in range(2, last + 1)])

    def _rows_general(self, cam: _Subpaths, lig: _Subpaths) -> _Rows:
        """s, t ≥ 2 with s + t − 2 ≤ max_depth."""
        parts = []
        for t in range(2, self.n_cam + 1):
            on_cam = cam.surface(t - 1)
            for s in range(2, min(self.n_light, self.settings.max_depth + 2 - t) + 1):
                parts.append((s, t, np.flatnonzero(on_cam & (lig.count > s - 1))))
        return _Rows(parts)

    def _rows_t1(self, lig: _Subpaths) -> _Rows:
        """t = 1: light vertices 1 … max_depth."""
        last = min(self.n_light, self.settings.max_depth + 1)
        return _Rows([(s, 1, np.flatnonzero(lig.count > s - 1)) for s in range(2, last + 1)])

    # ================================================================== strategies
    def _hit_emitter(self, cam: _Subpaths, lane: NDArray, s: NDArray, t: NDArray):
        """s = 0: camera vertex t−1 is on an emitter. Returns (kept rows, contributions)."""
        lights = self.scene.lights
        k = t - 1
        env, prim = cam.at("env", k, lane), cam.at("prim", k, lane)
        Le = np.zeros((len(lane), 3))
        Le[env] = lights.env_L
        Le[~env] = lights.tri_radiance(prim[~env])
        c = cam.at("beta", k, lane) * Le
        keep = np.flatnonzero(c.max(axis=1) > 0)
        lane, s, t, k, env, prim, c = lane[keep], s[keep], t[keep], k[keep], env[keep], prim[keep], c[keep]
        # Densities of the light strategies that could have made this emitter vertex
        wo, ng = cam.at("wo", k, lane), cam.at("ng", k, lane)
        light = np.full(len(lane), max(lights.env_light, 0))
        light[~env] = lights.tri_light[prim[~env]]
        pdf_pos, pdf_dir = lights.pdf_emit(light, cam.at("p", k, lane), ng, wo)
        pt_rev = np.where(env, self.env_pdf, pdf_pos)
        cos_prev = np.abs(dot(cam.at("ng", k - 1, lane), wo))
        ptm_rev = np.where(env, self.inv_disk * cos_prev, pdf_dir * cam.at("g_prev", k, lane))
        w = self._mis_weight(cam, None, lane, s, t, pt_rev, ptm_rev)
        return keep, c * w[:, None]

    def _connect_light(self, cam: _Subpaths, lane: NDArray, s: NDArray, t: NDArray,
                       rng: np.random.Generator):
        """s = 1: next-event estimation from camera vertex t−1 with a new light sample."""
        lights = self.scene.lights
        k, m = t - 1, len(lane)
        p, ng, ns, wo = (cam.at(a, k, lane) for a in ("p", "ng", "ns", "wo"))
        ls = lights.illuminate(p, rng.random(m), rng.random((m, 2)))
        bsdf = Bsdf.from_table(self.scene.materials, cam.at("mat", k, lane), ns, ng)
        f, pdf_fwd = _eval_pdf(bsdf, wo, ls.wi)
        pdf_w = np.where(ls.valid, ls.pdf_w, 1.0)
        c = cam.at("beta", k, lane) * f * ls.Li * (np.abs(dot(ns, ls.wi)) / pdf_w)[:, None]
        keep = np.flatnonzero(ls.valid & (c.max(axis=1) > 0))
        lane, s, t, k, c = lane[keep], s[keep], t[keep], k[keep], c[keep]
        p, ng, wo, pdf_fwd = p[keep], ng[keep], wo[keep], pdf_fwd[keep]
        wi, dist, n_l, lp = ls.wi[keep], ls.dist[keep], ls.n[keep], ls.p[keep]
        kind = lights.kind[ls.light[keep]]
        infinite = (kind == SUN) | (kind == ENV)
        on_surf = (kind == AREA) | (kind == TRI)
        d2 = np.where(infinite, 1.0, dist * dist)
        # Light endpoint: origin density, and its density as reached from the camera side
        qs_fwd = np.where(kind == SUN, 0.0, np.where(kind == ENV, ls.pdf_w[keep], ls.pdf_pos[keep]))
        conv = np.where(infinite, 1.0, np.where(on_surf, np.abs(dot(n_l, wi)), 1.0) / d2)
        qs_rev = pdf_fwd * conv
        # Camera vertex t−1 as reached from the light, and t−2 through vertex t−1
        cos_pt = np.abs(dot(ng, wi))
        pt_rev = np.where(infinite, self.inv_disk * cos_pt, ls.pdf_dir[keep] * cos_pt / d2)
        ptm_rev = bsdf.subset(keep).pdf(wi, wo) * cam.at("g_prev", k, lane)
        no_s0 = (kind == POINT) | (kind == SUN) | (kind == AREA)
        w = self._mis_weight(cam, None, lane, s, t, pt_rev, ptm_rev, qs_rev=qs_rev,
                             qs_fwd=qs_fwd, no_s0=no_s0)
        vis = self._light_visible(p, ng, wi, lp, n_l, infinite, on_surf)
        return keep[vis], (c * w[:, None])[vis]

    def _light_visible(self, p, ng, wi, lp, n_l, infinite, on_surf) -> NDArray:
        """Shadow rays toward light samples, cast as the path tracer casts them."""
        tracer = self.scene.tracer
        target = np.where(infinite[:, None], p + wi * 4.0 * self.scene.scene_radius, lp)
        vis = np.empty(len(p), bool)
        a, b = np.flatnonzero(on_surf), np.flatnonzero(~on_surf)
        if len(a):
            vis[a] = tracer.visible(p[a], ng[a], target[a], n_l[a])
        if len(b):
            vis[b] = tracer.visible(p[b], ng[b], target[b], None)
        return vis

    def _connect_vertices(self, cam: _Subpaths, lig: _Subpaths, no_s0: NDArray, lane: NDArray,
                          s: NDArray, t: NDArray):
        """s, t ≥ 2: connect light vertex s−1 to camera vertex t−1."""
        kq, kp = s - 1, t - 1
        qp, qng, qns, qwo = (lig.at(a, kq, lane) for a in ("p", "ng", "ns", "wo"))
        pp, png, pns, pwo = (cam.at(a, kp, lane) for a in ("p", "ng", "ns", "wo"))
        v = pp - qp
        d2 = np.einsum("ij,ij->i", v, v)
        w = v / np.sqrt(np.maximum(d2, 1e-300))[:, None]          # light vertex → camera vertex
        mats = self.scene.materials
        bq = Bsdf.from_table(mats, lig.at("mat", kq, lane), qns, qng)
        bp = Bsdf.from_table(mats, cam.at("mat", kp, lane), pns, png)
        fq, pdf_q = _eval_pdf(bq, qwo, w)                 # pdf_q: qs → pt
        fp, pdf_p = _eval_pdf(bp, pwo, -w)                # pdf_p: pt → qs
        if self.shading_normals:
            fq = fq * _adjoint_correction(qns, qng, qwo, w)[:, None]
        G = np.abs(dot(qns, w)) * np.abs(dot(pns, w)) / np.maximum(d2, 1e-300)
        c = lig.at("beta", kq, lane) * fq * fp * cam.at("beta", kp, lane) * G[:, None]
        keep = np.flatnonzero((c.max(axis=1) > 0) & (d2 > 0))
        lane, s, t, kq, kp, c, w, d2 = (a[keep] for a in (lane, s, t, kq, kp, c, w, d2))
        qp, qng, qwo, pp, png, pwo = (a[keep] for a in (qp, qng, qwo, pp, png, pwo))
        pt_rev = pdf_q[keep] * np.abs(dot(png, w)) / d2
        ptm_rev = bp.subset(keep).pdf(-w, pwo) * cam.at("g_prev", kp, lane)
        qs_rev = pdf_p[keep] * np.abs(dot(qng, w)) / d2
        qsm_rev = bq.subset(keep).pdf(w, qwo) * lig.at("g_prev", kq, lane)
        wgt = self._mis_weight(cam, lig, lane, s, t, pt_rev, ptm_rev, qs_rev=qs_rev,
                               qsm_rev=qsm_rev, qs_fwd=lig.at("pdf_fwd", kq, lane),
                               no_s0=no_s0[lane])
        vis = self.scene.tracer.visible(qp, qng, pp, png)
        return keep[vis], (c * wgt[:, None])[vis]

    def _connect_camera(self, film: Film, lig: _Subpaths, no_s0: NDArray, lane: NDArray,
                        s: NDArray, t: NDArray) -> None:
        """t = 1: connect light vertex s−1 to the camera and splat (light tracing)."""
        camera, k = self.camera, s - 1
        p, ng, ns, wo = (lig.at(a, k, lane) for a in ("p", "ng", "ns", "wo"))
        conn = camera.connect(p)
        wi = conn.wi
        bsdf = Bsdf.from_table(self.scene.materials, lig.at("mat", k, lane), ns, ng)
        f = bsdf.eval(wo, wi)
        if self.shading_normals:
            f = f * _adjoint_correction(ns, ng, wo, wi)[:, None]
        c = lig.at("beta", k, lane) * f * (np.abs(dot(ns, wi)) * conn.factor)[:, None]
        keep = np.flatnonzero(conn.valid & (c.max(axis=1) > 0))
        if len(keep) == 0:
            return
        lane, s, t, k, c, p, ng, wo, wi = (a[keep] for a in (lane, s, t, k, c, p, ng, wo, wi))
        raster, dist = conn.raster[keep], conn.dist[keep]
        # The camera strategy's density of this vertex: one camera sample over the window
        qs_rev = camera.pdf_area(-wi, dist, dot(ng, wi))
        qsm_rev = bsdf.subset(keep).pdf(wi, wo) * lig.at("g_prev", k, lane)
        w = self._mis_weight(None, lig, lane, s, t, None, None, qs_rev=qs_rev, qsm_rev=qsm_rev,
                             qs_fwd=lig.at("pdf_fwd", k, lane), no_s0=no_s0[lane])
        vis = self.scene.tracer.visible(p, ng, np.broadcast_to(camera.position, p.shape), None)
        raster, c, s, t = raster[vis], (c * w[:, None])[vis], s[vis], t[vis]
        film.add_splats(raster, c)
        if self.strategy_images is not None and len(c):
            win = self.window
            ix = np.floor(raster[:, 0]).astype(np.int64) - win.x0
            iy = np.floor(raster[:, 1]).astype(np.int64) - win.y0
            ok = (ix >= 0) & (ix < win.width) & (iy >= 0) & (iy < win.height)
            self._record_strategies(s[ok], t[ok], (iy * win.width + ix)[ok], c[ok] / win.n_pixels)
