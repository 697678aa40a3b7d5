"""Paper step 5 over the image: the VPL light at every shading point of the G-buffer, by
lightcuts (:mod:`.lightcuts`) or the brute-force ablation, split into the light of emitter
VPLs (direct) and of the others (indirect), paced under a time limit
(:class:`~.pacing.GatherPace`).

The shading points are visited in a shuffled order of :data:`GATHER_RUN`-point runs, so every
batch is a sample of the whole image (for the pacing and an even partial image) while
neighbouring points stay together (coherent shadow rays).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
from numpy.typing import NDArray

from ...sampling import luminance
from ...scene import BuiltScene
from ...settings import RenderSettings
from ..path import next_event
from .balance import DirectRival, PassVariance
from .bias_compensation import compensate, compensates, compensation_rays
from .interpolation import Interpolation, auto_spacing, grid_offset, plan_interpolation, same_surface
from .lightcuts import GlossyReceivers, ShadingPoints, brute_force, lightcut
from .pacing import MAX_PACED_ERROR, GatherPace, Schedule
from .stochastic_lightcuts import leaf_cdf, stochastic_lightcut
from .vpl import GBuffer
from . import warm_up

#: Absolute lightcut error floor as a fraction of max_error × the mean pixel luminance.
ABS_FLOOR = 0.1
#: Largest gather batch (shading points) for progress reports every ~0.25 s of work: a
#: lightcut round of 2048 points took up to 0.97 s of CPU on the S-corridor, of 512 points
#: 0.20 s, at the same total cost.
PROGRESS_GATHER_POINTS = 512
#: Shading points whose specular lobe has a roughness below this count as glossy (er_caustic).
GLOSSY_ROUGHNESS = 0.5
#: ``settings.lightcut_error`` → the ``error_mode`` of :func:`.lightcuts.lightcut`.
ERROR_MODES = {"NODE": "bound", "TOTAL": "total", "LITERAL": "literal"}
#: Seed salt of the stochastic gather's draws (with the seed, the pass and the batch start).
PASS_SALT = 0x5C7
#: The variance probe after the first stochastic gather pass (:meth:`Gather._probe`): at
#: least this many points, or this share of them if more (2 % of a pass's time) …
PROBE_POINTS = 2048
PROBE_SHARE = 0.02
#: … drawn with this pass index (independent of every real pass's draws).
PROBE_PASS = 1 << 20
#: Another stochastic gather pass starts only if the iteration's time left is at least this
#: share of the first pass's duration (a pass the time cuts short keeps the points it reached).
PASS_START = 0.1
#: A direct-light pass takes spare time only if the iteration's time left holds this many of
#: its durations (it is not cut short: a pass of the direct film must be complete).
RIVAL_START = 1.5
#: The direct-light passes compete for the time of the gather's second pass in every paced
#: iteration (False: only in one that fills the render's time, as before stop 46); in one that
#: later iterations follow they may take that pass's time and no more.
RIVAL_IN_EVERY_PACED = True
#: Receivers per chunk of the clamp's bias compensation (:meth:`Gather._compensation`; progress
#: and Esc between chunks), and the seed salt of its draws.
COMPENSATION_CHUNK = 1 << 14
COMPENSATION_SALT = 0xB1A5
#: Stochastic cut size at the compensation's surfaces (at most ``stochastic_cut_size``): their
#: light is weighted by the clamp's share w < 1 and one BSDF sample, whose noise dominates.
COMPENSATION_CUT = 64
#: Consecutive shading points kept together in the shuffled gather order (coherent rays).
GATHER_RUN = 32
#: Glossy shading points get the per-cluster GGX material bound (:class:`.lightcuts.
#: GlossyReceivers`); False falls back to the constant lobe-peak bound of ``bsdf_max_value``,
#: which glossy lobes exceed (kept for benchmarks/bench_glossy_bound.py's comparison only).
GLOSSY_CLUSTER_BOUND = True


@dataclass
class Gathered:
    """The VPL gather per pixel: ``parts`` (2, h·w, 3) light of emitter VPLs (direct) and of
    the others (indirect), before the energy scale; ``glossy`` (h·w, 3) the part gathered at
    glossy shading points; ``cut`` (h·w, 1) mean cut size; ``complete`` (h·w,) every shading
    point of the pixel was gathered; ``through_energy`` Σ_pixels Y of the part gathered at
    points reached through mirrors and smooth glass (:func:`.vpl.follow_specular`: light
    that P, the energy of delta-free paths, does not count)."""

    parts: NDArray
    glossy: NDArray
    cut: NDArray
    complete: NDArray
    through_energy: float = 0.0


def per_pixel(values: NDArray, n_pixels: int, S: int) -> NDArray:
    """Average the S shading points of each pixel: (n_pixels·S, C) → (n_pixels, C)."""
    if S == 1:                       # the default: a view (the mean over 1 costs 0.1 s at 1080p)
        return values.reshape(n_pixels, -1)
    return values.reshape(n_pixels, S, -1).mean(axis=1)


def per_pixel_parts(values: NDArray, S: int) -> NDArray:
    """(K, n_pixels·S, 3) → (K, n_pixels, 3): :func:`per_pixel` of each part."""
    K, Q = values.shape[:2]
    if S == 1:
        return values.reshape(K, Q, 3)
    return values.reshape(K, Q // S, S, 3).mean(axis=2)


class Gather:
    """Phase 5 of one render (module docstring).

    Args:
        scene, settings: the render's.
        g: the G-buffer (shading points).
        gather_batch: largest batch of shading points the memory plan allows.
    """

    def __init__(self, scene: BuiltScene, settings: RenderSettings, g: GBuffer, gather_batch: int,
                 iteration: int = 0):
        self.scene, self.settings, self.g = scene, settings, g
        self.gather_batch = gather_batch
        self.iteration = iteration
        self.interp: Interpolation | None = None

    def _plan_interpolation(self, stats: dict, schedule: Schedule) -> NDArray:
        """Plan the gather's interpolation (:mod:`.interpolation`; ≈ 2 s at 1080p, polling
        progress and Esc); (Q,) bool the points to gather."""
        s, window = self.settings, self.scene.camera.window
        k = s.gather_spacing or auto_spacing(window.n_pixels)
        if s.gather == "BRUTE_FORCE":       # the exact ablation: no spacing; a pixel's further
            k = 1                           # points still take its first point's light
        if k > 1 or self.g.samples > 1:
            self.interp = plan_interpolation(
                self.g, self.scene, window.width, window.height, k, grid_offset(k, self.iteration),
                keep_going=lambda: schedule.clock.poll(schedule.fraction("Lightcuts", 0.0),
                                                       "Lightcuts: planning the interpolation"))
        stats["gather_spacing"] = k if self.interp is not None else 1
        n_valid = max(int(np.count_nonzero(self.g.valid)), 1)
        stats["gather_interpolated"] = 0.0 if self.interp is None else len(self.interp.target) / n_valid
        return self.g.valid if self.interp is None else self.interp.gathered(self.g.valid)

    def _filled(self, L: NDArray, done_pt: NDArray, copy: bool = False) -> tuple[NDArray, NDArray]:
        """``L`` (2, Q, 3) and ``done_pt`` (Q,) with the interpolated points set (in place
        unless ``copy``)."""
        if self.interp is None:
            return L, done_pt
        if copy:
            L, done_pt = L.copy(), done_pt.copy()
        done_pt[self.interp.target] = self.interp.fill(L, done_pt)
        return L, done_pt

    def run(self, vpls, tree, gmax: float, schedule: Schedule, stats: dict, show,
            rival: DirectRival | None = None) -> Gathered:
        """VPL light at every shading point; ``show(points)`` after every batch (preview;
        ``points()`` returns the light parts (2, Q, 3) and (Q,) the points done so far, for
        the caller to call — and reduce to pixels — only when a preview is due: per batch,
        that reduction alone cost ≈ 4 s per 1080p pass). Points the gather interpolates
        (:mod:`.interpolation`, ``gather_spacing``) are filled from their anchors after
        every whole pass.
        ``rival``: the direct-light passes, which may take spare time instead of further
        gather passes (:mod:`.balance`).

        Cancelling (or running out of time) stops after the current batch; a cancel during a
        lightcut batch stops its refinement, so the batch keeps coarser but complete cuts.
        The stochastic gather makes ``stochastic_passes`` whole passes (new VPL draws,
        :data:`PASS_SALT`; fewer if the iteration's time runs out) and averages them; in a
        paced iteration that no other will follow (:meth:`~.pacing.Schedule.fills_time`) it
        repeats passes while the time left holds another one: its error is noise, so the
        budget the bounded gather would spend on refinement goes into averaging instead.
        """
        s, g, window = self.settings, self.g, self.scene.camera.window
        S = g.samples
        pts_all = spread_order(np.flatnonzero(self._plan_interpolation(stats, schedule)), s.seed)

        def preview(point_parts, done):     # the interpolated points filled only when shown
            show(lambda: self._filled(point_parts, done, copy=True))
        clock = schedule.clock
        warm_up.wait(lambda: clock.poll(schedule.fraction("Lightcuts", 0.0),
                                        "Lightcuts: compiling the kernels (first render only)"))
        if clock.cancelled:
            stats["gather_incomplete"] = 1          # cancelled while planning or compiling
        if len(vpls) == 0 or clock.cancelled:
            pts_all = pts_all[:0]
        sweep = _Sweep(self, vpls, tree, gmax, schedule, stats, pts_all)
        comp = self._compensation(sweep, gmax, schedule, stats) if len(pts_all) else None
        t0 = time.perf_counter()
        L, cut, done_pt, done = sweep.run(0, preview)
        self._filled(L, done_pt)
        if len(vpls) == 0 and not clock.cancelled:
            done_pt[:] = True       # no VPL light anywhere: every point is complete (with 0)
        passes = 1.0
        if s.gather == "STOCHASTIC" and done == len(pts_all) and len(pts_all):
            L, passes = self._more_passes(sweep, L, time.perf_counter() - t0, schedule, preview, done_pt,
                                          rival)
        stats["gather_passes"] = passes
        if comp is not None:
            L[1] += comp
        sweep.record(stats, done, cut)
        if self.interp is not None:
            self.interp.fill_values(cut)
        glossy = self._glossy(done_pt & g.valid)
        through = 0.0
        if g.through is not None:
            through = float(luminance(L[:, g.through].sum(axis=(0, 1)))) / S
        return Gathered(parts=per_pixel_parts(L, S),
                        glossy=per_pixel(L.sum(axis=0) * glossy[:, None], window.n_pixels, S),
                        cut=per_pixel(cut[:, None], window.n_pixels, S),
                        complete=done_pt.reshape(-1, S).all(axis=1), through_energy=through)

    def _compensation(self, sweep: "_Sweep", gmax: float, schedule: Schedule, stats: dict) -> NDArray | None:
        """(Q, 3) the clamp's bias compensation at every gathered shading point (the
        interpolated ones take their anchors', :mod:`.interpolation`;
        :mod:`.bias_compensation`), or None when the render does not compensate
        (:func:`~.bias_compensation.compensates`). L_o at the surfaces found is the direct
        light by light sampling plus this gather's clamped VPL estimate there. Runs before
        the sweep so that the sweep's pacing sees the time it took; a cancel stops it between
        chunks (the gather then stops too)."""
        s, g, scene = self.settings, self.g, self.scene
        if not compensates(s, gmax):
            return None
        pts = np.sort(sweep.pts_all)
        out = np.zeros((len(g.pixel), 3))
        near, t0 = 0, time.perf_counter()
        m = compensation_rays(len(pts))
        step = max(COMPENSATION_CHUNK // m, 1)
        for start in range(0, len(pts), step):
            idx = pts[start:start + step]
            rng = np.random.default_rng([s.seed, COMPENSATION_SALT, self.iteration, start])

            def radiance_at(p, ng, ns, wo, mat):
                bsdf = scene.bsdf(mat, ns, ng, p)
                L = sweep.radiance(self.shading_points_at(p, ng, ns, wo, mat, bsdf), rng)
                if not scene.lights.empty:
                    L = L + next_event(scene, SimpleNamespace(p=p, ns=ns, ng=ng), wo, bsdf, rng)
                return L

            got, hit = compensate(scene, gmax, g.p[idx], g.ng[idx], g.ns[idx], g.wo[idx], g.mat[idx], rng,
                                  radiance_at, rays=m, emission_mis=True)
            out[idx] = got if g.weight is None else got * g.weight[idx]
            near += int(np.count_nonzero(hit))
            f = (start + len(idx)) / len(pts)
            if not schedule.clock.poll(schedule.fraction("Lightcuts", 0.0),
                                       f"Lightcuts: clamp compensation {100 * f:.0f}%"):
                break
        if self.interp is not None:     # the interpolated points: from their anchors
            self.interp.fill(out[None], np.ones(len(out), bool))
        stats["compensated_points"] = near / max(len(pts), 1)
        stats["compensation_rays"] = m
        stats["compensated_energy"] = float(luminance(out.sum(axis=0))) / g.samples
        stats["compensation_seconds"] = time.perf_counter() - t0
        return out

    def _more_passes(self, sweep: "_Sweep", L: NDArray, t_pass: float, schedule: Schedule, show,
                     done_pt: NDArray, rival: DirectRival | None = None) -> tuple[NDArray, float]:
        """Passes 2 … ``stochastic_passes`` of the stochastic gather (more while the time left
        holds them when the iteration fills its time, asked again after every pass: once the
        passes are done, time that no later iteration would use goes into more passes — or,
        pass by pass, into more direct-light passes of ``rival`` when that lowers the image's
        error more per second, :mod:`.balance`; in a paced iteration the rival competes from
        the first pass on, after a variance probe, :meth:`_probe` — in one that later
        iterations follow, for the second pass's time and no more), each point's estimate the
        mean of its passes.
        A pass the iteration's time cuts short keeps the points it reached (spread over
        the image by :func:`spread_order`): each pass is an unbiased estimate per point, so a
        mean over 1 or 2 passes is too. Returns the mean (2, Q, 3) and the passes made
        (fractional for a cut-short last one)."""
        s, n_pts, S = self.settings, len(sweep.pts_all), self.g.samples
        n_pixels = len(self.g.pixel) // S
        total, count, passes = L.copy(), np.ones(len(self.g.pixel)), 1.0
        spread = PassVariance(n_pixels)
        spread.add(_pixel_luminance(L, n_pixels, S))
        fills = schedule.fills_time()
        early = rival is not None and (schedule.paced if RIVAL_IN_EVERY_PACED else fills) \
            and self._probe(sweep, L, spread)
        # direct passes the rival may take: in an iteration later ones follow, as many as fit
        # in the time of the gather's second pass
        budget = np.inf if fills or rival is None else max(1, int(round(t_pass / max(rival.seconds, 1e-9))))
        lent = 0
        while (passes < s.stochastic_passes or schedule.fills_time()) and not schedule.clock.cancelled \
                and schedule.remaining() > PASS_START * t_pass:
            if rival is not None and (passes >= s.stochastic_passes or early) \
                    and schedule.remaining() > RIVAL_START * rival.seconds:
                ref = spread.mean() + rival.variance.mean()
                if rival.gain(ref) > spread.gain(ref, t_pass):
                    if lent >= budget and not schedule.fills_time():   # the second pass's time
                        break                                           # is spent: end here
                    if not rival.step():
                        break
                    lent += 1
                    continue
            t0 = time.perf_counter()
            L2, _, done_pt2, done2 = sweep.run(int(passes), lambda parts, c: None)
            pts = sweep.pts_all[:done2]
            if done2 == n_pts and self.interp is not None:      # a whole pass: fill it too
                self._filled(L2, done_pt2)
                pts = np.r_[pts, self.interp.target]
            total[:, pts] += L2[:, pts]
            count[pts] += 1
            passes += done2 / n_pts
            show(total / count[None, :, None], done_pt)
            if done2 < n_pts:
                break
            spread.add(_pixel_luminance(L2, n_pixels, S))
            t_pass = 0.5 * (t_pass + time.perf_counter() - t0)
        return total / count[None, :, None], passes

    def _probe(self, sweep: "_Sweep", L: NDArray, spread: PassVariance) -> bool:
        """Draw the first pass again at a spread subsample of its points (:data:`PROBE_POINTS`,
        :data:`PROBE_SHARE`, a few % of a pass) so that ``spread`` knows the gather's variance
        before its second pass, and the direct-light passes may compete for the time of that
        one already (:mod:`.balance`). False when it was cut short."""
        S, n_pts = self.g.samples, len(sweep.pts_all)
        k = min(n_pts, max(PROBE_POINTS, int(PROBE_SHARE * n_pts)))
        L2, done = sweep.probe(k)
        if done < k or k == 0:
            return False
        pts = sweep.pts_all[:k]
        pix = self.g.pixel[pts]
        n_pixels = len(self.g.pixel) // S
        # per pixel and pass the S points' mean: a point's variance / S; with interpolation
        # a pixel's points take their light from one gathered anchor: its variance
        norm = 1.0 if self.interp is not None else np.sqrt(S)
        a, b = (luminance(x[:, pts].sum(axis=0)) / norm for x in (L, L2))
        lit = len(np.unique(self.g.pixel[sweep.pts_all]))   # pixels with a gathered point
        spread.probe(pix, a, b, lit / n_pixels)
        return True

    def _glossy(self, gathered: NDArray) -> NDArray:
        """(Q,) shading points with a specular lobe of roughness < :data:`GLOSSY_ROUGHNESS`,
        among the ``gathered`` ones (after a cancel, only those: no whole-image pass then)."""
        g, scene = self.g, self.scene
        h = np.flatnonzero(gathered)
        out = np.zeros(len(g.pixel), bool)
        if len(h):
            bsdf = scene.bsdf(g.mat[h], g.ns[h], g.ng[h], g.p[h])
            out[h] = (~bsdf.is_diffuse & ~bsdf.delta    # delta lobes receive no VPL light
                      & (scene.roughness(g.mat[h], g.p[h]) < GLOSSY_ROUGHNESS))
        return out

    def _shading_points(self, idx: NDArray) -> ShadingPoints:
        """The lightcut shading points of G-buffer entries ``idx`` (:meth:`shading_points_at`;
        the materials' bound ``bsdf_max_value`` computed per batch so that no whole-image pass
        delays the first progress report)."""
        g = self.g
        return self.shading_points_at(g.p[idx], g.ng[idx], g.ns[idx], g.wo[idx], g.mat[idx])

    def shading_points_at(self, p: NDArray, ng: NDArray, ns: NDArray, wo: NDArray, mat: NDArray,
                          bsdf=None) -> ShadingPoints:
        """Lightcut shading points at surface points (normals flipped toward ``wo``): BSDF and
        visibility callbacks, the materials' bound ``bsdf_max_value`` at diffuse points,
        :class:`.lightcuts.GlossyReceivers` at glossy ones; ``bsdf`` their BSDFs if built."""
        scene = self.scene
        if bsdf is None:
            bsdf = scene.bsdf(mat, ns, ng, p)

        def eval_f(k, wi):
            return bsdf.subset(k).eval(wo[k], wi)

        def visible(k, q, qn):
            return scene.tracer.visible(p[k], ng[k], q, qn)

        # Glossy points: per-cluster GGX bound (f_bound is no bound for a glossy lobe)
        glossy = (GlossyReceivers.from_bsdf(bsdf, wo, ns)
                  if GLOSSY_CLUSTER_BOUND and not bsdf.all_diffuse else None)
        f_bound = scene.bsdf_max_value(mat, p)
        # Rough glass and translucent surfaces transmit VPL light from the far side: |cos θ_x|
        # there, as the VPLs' normalisation (vpl.vpl_radiance) counts it
        through = ((bsdf.p_tr > 0.0) & ~bsdf.delta) | bsdf.translucent
        transmissive = through if through.any() else None
        return ShadingPoints(p, ns, wo, f_bound, eval_f, visible,
                             transmissive=transmissive, glossy=glossy)


class _Sweep:
    """One pass of the gather over the shading points ``pts_all`` (in batches, paced, with
    progress); :meth:`run` may be called again for another pass of the stochastic gather."""

    def __init__(self, gather: Gather, vpls, tree, gmax: float, schedule: Schedule,
                 stats: dict, pts_all: NDArray):
        self.gather, self.vpls, self.tree, self.schedule = gather, vpls, tree, schedule
        self.pts_all = pts_all
        scene, s, window = gather.scene, gather.settings, gather.scene.camera.window
        # Absolute error floor (algorithm.md §G.6; not in the papers): below a small fraction
        # of the mean pixel luminance, Weber's law no longer applies (dark pixels would refine
        # to max_cut_size for errors nobody can see).
        self.floor = s.max_error * ABS_FLOOR * stats.get("P", 0.0) / max(window.n_pixels, 1)
        self.clamp = 0.0 if not np.isfinite(gmax) else gmax
        self.share = emitter_share(tree, vpls) if tree is not None else None
        self.cdf = leaf_cdf(tree) if tree is not None and s.gather == "STOCHASTIC" else None
        self.rays, self.clamped, self.unmet, self.shared = 0, 0.0, 0, 0
        self.stats = stats
        # The stochastic gather has no error threshold to raise: its pacing caps the cut at once.
        self.pace = (GatherPace(MAX_PACED_ERROR, s.stochastic_cut_size) if s.gather == "STOCHASTIC"
                     else GatherPace(s.max_error, s.max_cut_size))
        self.pass_index = 0
        self.planned = s.stochastic_passes if s.gather == "STOCHASTIC" else 1

    def _report(self, f_done: float, within_iteration: bool = False) -> bool:
        """Report progress; False when cancelled or out of time (the render's, and with
        ``within_iteration`` the iteration's: a repeated pass must not overrun it)."""
        clock = self.schedule.clock
        # pass p of the planned ones covers [p, p + 1] / planned of the phase (further passes
        # that fill the time stay at its end)
        f = min((self.pass_index + f_done / max(len(self.pts_all), 1)) / self.planned, 1.0)
        return clock.poll(self.schedule.fraction("Lightcuts", f),
                          f"Lightcuts {100 * f:.0f}% | {self.rays / 1e6:.2f}M shadow rays") \
            and clock.remaining() > 0 and (not within_iteration or self.schedule.remaining() > 0)

    def run(self, pass_index: int, show, count: int | None = None) -> tuple[NDArray, NDArray, NDArray, int]:
        """Gather pass ``pass_index`` over ``pts_all`` (its first ``count`` only, if given):
        (2, Q, 3) light parts, (Q,) cut sizes, (Q,) points done and the number of those
        points done (fewer when stopped)."""
        ga, s = self.gather, self.gather.settings
        pts_all = self.pts_all if count is None else self.pts_all[:count]
        self.pass_index = pass_index
        g = ga.g
        Q = len(g.pixel)
        L = np.zeros((2, Q, 3))              # [from emitter VPLs, from the others]
        cut = np.zeros(Q)
        done_pt = ~g.valid                   # misses need no gather
        done, pace, stopped = 0, self.pace, False
        # A small first batch calibrates the cost per point before the cap is fitted.
        step = min(ga.gather_batch, PROGRESS_GATHER_POINTS)
        edges = np.unique(np.r_[0, np.arange(min(256, len(pts_all)), len(pts_all), step), len(pts_all)])
        for start, stop in zip(edges[:-1], edges[1:]):
            idx = pts_all[start:stop]
            t_batch = time.perf_counter()
            if not self._batch(idx, start, pass_index, L, cut):
                stopped = True                  # brute force: the batch was abandoned
                break
            if g.weight is not None:            # points seen in mirrors, through glass
                L[:, idx] *= g.weight[idx]
            done = start + len(idx)
            done_pt[idx] = True
            if pass_index == 0:
                pace.update(len(idx), time.perf_counter() - t_batch, cut[idx].mean(),
                            len(pts_all) - done, self.schedule.remaining())
            if not self._report(done, within_iteration=pass_index > 0) and done < len(pts_all):
                stopped = True
                break
            show(L, done_pt)
        if stopped and pass_index == 0:
            self.stats["gather_incomplete"] = 1
            self.schedule.clock.cancelled = True
        return L, cut, done_pt, done

    def radiance(self, pts: ShadingPoints, rng: np.random.Generator) -> NDArray:
        """(P, 3) the clamped VPL light at any shading points (the bias compensation's
        surfaces, :mod:`.bias_compensation`) by the gather's method: a stochastic cut of
        :data:`COMPENSATION_CUT` nodes, a lightcut to ``max_error`` or every VPL."""
        s, vpls, tree = self.gather.settings, self.vpls, self.tree
        if s.gather == "BRUTE_FORCE":
            self.rays += pts.count * len(vpls)
            return brute_force(vpls.position, vpls.normal, vpls.intensity, pts, clamp=self.clamp,
                               keep_going=lambda: True)
        if s.gather == "STOCHASTIC":
            res = stochastic_lightcut(tree, vpls.position, vpls.normal, vpls.intensity, pts, rng,
                                      cut_size=min(s.stochastic_cut_size, COMPENSATION_CUT),
                                      clamp=self.clamp, cdf=self.cdf)
        else:
            res = lightcut(tree, vpls.position, vpls.normal, vpls.intensity, pts, max_error=s.max_error,
                           max_cut_size=s.max_cut_size, clamp=self.clamp, abs_floor=self.floor,
                           error_mode=ERROR_MODES[s.lightcut_error])
        self.rays += res.shadow_rays
        return res.radiance

    def probe(self, k: int) -> tuple[NDArray, int]:
        """Pass :data:`PROBE_PASS` (independent draws) over the first ``k`` of ``pts_all``
        only: ((2, Q, 3) light parts, points done)."""
        L, _, _, done = self.run(PROBE_PASS, lambda parts, c: None, count=k)
        return L, done

    def _batch(self, idx: NDArray, start: int, pass_index: int, L: NDArray, cut: NDArray) -> bool:
        """Gather the points ``idx`` into ``L`` and ``cut``; False when a cancel abandoned
        the batch (brute force only: the cuts of a cancelled lightcut batch stay complete)."""
        s, vpls, tree, pace = self.gather.settings, self.vpls, self.tree, self.pace
        pts = self.gather._shading_points(idx)
        if s.gather == "BRUTE_FORCE":
            for part, sel in enumerate((vpls.emitter, ~vpls.emitter)):
                if sel.any():
                    got = brute_force(vpls.position[sel], vpls.normal[sel], vpls.intensity[sel],
                                      pts, clamp=self.clamp, keep_going=lambda: self._report(start))
                    if got is None:
                        return False
                    L[part, idx] = got
            cut[idx] = len(vpls)
            self.rays += len(idx) * len(vpls)
            return True
        if s.gather == "STOCHASTIC":
            rng = np.random.default_rng([s.seed, PASS_SALT, pass_index, start])
            ref = (share_refs(self.gather.g, idx, s.stochastic_cut_sharing,
                              self.gather.scene.camera.window.width)
                   if s.stochastic_cut_sharing > 1 else None)
            res = stochastic_lightcut(tree, vpls.position, vpls.normal, vpls.intensity, pts,
                                      rng, cut_size=min(pace.cap, s.stochastic_cut_size),
                                      clamp=self.clamp, cdf=self.cdf, ref=ref)
            if ref is not None:
                self.shared += int(np.count_nonzero(ref != np.arange(len(idx))))
        else:
            res = lightcut(tree, vpls.position, vpls.normal, vpls.intensity, pts,
                           max_error=pace.error, max_cut_size=pace.cap, clamp=self.clamp,
                           abs_floor=self.floor, error_mode=ERROR_MODES[s.lightcut_error],
                           return_cut=True, on_round=lambda: self._report(start))
        em = _sum_rows(res.cut_point, res.cut_estimate * self.share[res.cut_node], len(idx))
        L[0, idx], L[1, idx], cut[idx] = em, res.radiance - em, res.cut_size
        self.rays += res.shadow_rays
        self.clamped += res.clamped_energy
        self.unmet += int(res.unmet.sum())
        return True

    def record(self, stats: dict, done: int, cut: NDArray) -> None:
        """The gather's statistics (first pass's cuts; rays and clamp of every pass)."""
        S = self.gather.g.samples
        self.pace.record(stats, done)
        valid_cut = cut[self.pts_all[:done]] if done else np.zeros(1)
        stats["cut_size_mean"] = float(valid_cut.mean()) if done else 0.0
        stats["cut_size_max"] = int(valid_cut.max()) if done else 0
        # Points whose cut hit the size cap (or the pacing) before the error rule held.
        stats["cut_bound_unmet"] = self.unmet / done if done else 0.0
        stats["gather_shadow_rays"] = self.rays
        if self.gather.settings.gather == "STOCHASTIC" and self.gather.settings.stochastic_cut_sharing > 1:
            # share of the gathered points that used a neighbour's cut (the rest: block heads, edges)
            stats["shared_cut_fraction"] = self.shared / max(done * stats.get("gather_passes", 1), 1)
        stats["clamped_energy"] = self.clamped / S / stats.get("gather_passes", 1)


def spread_order(points: NDArray, seed: int) -> NDArray:
    """``points`` in a shuffled order of runs of :data:`GATHER_RUN` (deterministic per
    seed): every gather batch samples the whole image (for pacing and an even partial
    image) while neighbouring points stay together (coherent shadow rays)."""
    runs = np.arange(0, len(points), GATHER_RUN)
    order = np.random.default_rng([seed, 0x6A7]).permutation(len(runs))
    starts = runs[order]
    idx = (starts[:, None] + np.arange(GATHER_RUN)[None, :]).ravel()
    return points[idx[idx < len(points)]]


def share_refs(g: GBuffer, idx: NDArray, block: int, width: int) -> NDArray:
    """(P,) for the batch's points ``idx`` (G-buffer entries in gather order), the local index
    of the point whose stochastic cut each uses: the head of its block of ``block``
    consecutive points when both lie on one surface (:func:`.interpolation.same_surface`) in
    one row, else itself.  Which cut a point uses changes only its noise: the
    shared cut keeps its empty clusters (:func:`.stochastic_lightcuts.shared_cut`)."""
    j = np.arange(len(idx))
    head = j - j % block
    alike = (g.pixel[idx] // width == g.pixel[idx[head]] // width) & same_surface(g, idx[head], idx)
    return np.where(alike, head, j)


def emitter_share(tree, vpls) -> NDArray:
    """(n_nodes, 3) fraction of each light-tree node's intensity that comes from emitter VPLs
    (the subtree sums of ``vpls.emitter`` intensities over the node's intensity)."""
    em = vpls.intensity * vpls.emitter[:, None]
    cs = np.vstack([np.zeros((1, 3)), np.cumsum(em[tree.leaf_order], axis=0)])
    sub = cs[tree.leaf_start + tree.leaf_count] - cs[tree.leaf_start]
    return np.divide(sub, tree.intensity, out=np.zeros_like(sub), where=tree.intensity > 0)


def _pixel_luminance(L: NDArray, n_pixels: int, S: int) -> NDArray:
    """(n_pixels,) luminance of a gather pass's (2, Q, 3) light, averaged per pixel."""
    return per_pixel(luminance(L.sum(axis=0))[:, None], n_pixels, S)[:, 0]


def _sum_rows(group: NDArray, values: NDArray, n: int) -> NDArray:
    """(n, 3) per-group sums of (K, 3) rows."""
    return np.stack([np.bincount(group, weights=values[:, c], minlength=n) for c in range(3)], axis=1)
