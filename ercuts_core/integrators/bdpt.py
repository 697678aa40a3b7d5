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
  Rows whose connection leaves a vertex without a glass lobe on the side opposite to its
  path (f = 0 there; rough glass transmits through ``eval``) or, for t = 1, outside the
  view are dropped before any BSDF work;
  MIS weights and shadow rays are computed only for rows with a non-zero contribution.
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
* Lights (:mod:`..lights`): POINT/SUN are delta lights (or, with a radius or an angle,
  soft lights whose emission densities :meth:`LightSet.illuminate` reports for the s = 1
  MIS weights; a soft-falloff light's subpath is dropped when its first hit is not lit,
  :meth:`LightSet.emission_reaches`); they and AREA lights cannot be hit by rays,
  so the s = 0 strategy does not exist for them and they are excluded from that MIS
  term exactly like delta lights. SUN/ENV light subpaths start on a disk of radius R
  (the scene's bounding sphere); as in pbrt-v3 the *direction* density (incl. selection)
  is stored as the endpoint's ``pdf_fwd`` and the disk density 1/(πR²)·|cos| as the
  next vertex's, so that infinite-light vertices are never converted by cos/d².
* Camera: the camera ray density for one sample spread over the rendered window
  (``Camera.pdf_area``) is the camera strategy's density; with one light subpath per
  camera sample, this is the matching normalization for the per-pixel splat importance
  of ``Camera.connect`` [pbrt-v3 PerspectiveCamera::Pdf_We / We]. With depth of field the
  camera vertex is a lens point (camera rays and t = 1 connections each draw one; the
  densities keep their pinhole form, :mod:`..camera`). Orthographic cameras are delta in
  direction: no t = 1 strategy.
* Shading normals: light-subpath vertices use Veach's adjoint correction
  |wo·ns||wi·ng| / (|wo·ng||wi·ns|) (pbrt-v3 ``CorrectShadingNormal``, Importance mode);
  connection cosines use the shading normal, densities the geometric normal.
* Delta vertices (perfect mirrors, smooth glass; pbrt-v3/v4 ``Vertex::delta``): a walk
  step that sampled a delta lobe marks its vertex ``delta`` and stores 0 as the forward
  density of the next vertex and the reverse density of the previous one; the throughput
  takes the sample's weight as usual. No connection (s = 1, t = 1, general) is made to or
  from a vertex whose BSDF is purely delta (``Bsdf.is_delta``, pbrt ``IsConnectible``);
  a vertex with delta and continuous lobes connects through its continuous part and is
  delta only as sampled. MIS skips the hypothetical strategies that would connect at a
  delta vertex and counts the delta zeros as ratio 1 (pbrt ``remap0``), so emission seen
  through specular chains only (a lamp in a mirror, behind glass) gets weight 1. Other
  zero *reverse* densities mean that the other strategy cannot produce the path and stay
  0; a zero forward density (delta lights, delta neighbours) counts as 1.

Debugging: ``BDPTIntegrator(..., debug_strategies=True)`` accumulates each strategy's
MIS-weighted contribution in ``strategy_images[(s, t)]`` ((n_window_pixels, 3) sums, in
units where ``sum(strategy_images.values()) / spp`` equals the image RGB).

Connections (Ercuts' seed paths): ``BDPTIntegrator(..., on_connections=callback)`` calls
``callback(cam, lig, rows)`` after every batch of lanes with the batch's
:class:`Subpaths` and a :class:`Connection` per group of unoccluded, MIS-weighted
contributions (lane, s, t, energy; the light sample for s = 1, the raster position for
t = 1), so that a caller can rebuild every sampled path
(:mod:`ercuts_core.integrators.ercuts.seeding` turns them into the chains' seed paths).
Without a callback nothing is recorded.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from ..arrays import take_rows
from ..bsdf import Bsdf
from ..film import Film, path_class
from ..lights import AREA, ENV, POINT, SUN, TRI
from ..qmc import PassSequence, PixelSequence
from ..sampling import luminance
from ..scene import BuiltScene
from ..settings import RenderSettings
from ..vecmath import dot
from .base import Integrator

#: Upper bound of one density ratio and of the running ratio products in MIS.
_RATIO_MAX = 1e30
_PRODUCT_MAX = 1e300


def _eval_pdf(bsdf: Bsdf, wo: NDArray, wi: NDArray, adjoint: bool = False) -> tuple[NDArray, NDArray]:
    """(f(wo, wi) (N, 3), pdf(wo → wi) (N,)) in one BSDF evaluation.

    ``Bsdf.eval`` and ``Bsdf.pdf`` share one core: :meth:`Bsdf.eval_pdf` runs it once.
    ``adjoint``: wo points to the light side (light subpaths; the bump shadowing term of
    :class:`~ercuts_core.bsdf.Bsdf` is the only non-reciprocal factor).
    """
    return bsdf.eval_pdf(wo, wi, adjoint)


def _adjoint_correction(ns: NDArray, ng: NDArray, wo: NDArray, wi: NDArray) -> NDArray:
    """(N,) |wo·ns||wi·ng| / (|wo·ng||wi·ns|): shading-normal correction for importance
    transport [Veach 1997 §5.3; pbrt-v3 CorrectShadingNormal]; 0 where undefined."""
    num = np.abs(dot(wo, ns)) * np.abs(dot(wi, ng))
    den = np.abs(dot(wo, ng)) * np.abs(dot(wi, ns))
    out = np.zeros(len(num))
    np.divide(num, den, out=out, where=den > 0)
    return out


#: Columns of a vertex's float attributes in :attr:`Subpaths.data` and :attr:`VertexRows.data`.
_COLUMNS = {"p": slice(0, 3), "ng": slice(3, 6), "ns": slice(6, 9), "wo": slice(9, 12),
            "beta": slice(12, 15), "g_prev": 15}
_WIDTH = 16


def _column_views(obj, data: NDArray) -> None:
    """Set ``obj.p``, ``obj.ng``, … (:data:`_COLUMNS`) to views of ``data``'s last axis."""
    for name, col in _COLUMNS.items():
        setattr(obj, name, data[..., col])


def _delta_counts(cam: "Subpaths", lig: "Subpaths") -> tuple[NDArray, ...]:
    """Per subpath vertex k (V, N), for classifying paths by :meth:`BDPTIntegrator._count_delta`:
    the delta events at vertices 1 … k of each subpath, the camera subpath's leading vertices
    on mirrors and glass among 1 … k (``Bsdf.is_specular_or_glass``: the prefix ERCUTS's gather
    follows, :func:`~.ercuts.vpl.follow_specular`), and the light subpath's run of such
    vertices ending at k."""
    cam_clear = cam.clear.copy()
    cam_clear[0] = True                           # the camera vertex starts every prefix
    lead = np.cumsum(np.logical_and.accumulate(cam_clear, axis=0), axis=0) - 1
    run = np.zeros(lig.clear.shape, np.int64)
    for k in range(1, len(run)):
        run[k] = np.where(lig.clear[k], run[k - 1] + 1, 0)
    return np.cumsum(cam.delta, axis=0), lead, np.cumsum(lig.delta, axis=0), run


@dataclass
class LightSample:
    """The light vertex of s = 1 connections: (R, 3) position (a direction for infinite
    lights), (R, 3) normal (0 off surfaces) and (R,) global light index."""

    p: NDArray
    n: NDArray
    light: NDArray


class Connection:
    """A group of R sampled paths (unoccluded, MIS-weighted contribution w·C ≠ 0) of one
    batch: lane, s and t (R,) each; ``e`` (R,) Y(w·C) in image units (t = 1 rows divided by
    the number of window pixels, as their splats are, so Σe estimates the image energy);
    ``light_sample`` for s = 1 rows, ``raster`` (R, 2) and ``eye`` (R, 3) (the camera point
    connected to: the pinhole or a lens point) for t = 1 rows."""

    def __init__(self, lane: NDArray, s: NDArray, t: NDArray, e: NDArray,
                 light_sample: LightSample | None = None, raster: NDArray | None = None,
                 eye: NDArray | None = None):
        self.lane, self.s, self.t, self.e = lane, s, t, e
        self.light_sample, self.raster, self.eye = light_sample, raster, eye


class VertexRows:
    """Attributes of one vertex per connection row, gathered in one go (views of ``data``)."""

    def __init__(self, data: NDArray):
        self.data = data
        _column_views(self, data)

    def take(self, idx: NDArray) -> "VertexRows":
        return VertexRows(take_rows(self.data, idx))


class Subpaths:
    """Vertices of N subpaths, vertex-major structure of arrays (index [vertex, lane]).

    The float attributes of a vertex live side by side in ``data`` (V, N, 16), so that
    a connection row needs one gather (:meth:`rows`).

    Attributes:
        p, ng, ns, wo, beta: (V, N, 3) views of ``data``: position, unit geometric/shading
            normal, unit direction toward the previous vertex, throughput up to and
            including the vertex.
        mat, prim: (V, N) material row and triangle (−1: not a triangle).
        pdf_fwd: (V, N) density of the vertex as generated by this subpath (area measure).
        pdf_rev: (V, N) density as generated from the other end, set by the random walk.
        g_prev: (V, N) view of ``data``: the factor converting a solid-angle density at vertex k toward k − 1
            into an area density at k − 1 (|cos at k−1|/d², 1/d² or 1 for points/infinite).
        env: (V, N) camera vertex made by an escaped ray (an environment-light endpoint).
        delta: (V, N) the walk sampled a delta lobe at the vertex (pbrt ``Vertex::delta``);
            then pdf_fwd of vertex k + 1 and pdf_rev of vertex k − 1 are 0.
        connectible: (V, N) False where every lobe of the vertex's BSDF is a delta lobe
            (``Bsdf.is_delta``, pbrt ``IsConnectible``); True where no BSDF was built.
        clear: (V, N) the vertex's BSDF is a mirror or glass only (``Bsdf.is_specular_or_glass``;
            the path classes of :meth:`BDPTIntegrator._count_delta`); False where none was built.
        reflect_only: (V, N) the vertex's BSDF has no glass and no translucent lobe
            (``Bsdf.reflect_only``), so f = 0 unless wo and wi lie on one side (connection
            rows are pre-filtered by side only there; rough glass and translucent surfaces
            transmit through ``eval``); False where no BSDF was built.
        count: (N,) number of vertices (vertex 0 always exists).
        on_surface0, infinite0: (N,) vertex 0 lies on a surface / is at infinity.
        raster: (N, 2) camera subpaths: full-frame raster position of the camera sample.
        light, kind0: (N,) light subpaths: global light index and kind of vertex 0.
    """

    def __init__(self, n_vertices: int, n_lanes: int):
        V, N = n_vertices, n_lanes
        self.n_lanes = N
        self.data = np.zeros((V, N, _WIDTH))
        _column_views(self, self.data)
        self.mat = np.zeros((V, N), np.int64)
        self.prim = np.full((V, N), -1, np.int64)
        self.pdf_fwd = np.zeros((V, N))
        self.pdf_rev = np.zeros((V, N))
        self.env = np.zeros((V, N), bool)
        self.delta = np.zeros((V, N), bool)
        self.connectible = np.ones((V, N), bool)
        self.clear = np.zeros((V, N), bool)
        self.reflect_only = np.zeros((V, N), bool)
        self.count = np.ones(N, np.int64)
        #: (3, N, 3) camera subpaths: lights with a shape met after delta events only
        #: (:meth:`BDPTIntegrator._lights_after_delta`), by path class
        self.lights_seen = np.zeros((3, N, 3))
        self.on_surface0 = np.zeros(N, bool)
        self.infinite0 = np.zeros(N, bool)
        self.raster = np.zeros((N, 2))
        self.light = np.zeros(N, np.int64)
        self.kind0 = np.zeros(N, np.int64)

    def rows(self, k: NDArray, lane: NDArray) -> VertexRows:
        """The float attributes of vertex k[r] of lane[r] for connection rows r."""
        return VertexRows(take_rows(self.data.reshape(-1, _WIDTH), k * self.n_lanes + lane))

    def at(self, name: str, k: NDArray, lane: NDArray) -> NDArray:
        """Gather the (V, N) attribute ``name`` (pdf_fwd, pdf_rev, mat, prim, env, delta) for rows."""
        return take_rows(getattr(self, name).reshape(-1), k * self.n_lanes + lane)

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
        on_connections: ``callback(cam, lig, rows)`` after every batch of lanes (module
            docstring, :class:`Connection`); None records nothing.
        paths: 'all', or 'direct_and_late_delta': only the paths that ERCUTS's gather does
            not render when it follows the camera through mirrors and smooth glass (as
            :class:`~.path.PathIntegrator`'s set of that name; the class of a path, not of
            a strategy, so the MIS weights stay those of all strategies); or 'late_delta',
            those of them with a late event (caustics, a lamp behind glass: light tracing's
            and the connections' paths), added without coverage (:attr:`light_only`).
    """

    def __init__(self, scene: BuiltScene, settings: RenderSettings, *,
                 debug_strategies: bool = False, mis_power: float = 2.0,
                 max_lanes: int = 1 << 15, max_rows: int = 1 << 17,
                 on_connections: "Callable[[Subpaths, Subpaths, list[Connection]], None] | None" = None,
                 paths: str = "all"):
        super().__init__(scene, settings)
        if paths not in ("all", "direct_and_late_delta", "late_delta"):
            raise ValueError(f"unknown path set {paths!r}")
        self.paths = paths
        #: the passes add light only (no coverage, no first-hit AOVs): 'late_delta' renders a
        #: part of the image that a path tracer's passes over the same film complete
        self.light_only = paths == "late_delta"
        if paths != "all" and on_connections is not None:
            raise ValueError("on_connections records every path: paths must be 'all'")
        lights = scene.lights
        self.mis_power = float(mis_power)
        self.max_lanes = int(max_lanes)
        self.max_rows = int(max_rows)
        self.strategy_images: dict[tuple[int, int], NDArray] | None = {} if debug_strategies else None
        self.has_env = lights.env_light >= 0
        # Without shading normals (vertex normals, normal maps, bump) the adjoint correction is 1.
        self.shading_normals = scene.has_shading_normals
        # Emitters that camera rays can hit (only they need a last camera vertex: s = 0).
        hittable = self.has_env or len(lights.emissive_tris) > 0
        depth = settings.max_depth
        self.n_cam = depth + 2 if hittable else depth + 1
        # The last light vertex only serves t = 1, which an orthographic camera lacks.
        self.n_light = depth if self.camera.is_delta_direction else depth + 1
        # Selection pmf of the environment (× its direction density: pbrt InfiniteLightDensity)
        self.env_pmf = float(lights.pmf(np.array([lights.env_light]))[0]) if self.has_env else 0.0
        self.inv_disk = 1.0 / (np.pi * lights.radius**2)             # infinite-light disk
        self.on_connections = on_connections
        #: Σ over every batch rendered of the image energy (Σ_pixels luminance, one pass's
        #: units) of the paths with a delta event and two or more scattering vertices: the
        #: part of the rough image's indirect light that ERCUTS's chains and VPLs do not carry
        #: (:meth:`~.ercuts.integrator.ErcutsIntegrator._render` takes it out of P)
        self.delta_indirect = 0.0
        #: … of the paths outside the ER chains' domain when ERCUTS's gather follows the
        #: camera through mirrors and glass: a delta event, or x1 or x2 on a mirror or glass
        #: (``Bsdf.is_specular_or_glass``); P leaves them out
        self.outside_indirect = 0.0
        #: … of all paths with two or more scattering vertices, those ERCUTS's direct-light
        #: passes path-trace when its gather follows the camera through mirrors and glass (a
        #: delta event outside the camera-side prefix of mirrors and glass, or at most one
        #: scattering vertex outside it: ``PathIntegrator(paths='direct_and_late_delta')``);
        #: the direct phase is sized by it
        self.traced_indirect = 0.0

    # ================================================================== driver
    def render_batch(self, film: Film, pix: NDArray, rng: np.random.Generator,
                     sequence: "PassSequence | None" = None) -> None:
        """One sample per pixel ``pix`` (N,) into ``film``, in batches of ``max_lanes``. With
        the pass loop's ``sequence`` (:mod:`ercuts_core.qmc`) the first dimensions of a
        sample — the camera jitter (and lens), the light subpath's emission, and the light
        sample of next-event estimation (s = 1) at the first camera vertex — are the pass's
        randomised Sobol point, so over the passes they are stratified per pixel; the others
        (later bounces) come from ``rng``."""
        for start in range(0, len(pix), self.max_lanes):
            chunk = pix[start:start + self.max_lanes]
            self._render_lanes(film, chunk, rng, None if sequence is None else sequence.bind(chunk, rng))

    def _render_lanes(self, film: Film, pix: NDArray, rng: np.random.Generator,
                      u: "PixelSequence | None" = None) -> None:
        n = len(pix)
        self._pending: list[Connection] = []                         # rows for on_connections
        # Trace the camera and light subpaths
        cam, alpha = self._camera_subpaths(film, pix, rng, u)
        lig, no_s0 = self._light_subpaths(n, rng, u)
        u_nee = None if u is None else u.take(np.arange(n), 3)      # s = 1 at t = 2
        L = np.zeros((3, n, 3))                  # by path class (film.path_class of s + t − 2)
        self._delta_counts = _delta_counts(cam, lig)
        self._clear = (cam.clear, lig.clear)
        # Execute all connection strategies, one group of (s, t) pairs at a time
        with np.errstate(over="ignore", under="ignore"):
            for lane, s, t in self._rows_s0(cam).chunks(self.max_rows):
                lane, s, t = self._late_rows(lane, s, t)
                self._accumulate(L, pix, lane, s, t, *self._hit_emitter(cam, lane, s, t))
            for lane, s, t in self._rows_s1(cam).chunks(self.max_rows):
                lane, s, t = self._late_rows(lane, s, t)
                keep, c, sample = self._connect_light(cam, lane, s, t, rng, u_nee)
                self._accumulate(L, pix, lane, s, t, keep, c, sample)
            for lane, s, t in self._rows_general(cam, lig).chunks(self.max_rows):
                lane, s, t = self._late_rows(lane, s, t)
                self._accumulate(L, pix, lane, s, t,
                                 *self._connect_vertices(cam, lig, no_s0, lane, s, t))
            if not self.camera.is_delta_direction:
                for lane, s, t in self._rows_t1(lig).chunks(self.max_rows):
                    self._connect_camera(film, lig, no_s0, *self._late_rows(lane, s, t), rng)
        if not self.light_only:     # E S⁺ L: in every set but the late one (a prefix only)
            L += cam.lights_seen
        seen = float(luminance(cam.lights_seen[2]).sum())     # (two or more S: indirect)
        self.delta_indirect += seen
        self.traced_indirect += seen
        film.add_samples(pix, L.sum(axis=0), 0.0 * alpha if self.light_only else alpha, parts=L)
        if self.on_connections is not None:
            self.on_connections(cam, lig, self._pending)

    def _accumulate(self, L: NDArray, pix: NDArray, lane: NDArray, s: NDArray, t: NDArray,
                    keep: NDArray, c: NDArray, light_sample: LightSample | None = None) -> None:
        """L[class, lane[keep]] += c, class = path_class(s + t − 2) (scattering vertices); rows
        of one lane may repeat across strategies."""
        lane, s, t = lane[keep], s[keep], t[keep]           # c: the kept rows' contributions
        kept = self._in_set(*self._count_delta(lane, s, t, c))
        if kept is not None:
            lane, s, t, c = lane[kept], s[kept], t[kept], c[kept]
        if len(lane) == 0:
            return
        if self.on_connections is not None:
            self._pending.append(Connection(lane, s, t, luminance(c), light_sample=light_sample))
        cell = path_class(s + t - 2) * L.shape[1] + lane
        flat = L.reshape(-1, 3)
        for ch in range(3):
            flat[:, ch] += np.bincount(cell, weights=c[:, ch], minlength=len(flat))
        if self.strategy_images is not None:
            self._record_strategies(s, t, pix[lane], c)

    def _count_delta(self, lane: NDArray, s: NDArray, t: NDArray, c: NDArray) -> tuple[NDArray, NDArray]:
        """Classify connection rows (lane, s, t) by their path and count their energies Y(c)
        (one pass's units). A path's *prefix* is its run of scattering vertices on mirrors
        and glass from the camera on (camera vertices 1 … t − 1, then light vertices s − 1,
        s − 2, …; :func:`_delta_counts`), x_d the vertex after it; returns two (R,) bool: the
        path is *traced* — it is *late* (the second array: a delta event outside the prefix,
        or the vertex after x_d on a mirror or glass), or it has at most one scattering vertex
        outside the prefix: what ERCUTS's direct passes render when its gather follows the
        camera through mirrors and glass (``PathIntegrator(paths='direct_and_late_delta')``,
        the late ones ``'late_delta'``). Of the rows with
        s + t − 2 ≥ 2 scattering vertices, those with a delta event — at a camera vertex
        1 … t − 2 or a light vertex 1 … s − 2 (a connection vertex is never one) — add to
        :attr:`delta_indirect`; those or the ones whose x1 or x2 is on a mirror or glass to
        :attr:`outside_indirect`; the traced ones to :attr:`traced_indirect`."""
        traced, late, scatter, total, outside = self._classify(lane, s, t)
        ind = np.flatnonzero(scatter >= 2)
        if len(ind):
            y = luminance(c[ind])
            self.delta_indirect += float(y[total[ind] > 0].sum())
            self.outside_indirect += float(y[outside[ind]].sum())
            self.traced_indirect += float(y[traced[ind]].sum())
        return traced, late

    def _classify(self, lane: NDArray, s: NDArray, t: NDArray) -> tuple[NDArray, ...]:
        """Per connection row (R,): traced, late (:meth:`_count_delta`), the scattering
        vertices s + t − 2, the delta events, and outside the ER chains' domain (a delta
        event, or x1 or x2 on a mirror or glass)."""
        cam_dc, cam_lead, lig_dc, lig_run = self._delta_counts
        scatter = s + t - 2
        cam_sc = np.maximum(np.where(s >= 1, t - 1, t - 2), 0)    # camera scattering vertices
        lead = cam_lead[cam_sc, lane]
        m = np.where((lead == cam_sc) & (s >= 2), np.minimum(lig_run[np.maximum(s - 1, 0), lane], s - 1), 0)
        tc, sc = np.maximum(t - 2, 0), np.maximum(s - 2, 0)
        total = cam_dc[tc, lane] + lig_dc[sc, lane]
        in_prefix = cam_dc[np.minimum(lead, tc), lane] + np.where(
            m >= 2, lig_dc[sc, lane] - lig_dc[np.maximum(s - m - 1, 0), lane], 0)
        after = self._clear_after_prefix(lane, s, lead + m, cam_sc)
        late = (total > in_prefix) | after
        traced = late | (scatter - lead - m <= 1)
        return traced, late, scatter, total, (total > 0) | (lead + m >= 1) | after

    def _late_rows(self, lane: NDArray, s: NDArray, t: NDArray) -> tuple[NDArray, NDArray, NDArray]:
        """The rows of late paths alone when the passes render only them (:attr:`light_only`:
        the others' connections are not made), else all rows."""
        if not self.light_only:
            return lane, s, t
        late = self._classify(lane, s, t)[1]
        return lane[late], s[late], t[late]

    def _in_set(self, traced: NDArray, late: NDArray) -> NDArray | None:
        """(R,) bool: the rows of :attr:`paths` (from :meth:`_count_delta`), None for 'all'."""
        return None if self.paths == "all" else late if self.light_only else traced

    def record_first_hit(self, film: Film, pix: NDArray, keep: NDArray, surf, bsdf) -> None:
        """First-hit AOVs, unless the passes add light only (:attr:`light_only`)."""
        if not self.light_only:
            super().record_first_hit(film, pix, keep, surf, bsdf)

    def _clear_after_prefix(self, lane: NDArray, s: NDArray, prefix: NDArray, cam_sc: NDArray) -> NDArray:
        """(R,) the scattering vertex after x_d (the first one after the ``prefix`` (R,)
        vertices on mirrors and glass; camera order: camera vertices 1 … ``cam_sc``, then light
        vertices s − 1, s − 2, …) exists and is on a mirror or glass: no VPL can sit there."""
        cam, lig = self._clear
        pos = prefix + 2                                   # its index in camera order
        on_cam = pos <= cam_sc
        light_k = s - (pos - cam_sc)                       # on the light side: vertex s − j
        out = np.zeros(len(lane), bool)
        c = np.flatnonzero(on_cam)
        out[c] = cam[pos[c], lane[c]]
        g = np.flatnonzero(~on_cam & (light_k >= 1))
        out[g] = lig[light_k[g], lane[g]]
        return out

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
    def _camera_subpaths(self, film: Film, pix: NDArray, rng: np.random.Generator,
                         u: "PixelSequence | None" = None):
        """Camera subpaths for window pixels ``pix``; records alpha and first-hit AOVs. The
        jitter and lens numbers come from ``u`` when given (:meth:`render_batch`)."""
        n = len(pix)
        cam = Subpaths(self.n_cam, n)
        # As Integrator.camera_rays (same random numbers), keeping the raster positions
        cam.raster, lens = self.camera_samples(pix, rng, u)
        o, d = self.camera.generate_rays(cam.raster, lens)
        cam.p[0] = o
        cam.beta[0] = 1.0
        alpha = self._random_walk(cam, np.arange(n), o, d, np.ones((n, 3)), np.zeros(n),
                                  rng, importance=False, film=film, pix=pix)
        return cam, alpha

    def _light_subpaths(self, n: int, rng: np.random.Generator, u: "PixelSequence | None" = None):
        """One light subpath per lane, started with :meth:`LightSet.emit` (its five numbers
        from ``u`` when given, :meth:`render_batch`).

        Returns:
            the subpaths and (N,) ``no_s0``: the path's light cannot be hit by camera rays
            (delta or AREA), so the s = 0 strategy does not exist for it.
        """
        lights, tracer = self.scene.lights, self.scene.tracer
        lig = Subpaths(self.n_light, n)
        if u is None:
            e = lights.emit(rng.random(n), rng.random((n, 2)), rng.random((n, 2)))
        else:
            ue = u.take(np.arange(n), 5)
            e = lights.emit(ue[:, 0], ue[:, 1:3], ue[:, 3:5])
        no_s0 = (e.kind == POINT) | (e.kind == SUN) | (e.kind == AREA)
        lig.light, lig.kind0 = e.light, e.kind
        lig.on_surface0 = (e.kind == AREA) | (e.kind == TRI)
        lig.infinite0 = e.is_infinite.copy()
        lig.p[0], lig.ng[0], lig.ns[0] = e.p, e.n, e.n
        lig.beta[0] = e.Le
        # Origin density incl. selection; for infinite lights the direction density
        # (pbrt-v3 InfiniteLightDensity: only ENV has one, the sun is a delta).
        env_dir = np.zeros(n)
        m = e.kind == ENV
        if m.any():
            env_dir[m] = self.env_pmf * e.pdf_dir[m]     # pmf × density of the direction −d
        lig.pdf_fwd[0] = np.where(e.kind == ENV, env_dir, np.where(e.kind == SUN, 0.0, e.pdf_pos))
        ok = (e.beta.max(axis=1) > 0) & (e.pdf_pos > 0) & (e.pdf_dir > 0)
        lanes = np.flatnonzero(ok)
        if len(lanes) and self.n_light > 1:
            p, nl, d = e.p[lanes], e.n[lanes], e.d[lanes]
            on_surf = lig.on_surface0[lanes]
            o = np.where(on_surf[:, None], tracer.offset(p, nl, d), p)
            self._random_walk(lig, lanes, o, d, e.beta[lanes], e.pdf_dir[lanes], rng,
                              importance=True)
            hit = lanes[lig.count[lanes] > 1]        # soft-falloff lights light a subset
            lig.count[hit[~lights.emission_reaches(e.light[hit], e.p[hit], lig.p[1, hit])]] = 1
        return lig, no_s0

    def _random_walk(self, path: Subpaths, lanes: NDArray, o: NDArray, d: NDArray,
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
        all_delta = np.ones(len(lanes), bool)              # every vertex so far a delta event
        for k in range(1, n_vertices):
            if len(lanes) == 0:
                break
            surf = scene.intersect(o, d)
            hit = surf.valid
            if not importance and k >= 2:
                self._lights_after_delta(path, k, lanes, all_delta, o, d, surf, beta)
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
                self.record_first_hit(film, pix, keep, None, None)
            if len(keep) == 0:
                break
            lanes, d, beta, pdf_dir = lanes[keep], d[keep], beta[keep], pdf_dir[keep]
            all_delta = all_delta[keep]
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
            row = path.data[k]
            for name, value in zip(_COLUMNS, (p, ng, ns, wo, beta, g_prev)):
                row[lanes, _COLUMNS[name]] = value
            path.mat[k, lanes], path.prim[k, lanes] = surf.mat, surf.prim
            path.pdf_fwd[k, lanes] = fwd
            path.count[lanes] = k + 1
            last = k == n_vertices - 1
            if last and not (film is not None and k == 1):
                break
            bsdf = scene.bsdf(surf.mat, ns, ng, p)
            path.clear[k, lanes] = bsdf.is_specular_or_glass
            if film is not None and k == 1:
                self.record_first_hit(film, pix, keep, surf, bsdf)
            if last:
                break
            path.connectible[k, lanes] = ~bsdf.is_delta
            path.reflect_only[k, lanes] = bsdf.reflect_only
            # Sample the BSDF for the next vertex
            bs = bsdf.sample(wo, rng.random((len(lanes), 3)), adjoint=importance)
            beta = beta * bs.weight
            if importance and self.shading_normals:
                # Absolute cosines: also right for a refraction (wi on the other side)
                beta = beta * _adjoint_correction(ns, ng, wo, bs.wi)[:, None]
            alive = bs.valid & (beta.max(axis=1) > 0)
            fwd_next, rev = self._walk_densities(bsdf, bs, wo, alive)
            path.delta[k, lanes] = bs.is_delta & alive
            path.pdf_rev[k - 1, lanes] = rev * g_prev          # area measure at vertex k − 1
            if k >= s.rr_depth:
                q = beta.max(axis=1)
                if importance:
                    q = q / beta0
                q = np.minimum(1.0, q)
                survive = rng.random(len(lanes)) < q
                beta = beta / np.where(survive, q, 1.0)[:, None]
                alive &= survive
            keep = np.flatnonzero(alive)
            all_delta = (all_delta & bs.is_delta)[keep]
            lanes, beta, beta0 = lanes[keep], beta[keep], beta0[keep]
            d, pdf_dir = bs.wi[keep], fwd_next[keep]
            o = tracer.offset(p[keep], ng[keep], d)
        return alpha

    def _lights_after_delta(self, path: Subpaths, k: int, lanes: NDArray, all_delta: NDArray,
                            o: NDArray, d: NDArray, surf, beta: NDArray) -> None:
        """Camera rays (o, d) toward vertex k whose vertices 1 … k − 1 are all delta events:
        add the area, soft point and sun-cone lights they meet before their hit
        (:meth:`LightSet.radiance_along`) to ``path.lights_seen``, weight 1. No other strategy
        makes such a path (no connection at a delta vertex; these lights are not geometry, so
        s = 0 has no hit to find); a path with a non-delta vertex before the delta chain is
        light tracing's (t = 1) and is left to it."""
        lights = self.scene.lights
        r = np.flatnonzero(all_delta)
        if len(r) == 0 or not lights.has_shapes:
            return
        t = np.where(surf.valid[r], surf.t[r], np.inf)
        path.lights_seen[path_class(k - 1), lanes[r]] += beta[r] * lights.radiance_along(o[r], d[r], t)

    @staticmethod
    def _walk_densities(bsdf: Bsdf, bs, wo: NDArray, alive: NDArray) -> tuple[NDArray, NDArray]:
        """Solid-angle densities of a walk step: (forward density of the sampled direction,
        reverse density toward the previous vertex), both (M,).

        After a delta event both are 0 (pbrt-v3/v4 ``RandomWalk``: ``if specular:
        v.delta = true; pdfFwd = pdfRev = 0``): the discrete probability is not a density,
        and the MIS weights treat these zeros as ratio 1 and skip the strategies that
        would connect at the delta vertex (:meth:`_mis_weight`) [Veach 1997 §10.3.5].
        """
        ok = alive & ~bs.is_delta
        return np.where(ok, bs.pdf, 0.0), np.where(ok, bsdf.pdf(bs.wi, wo), 0.0)

    # ================================================================== MIS
    def _ratio_terms(self, rev: NDArray, fwd: NDArray, valid: NDArray, skip: NDArray,
                     remap_rev: NDArray) -> NDArray:
        """Σ_m (Π_{j ≤ m} rev_j/fwd_j)^β over the valid, non-skipped entries.

        Zero densities next to a delta vertex count as 1 (pbrt-v3 ``remap0``): the delta
        factor is common to every strategy that can produce the path and cancels
        [Veach 1997 §10.3.5]. A zero forward density is always remapped; a zero reverse
        density only where ``remap_rev`` (the delta vertex's neighbour): elsewhere it means
        that the hypothetical strategy cannot produce the path (pbrt's remap0 would count
        it and lose energy), so it stays 0.

        Args:
            rev, fwd, valid, skip, remap_rev: (K, R) per subpath vertex and row, ordered
                from the connection vertex (m = 0) toward the subpath's start.
        """
        rev = np.where(remap_rev & (rev == 0), 1.0, rev)
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

    @staticmethod
    def _delta_flags(path: Subpaths | None, i: NDArray, lane: NDArray) -> tuple[NDArray, NDArray, NDArray]:
        """(K, R) delta flags of subpath vertices i, i − 1 and i + 1 for MIS rows (all False
        without a subpath; indices clamped, out-of-range entries are masked by the caller).

        The connection vertex (m = 0) is never delta for the strategy being weighted
        (pbrt-v3 MISWeight: ``pt->delta = qs->delta = false``).
        """
        if path is None:
            z = np.zeros(i.shape, bool)
            return z, z, z
        last = path.delta.shape[0] - 1
        here = path.at("delta", np.clip(i, 0, last), lane)
        here[0] = False
        prev = path.at("delta", np.clip(i - 1, 0, last), lane)
        nxt = path.at("delta", np.clip(i + 1, 0, last), lane)
        return here, prev, nxt

    def _mis_weight(self, cam: Subpaths, lig: Subpaths | None, lane: NDArray, s: NDArray,
                    t: NDArray, pt_rev: NDArray, ptm_rev: NDArray, qs_rev: NDArray | None = None,
                    qsm_rev: NDArray | None = None, qs_fwd: NDArray | None = None,
                    no_s0: NDArray | None = None) -> NDArray:
        """MIS weights of connection rows (pbrt-v3 MISWeight, vectorized over rows).

        ``pt_rev``/``ptm_rev`` replace pdf_rev of camera vertices t−1 and t−2,
        ``qs_rev``/``qsm_rev`` those of light vertices s−1 and s−2, and ``qs_fwd`` the
        forward density of light vertex s−1 (the sampled light for s = 1). Entries that do
        not apply to a row (e.g. ``ptm_rev`` when t = 2) are ignored. ``no_s0``: per row,
        the light cannot be reached by the s = 0 strategy.

        Delta vertices (pbrt-v3/v4): the hypothetical strategy with i vertices on a
        subpath connects its vertices i − 1 and i, so it is skipped when either is delta;
        the zero densities the walk stored next to a delta vertex count as ratio 1
        (:meth:`_ratio_terms`). The replaced entries m = 0, 1 are recomputed densities,
        never delta zeros.
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
            here, prev, nxt = self._delta_flags(cam, i, lane)
            nxt[:2] = False
            skip = here | prev
            # i = 1 is the t = 1 strategy, absent for a delta-direction (orthographic) camera
            if self.camera.is_delta_direction:
                skip |= i == 1
            total += self._ratio_terms(rev, fwd, valid, skip, nxt)
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
            here, prev, nxt = self._delta_flags(lig, i, lane)
            nxt[:2] = False
            # i = 0 is the s = 0 strategy: impossible for delta and AREA lights (pbrt:
            # the predecessor of light vertex 0 is "delta" for a delta light)
            skip = here | np.where(i == 0, no_s0[None, :], prev)
            total += self._ratio_terms(rev, fwd, valid, skip, nxt)
        return np.where(s + t == 2, 1.0, 1.0 / (1.0 + total))

    # ================================================================== connection rows
    def _rows_s0(self, cam: Subpaths) -> _Rows:
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

    def _rows_s1(self, cam: Subpaths) -> _Rows:
        """s = 1: every connectible surface vertex of the camera subpaths up to depth max_depth."""
        last = min(self.n_cam, self.settings.max_depth + 1)
        return _Rows([(1, t, np.flatnonzero(cam.surface(t - 1) & cam.connectible[t - 1]))
                      for t in range(2, last + 1)])

    def _rows_general(self, cam: Subpaths, lig: Subpaths) -> _Rows:
        """s, t ≥ 2 with s + t − 2 ≤ max_depth, both vertices connectible (pbrt IsConnectible)."""
        parts = []
        for t in range(2, self.n_cam + 1):
            on_cam = cam.surface(t - 1) & cam.connectible[t - 1]
            for s in range(2, min(self.n_light, self.settings.max_depth + 2 - t) + 1):
                on_lig = (lig.count > s - 1) & lig.connectible[s - 1]
                parts.append((s, t, np.flatnonzero(on_cam & on_lig)))
        return _Rows(parts)

    def _rows_t1(self, lig: Subpaths) -> _Rows:
        """t = 1: connectible light vertices 1 … max_depth."""
        last = min(self.n_light, self.settings.max_depth + 1)
        return _Rows([(s, 1, np.flatnonzero((lig.count > s - 1) & lig.connectible[s - 1]))
                      for s in range(2, last + 1)])

    # ================================================================== strategies
    def _hit_emitter(self, cam: Subpaths, lane: NDArray, s: NDArray, t: NDArray):
        """s = 0: camera vertex t−1 is on an emitter. Returns (kept rows, contributions)."""
        lights = self.scene.lights
        k = t - 1
        env, prim = cam.at("env", k, lane), cam.at("prim", k, lane)
        pt = cam.rows(k, lane)
        Le = np.zeros((len(lane), 3))
        Le[env] = lights.env_radiance(-pt.wo[env])              # wo points back: −wo escaped
        Le[~env] = lights.tri_radiance(prim[~env], pt.p[~env])
        c = pt.beta * Le
        keep = np.flatnonzero(c.max(axis=1) > 0)
        lane, s, t, k, env, prim, c = lane[keep], s[keep], t[keep], k[keep], env[keep], prim[keep], c[keep]
        p, ng, wo, g_prev = pt.p[keep], pt.ng[keep], pt.wo[keep], pt.g_prev[keep]
        # Densities of the light strategies that could have made this emitter vertex
        light = np.full(len(lane), max(lights.env_light, 0))
        light[~env] = lights.tri_light[prim[~env]]
        pdf_pos, pdf_dir = lights.pdf_emit(light, p, ng, wo)
        env_pdf = np.zeros(len(lane))
        if env.any():
            env_pdf[env] = lights.pdf_illuminate_env(-wo[env])       # pmf × density of the direction
        pt_rev = np.where(env, env_pdf, pdf_pos)
        cos_prev = np.abs(dot(cam.rows(k - 1, lane).ng, wo))
        ptm_rev = np.where(env, self.inv_disk * cos_prev, pdf_dir * g_prev)
        w = self._mis_weight(cam, None, lane, s, t, pt_rev, ptm_rev)
        return keep, c * w[:, None]

    def _connect_light(self, cam: Subpaths, lane: NDArray, s: NDArray, t: NDArray,
                       rng: np.random.Generator, u_first: NDArray | None = None):
        """s = 1: next-event estimation from camera vertex t−1 with a new light sample (at the
        first camera vertex, t = 2, its numbers from ``u_first`` (lanes, 3) when given)."""
        lights = self.scene.lights
        m = len(lane)
        pt = cam.rows(t - 1, lane)
        u_sel, u_pos = rng.random(m), rng.random((m, 2))
        if u_first is not None:
            first = np.flatnonzero(t == 2)
            u_sel[first], u_pos[first] = u_first[lane[first], 0], u_first[lane[first], 1:3]
        ls = lights.illuminate(pt.p, u_sel, u_pos)
        # Light samples that carry energy, on the side the camera path arrived from
        same_side = dot(pt.wo, pt.ng) * dot(ls.wi, pt.ng) > 0
        idx = np.flatnonzero(ls.valid & (same_side | ~cam.at("reflect_only", t - 1, lane)))
        lane, s, t, pt = lane[idx], s[idx], t[idx], pt.take(idx)
        k = t - 1
        p, ng, ns, wo = pt.p, pt.ng, pt.ns, pt.wo
        wi, dist, n_l, lp = ls.wi[idx], ls.dist[idx], ls.n[idx], ls.p[idx]
        bsdf = self.scene.bsdf(cam.at("mat", k, lane), ns, ng, p)
        f, pdf_fwd = _eval_pdf(bsdf, wo, wi)
        c = pt.beta * f * ls.Li[idx] * (np.abs(dot(ns, wi)) / ls.pdf_w[idx])[:, None]
        keep = np.flatnonzero((c.max(axis=1) > 0) & ~bsdf.is_delta)
        idx = idx[keep]
        lane, s, t, k, c = lane[keep], s[keep], t[keep], k[keep], c[keep]
        p, ng, wo, pdf_fwd = p[keep], ng[keep], wo[keep], pdf_fwd[keep]
        wi, dist, n_l, lp = wi[keep], dist[keep], n_l[keep], lp[keep]
        kind = lights.kind[ls.light[idx]]
        infinite = (kind == SUN) | (kind == ENV)
        on_surf = (kind == AREA) | (kind == TRI)
        d2 = np.where(infinite, 1.0, dist * dist)
        # Light endpoint: origin density, and its density as reached from the camera side
        qs_fwd = np.where(kind == SUN, 0.0, np.where(kind == ENV, ls.pdf_w[idx], ls.pdf_pos[idx]))
        conv = np.where(infinite, 1.0, np.where(on_surf, np.abs(dot(n_l, wi)), 1.0) / d2)
        qs_rev = pdf_fwd * conv
        # Camera vertex t−1 as reached from the light, and t−2 through vertex t−1
        cos_pt = np.abs(dot(ng, wi))
        pt_rev = np.where(infinite, self.inv_disk * cos_pt, ls.pdf_dir[idx] * cos_pt / d2)
        ptm_rev = bsdf.subset(keep).pdf(wi, wo) * pt.g_prev[keep]
        no_s0 = (kind == POINT) | (kind == SUN) | (kind == AREA)
        w = self._mis_weight(cam, None, lane, s, t, pt_rev, ptm_rev, qs_rev=qs_rev,
                             qs_fwd=qs_fwd, no_s0=no_s0)
        vis = self._light_visible(p, ng, wi, lp, n_l, infinite, on_surf)
        sample = None
        if self.on_connections is not None:                  # the light vertex of each path
            sample = LightSample(np.where(infinite[:, None], wi, lp)[vis],
                                 np.where(on_surf[:, None], n_l, 0.0)[vis], ls.light[idx][vis])
        return idx[vis], (c * w[:, None])[vis], sample

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

    def _connect_vertices(self, cam: Subpaths, lig: Subpaths, no_s0: NDArray, lane: NDArray,
                          s: NDArray, t: NDArray):
        """s, t ≥ 2: connect light vertex s−1 to camera vertex t−1."""
        qs, pt = lig.rows(s - 1, lane), cam.rows(t - 1, lane)
        v = pt.p - qs.p
        d2 = np.einsum("ij,ij->i", v, v)
        # A reflection-only BSDF is 0 unless the connection leaves each vertex on the side
        # its path arrived from (geometric normals): skip those rows before any BSDF work.
        q_ok = (dot(qs.wo, qs.ng) * dot(v, qs.ng) > 0) | ~lig.at("reflect_only", s - 1, lane)
        p_ok = (dot(pt.wo, pt.ng) * dot(v, pt.ng) < 0) | ~cam.at("reflect_only", t - 1, lane)
        idx = np.flatnonzero(q_ok & p_ok & (d2 > 0))
        lane, s, t, v, d2 = lane[idx], s[idx], t[idx], v[idx], d2[idx]
        qs, pt = qs.take(idx), pt.take(idx)
        kq, kp = s - 1, t - 1
        qp, qng, qns, qwo = qs.p, qs.ng, qs.ns, qs.wo
        pp, png, pns, pwo = pt.p, pt.ng, pt.ns, pt.wo
        w = v / np.sqrt(d2)[:, None]                              # light vertex → camera vertex
        bq = self.scene.bsdf(lig.at("mat", kq, lane), qns, qng, qp)
        bp = self.scene.bsdf(cam.at("mat", kp, lane), pns, png, pp)
        fq, pdf_q = _eval_pdf(bq, qwo, w, adjoint=True)   # pdf_q: qs → pt
        fp, pdf_p = _eval_pdf(bp, pwo, -w)                # pdf_p: pt → qs
        if self.shading_normals:
            fq = fq * _adjoint_correction(qns, qng, qwo, w)[:, None]
        G = np.abs(dot(qns, w)) * np.abs(dot(pns, w)) / d2
        c = qs.beta * fq * fp * pt.beta * G[:, None]
        keep = np.flatnonzero((c.max(axis=1) > 0) & ~bq.is_delta & ~bp.is_delta)
        idx = idx[keep]
        lane, s, t, kq, kp, c, w, d2 = (a[keep] for a in (lane, s, t, kq, kp, c, w, d2))
        qp, qng, qwo, pp, png, pwo = (a[keep] for a in (qp, qng, qwo, pp, png, pwo))
        pt_rev = pdf_q[keep] * np.abs(dot(png, w)) / d2
        ptm_rev = bp.subset(keep).pdf(-w, pwo) * pt.g_prev[keep]
        qs_rev = pdf_p[keep] * np.abs(dot(qng, w)) / d2
        qsm_rev = bq.subset(keep).pdf(w, qwo) * qs.g_prev[keep]
        wgt = self._mis_weight(cam, lig, lane, s, t, pt_rev, ptm_rev, qs_rev=qs_rev,
                               qsm_rev=qsm_rev, qs_fwd=lig.at("pdf_fwd", kq, lane),
                               no_s0=no_s0[lane])
        vis = self.scene.tracer.visible(qp, qng, pp, png)
        return idx[vis], (c * wgt[:, None])[vis]

    def _connect_camera(self, film: Film, lig: Subpaths, no_s0: NDArray, lane: NDArray,
                        s: NDArray, t: NDArray, rng: np.random.Generator) -> None:
        """t = 1: connect light vertex s−1 to the camera (a lens point) and splat (light tracing)."""
        camera = self.camera
        qs = lig.rows(s - 1, lane)
        conn = camera.connect(qs.p, camera.lens_samples(rng, len(lane)))
        # In the view, and leaving on the side the light path arrived from (else f = 0)
        same_side = dot(qs.wo, qs.ng) * dot(conn.wi, qs.ng) > 0
        idx = np.flatnonzero(conn.valid & (same_side | ~lig.at("reflect_only", s - 1, lane)))
        if len(idx) == 0:
            return
        lane, s, t, qs = lane[idx], s[idx], t[idx], qs.take(idx)
        k = s - 1
        p, ng, ns, wo = qs.p, qs.ng, qs.ns, qs.wo
        wi, factor = conn.wi[idx], conn.factor[idx]
        raster, dist, eye = conn.raster[idx], conn.dist[idx], conn.origin[idx]
        bsdf = self.scene.bsdf(lig.at("mat", k, lane), ns, ng, p)
        # One evaluation toward the light vertex's predecessor gives f (wi: the camera
        # side, wo: the light side, as on camera paths) and the reverse density for MIS.
        f, pdf_rev = _eval_pdf(bsdf, wi, wo)
        if self.shading_normals:
            f = f * _adjoint_correction(ns, ng, wo, wi)[:, None]
        c = qs.beta * f * (np.abs(dot(ns, wi)) * factor)[:, None]
        keep = np.flatnonzero((c.max(axis=1) > 0) & ~bsdf.is_delta)
        if len(keep) == 0:
            return
        lane, s, t, k, c, p, ng, wo, wi = (a[keep] for a in (lane, s, t, k, c, p, ng, wo, wi))
        raster, dist, eye = raster[keep], dist[keep], eye[keep]
        # The camera strategy's density of this vertex: one camera sample over the window
        qs_rev = camera.pdf_area(-wi, dist, dot(ng, wi))
        qsm_rev = pdf_rev[keep] * qs.g_prev[keep]
        w = self._mis_weight(None, lig, lane, s, t, None, None, qs_rev=qs_rev, qsm_rev=qsm_rev,
                             qs_fwd=lig.at("pdf_fwd", k, lane), no_s0=no_s0[lane])
        vis = self.scene.tracer.visible(p, ng, np.ascontiguousarray(eye), None)
        raster, c, s, t = raster[vis], (c * w[:, None])[vis], s[vis], t[vis]
        lane, eye = lane[vis], eye[vis]
        kept = self._in_set(*self._count_delta(lane, s, t, c / self.window.n_pixels))
        if kept is not None:
            lane, raster, c, s, t = lane[kept], raster[kept], c[kept], s[kept], t[kept]
        film.add_splats(raster, c, path_class(s + t - 2))
        if self.on_connections is not None:
            self._pending.append(Connection(lane, s, t, luminance(c) / self.window.n_pixels,
                                            raster=raster, eye=eye))
        if self.strategy_images is not None and len(c):
            win = self.window
            pix, ok = win.pixel(raster)
            self._record_strategies(s[ok], t[ok], pix[ok], c[ok] / win.n_pixels)
