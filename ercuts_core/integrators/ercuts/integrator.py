"""The Ercuts integrator (Zhu, Xu, Pan 2010): BDPT → ER chains → VPLs → light tree → lightcuts.

Phases (each a module named after the paper's step):

1. :mod:`.initialization` (seed paths: :mod:`.seeding`) — rough BDPT image, its energy P (paths with a
   surface x2 that VPLs stand for), and fresh seed paths;
2. :mod:`.er_sampling` — equal-length Markov chains, each state worth e_d = P/n;
3. :mod:`.vpl` — a VPL at every chain's x2, merged by identity, normalised;
4. :mod:`.light_tree` — the binary light tree with the paper's pairing weight;
5. :mod:`.lightcuts` — per shading point, a cut refined until the error
   bound is under ``max_error`` of the estimate.

Direct light (``direct_light``). With 'NEE' (the default) the light that reaches the
camera directly or after one scattering — emitters and world seen directly, and direct
light from every light — is rendered in its own phase after the rough image, ``direct_samples``
jittered (anti-aliased) passes of next-event estimation with MIS (:meth:`_direct_light`);
the chains are restricted to indirect paths (x2 scatters, k ≥ 3), P is the rough image's
indirect energy, and the VPLs carry indirect light only. VPLs standing for area lights
(the paper's and Lightcuts' representation, kept as 'VPL') make soft shadows blotchy and,
through the per-VPL normalisation 1/Ê1 of VPLs that light few pixels, give occasional
bright faces (directly lit benchmark scene, 10 s: relMSE 0.005–0.29 over three seeds).
With 'VPL' the image is the sum of what the VPLs cannot represent — light seen directly
and direct light from point, spot, sun and environment lights, by next-event estimation at
the shading points — and the VPL gather. Either way the ERPT fallback of VPLs that lit no
sampled pixel is added.

Time: with ``time_limit`` > 0 each phase gets its share of the time left
(:mod:`.pacing`; fewer E1 samples per VPL if needed), and the gather (:mod:`.gather`) raises
the lightcut error threshold (or lowers it back toward ``max_error``) so the rest fits the
time left; a phase that runs out stops cleanly (fewer passes, shorter chains, coarser cuts)
and the stats say so.

Progress and cancellation (api.md): messages start with the phase ("BDPT", "Direct light",
"ER chains", "VPLs", "Light tree", "Lightcuts", fractions in :data:`.pacing.PHASES`); previews show
the rough image after each BDPT pass and the image so far during the gather. A cancel (or
the time limit) before the gather returns the rough BDPT image; during the gather, the
pixels gathered so far (the current batch finishes with coarser cuts) and the rough image
elsewhere.

Passes (``RenderResult.aovs``), per pixel:

* 'emission' — emitters and world seen directly ('NEE': of the direct passes; 'VPL': of
  the first shading point);
* 'direct' — 'NEE': the direct passes' light scattered once; 'VPL': next-event light from
  point, spot, sun and environment lights, plus the gathered light of *emitter VPLs* (x2
  is the chain path's light vertex, k = 2: light from an area light or emissive mesh
  scattered once, at x1) and their fallback deposits;
* 'indirect' — the gathered light of all other VPLs (x2 scatters) and their fallback.
  The split of a lightcut cluster follows its intensity: the estimate M·G·V·I_C of a cut
  node is divided by the node's share of emitter-VPL intensity. emission + direct +
  indirect is the image. Light in a pass is the image's (after the global energy scale),
  so the split is as good as the VPL image; BDPT/PATH classify every path exactly.
* 'vpl_density' (h, w, 1) — the number of (merged, normalised) VPLs whose position the
  camera sees in the pixel (projected, unoccluded): where the light sources of the
  gather sit.
* 'er_caustic' (h, w, 3) — the ER chain energy that does not reach the pixel through a
  diffuse-looking VPL: the gathered VPL light at *glossy* shading points (a specular lobe
  with roughness < :data:`GLOSSY_ROUGHNESS`, where the paper renders caustic paths by ERPT
  instead) plus the ERPT fallback deposits of VPLs that lit no sampled pixel. This
  implementation deposits no separate caustic ERPT energy (every chain state deposits into
  its VPL; paths through delta lobes are path-traced, below), so er_caustic is a *part* of
  direct + indirect, not an addition to the image; 0 in scenes without glossy surfaces and
  fallback deposits.
* 'cut_size' (h, w, 1) mean lightcut size, 'chain_deposits' (h, w, 1) chain states whose
  x1 lies in the pixel, and 'depth', 'normal', 'albedo' of the first shading point.

Mirrors and glass (delta lobes and the glass lobe, :mod:`ercuts_core.bsdf`). A VPL cannot
light a delta lobe nor shine through glass, nor stand for light leaving a delta lobe, so the
light is split by path. (1) The gather's shading points follow the camera through mirrors
and glass to the first other surface (:func:`~.vpl.follow_specular`, algorithm.md §G.3):
what a mirror shows or a window lets through is gathered from the VPLs there, weighted by the
mirror's and glass's sample weights (with ``direct_light='NEE'``; the ablation
:data:`FOLLOW_SPECULAR` = False gathers at the first hit). (2) Every path with a delta event
outside that camera-side prefix (caustics, a lamp behind glass, light a mirror throws on a
wall), and light seen directly or scattered once beyond the prefix, is path-traced with
next-event estimation and MIS in the direct-light passes
(``PathIntegrator(paths='direct_and_late_delta')``; without following,
``paths='direct_and_delta'``: every delta path; ``paths='delta'`` with
``direct_light='VPL'``). (3) The chains carry the delta-free paths only: P leaves out the
rough BDPT image's delta paths (``stats['P_delta']``, BDPT's own count, light tracing
included; ``stats['P_traced']`` the part the direct passes render, which sizes their
phase), the chains reject delta events, BDPT seeds through a delta vertex are dropped, and
delta lobes' lightcut bounds are 0. Scenes without mirrors and glass
(``BuiltScene.has_specular_or_glass``) are rendered exactly as before.

Spare time (:mod:`.balance`): when the last iteration fills its time, each further pass goes
to the direct-light passes or to the stochastic gather, whichever lowers the image's measured
error more per second.

Iterations are averaged, except the direct-light passes ('NEE'): each of their passes is an
independent estimate of the same light, so the image holds the mean over *all* passes of all
iterations (:attr:`~ercuts_core.film.Film.pooled`), not the mean of the iterations' means — an
iteration's pass count follows its time (the directly lit scene at 60 s: 64 and 258). Measured
there (160×120, seeds 0–3): relMSE 5.1 / 5.5 / 5.2 / 6.6·10⁻⁵ against 6.7–9.1·10⁻⁵ (seeds 0, 1,
six runs) with the mean of means.
"""
from __future__ import annotations

import time
from contextlib import contextmanager

import numpy as np
from numpy.typing import NDArray

from ...film import Film
from ...lights import ENV, POINT, SUN
from ...memory import MemoryPlan, plan
from ...sampling import luminance
from ...scene import BuiltScene
from ...settings import RenderSettings
from ...vecmath import dot
from ..base import Clock, batch_pixels, progress_batch_pixels, run_passes
from ..bdpt import BDPTIntegrator
from ..path import MAX_LIGHT_SAMPLES, PathIntegrator
from .balance import DirectRival, PassVariance, light_samples_for, passes_at_equal_cost
from .bias_compensation import compensates
from .er_sampling import chain_starts, run_chains
from .gather import Gather, Gathered, per_pixel, per_pixel_parts
from .late_paths import direct_passes
from .initialization import (ROUGH_MIN_PASSES, ROUGH_P_ERROR, RoughImage, indirect_energy, p_relative_error,
                             rough_camera, rough_factor, rough_image_energy, scene_with_camera,
                             seeds_from_path_tracer)
from .light_tree import build_light_tree
from .mutations import INACTIVE, NAMES, MutationContext
from .pacing import Schedule
from .progressive import (iteration_end, iteration_settings, iteration_target, more_iterations,
                          paced_iteration, shrunk_settings, stratified_jitter)
from .paths import PathBatch
from .seeding import seed_order, seed_paths, seed_pixels
from . import warm_up
from .vpl import (PIXEL_SAMPLE_RATE, SPECULAR_BOUNCES, GBuffer, build_gbuffer,
                  first_hits_only, follow_specular, g_clamp, make_vpls, paced_vpl_share, thin_vpls)

#: The gather shades what perfect mirrors show and smooth glass lets through with the VPLs
#: (algorithm.md §G.3, :func:`~.vpl.follow_specular`); False = the ablation: every path with
#: a delta event is path-traced in the direct-light passes (before issue 15's follow-up).
FOLLOW_SPECULAR = True
#: Light samples at the first camera hit in an iteration's first two direct-light passes, the
#: pilot from which :func:`~.balance.light_samples_for` chooses the later passes' count
#: (:func:`~..path.next_event_stratified`, padded Sobol points: one camera ray and hit serve
#: several shadow rays where soft shadows are most of the variance). Directly lit scene,
#: 160×120, 5 s of direct passes, 3 seeds, against a converged direct image: relMSE 6.5e-5
#: with 1, 4.6e-5 with 2, 2.4–2.7e-5 with 4, 3.0e-5 with 8; Cornell box 9.7e-5, 8.3e-5,
#: 1.4e-4 with 1, 2, 4 (its small panel's shadows are sharp: the pixel's jitter dominates).
#: None: one light sample throughout (the ablation).
PILOT_LIGHT_SAMPLES: int | None = 2
#: Conservative throughput of the E1 estimate (light-traced samples per second, 2 cores; a
#: share ``vpl.PIXEL_SAMPLE_RATE`` of them comes with a pixel sample of about the same cost)
#: for the first paced iteration; later ones use the rate the render measured (samples per
#: VPL × VPLs per second of the VPL phase: 2.3–2.4 × 10⁶ on the directly lit scene, 160×120).
_E1_RATE = 1.0e6
#: A paced iteration traces seed paths for at most this share of the ER chains' time share
#: (:meth:`ErcutsIntegrator._seed_deadline`): 81 920 chains need ≈ 330 000 seed pixels (38 s
#: at 1280×720), which at 640×480 in 120 s left the chains 12 of their 21 steps.
SEED_SHARE = 0.5
#: Largest E1 chunk (samples) for progress reports every ~0.25 s of work.
PROGRESS_E1_CHUNK = 1 << 16


class _Stopped(Exception):
    """Cancelled, or out of time, before the gather: the rough BDPT image is the result."""


class ErcutsIntegrator:
    """Runs the five phases on a built scene (see the module docstring)."""

    def __init__(self, scene: BuiltScene, settings: RenderSettings, memory: MemoryPlan | None = None):
        self.scene = scene
        self.settings = settings
        self.memory = memory or plan(scene.camera.window.n_pixels, scene.desc.mesh.n_triangles, settings)
        #: Ê1 samples per second measured by the render's last complete VPL phase (None: not yet).
        self.e1_rate: float | None = None

    # ------------------------------------------------------------------ driver
    def render(self, film: Film, clock: Clock, timings: dict, stats: dict) -> None:
        """Render ``settings.iterations`` iterations into ``film`` (:mod:`.progressive`; 0: as
        many as the time limit allows) and average them. Under a time limit the first
        iteration, and one the time left would not hold at full quality, are paced to finish
        in time (:func:`~.progressive.paced_iteration`); the others run at full quality. The
        first iteration stopped early (cancel, time limit) leaves the rough BDPT image (before
        the gather) or the rough image where not gathered; a later one stopped early is
        discarded, so the image is the average of the completed iterations (the direct-light
        passes pooled over them, module docstring)."""
        base, window = self.settings, self.scene.camera.window
        warm_up.start()                     # compile the gather's kernels during phases 1–4
        target = iteration_target(base.iterations, clock.deadline is not None)
        k, durations = 0, []
        while True:
            t0 = time.perf_counter()
            index = base.iteration_start + k
            self.settings, self.iteration, self.base_seed = iteration_settings(base, index), index, base.seed
            part = film if k == 0 else Film(window)
            it_timings, it_stats = (timings, stats) if k == 0 else ({}, {})
            span = None if target is None else (k / target, (k + 1) / target)
            paced = paced_iteration(k, target, clock, durations)
            if paced:
                self.settings = shrunk_settings(self.settings, k, target, clock, durations)
            self.schedule = Schedule(clock, base.direct_vpls, paced=paced, span=span,
                                     end=iteration_end(k, target, clock, t0),
                                     last=target is not None and k + 1 >= target)
            complete = self._iteration(part, clock, it_timings, it_stats)
            stats["iterations_paced"] = stats.get("iterations_paced", 0) + int(self.schedule.paced)
            if k > 0:
                for name, seconds in it_timings.items():
                    timings[name] = timings.get(name, 0.0) + seconds
                if not complete:
                    stats["iterations_discarded"] = 1
                    break
                film.merge(part)
            durations.append(time.perf_counter() - t0)
            k += 1
            stats["iterations"], stats["clamp_last_iteration"] = k, self.settings.clamp
            if not complete or not more_iterations(k, target, clock, durations):
                break
            clock.show(film.image)
        self.settings = base

    def _iteration(self, film: Film, clock: Clock, timings: dict, stats: dict) -> bool:
        """One complete Ercuts estimate into ``film`` (the five phases) on the iteration's
        :attr:`schedule` (:class:`~.pacing.Schedule`: paced, its phases share the
        iteration's time; else they run at full quality and the iteration is abandoned if the
        time runs out). Returns False when stopped early."""
        self.clock, self.timings, self.stats = clock, timings, stats
        self.rough: RoughImage | None = None
        self.direct_rival: DirectRival | None = None      # set by the direct-light phase
        try:
            self._render(film)
        except _Stopped:
            self.rough.fill(film)
            return False
        return not clock.cancelled

    def _render(self, film: Film) -> None:
        s, stats = self.settings, self.stats
        rng = np.random.default_rng([s.seed, 0xE5C7])
        with self._phase("bdpt"):                 # 1. rough BDPT image and P
            rough = self.rough = self._rough_bdpt()
        stats["bdpt_samples"] = rough.passes_done
        stats["rough_resolution"] = rough.film.window.width
        self.clock.show(lambda: rough.full_film().image())    # built only if a preview is due
        P_all = rough.energy()
        follow = self._follows_specular()
        if not s.direct_vpls:     # light seen directly and scattered once: its own passes
            P = rough.indirect_energy()
            # the direct passes also path-trace the paths through mirrors and glass (with
            # ``follow``, those the gather does not take over: late delta events)
            P_vpl = max(P - (rough.traced_indirect if follow else rough.delta_indirect), 0.0)
            self.schedule.grow_direct(1.0 - P_vpl / P_all if P_all > 0 else 0.0)
            with self._phase("direct"):
                base, alpha = self._direct_light("direct_and_late_delta" if follow else "direct_and_delta")
            if follow:      # the chains' paths: no delta event, x1 and x2 not on mirrors or glass
                st = self.stats
                st["P_delta"], st["P_outside"] = rough.delta_indirect, rough.outside_indirect
                st["P_traced"] = rough.traced_indirect
                P = max(P - rough.outside_indirect, 0.0)
            else:
                P = self._without_delta(P, base[2:])
        with self._phase("seeds"):
            self._gbuffer_poll(0.0)
            window = self.scene.camera.window
            S = s.shading_points(window.n_pixels)
            jitter = stratified_jitter(window.n_pixels, S, self.base_seed, self.iteration)
            g, _ = build_gbuffer(self.scene, S, rng, jitter, poll=self._gbuffer_poll)
            first_hits = self._first_hit_aovs(g)
            self._gbuffer_poll(1.0)       # the AOVs take ≈ 0.4 s at 1080p
            if follow:     # the gather's points: what mirrors show and windows let through (§G.3)
                follow_specular(self.scene, g, rng, min(SPECULAR_BOUNCES, s.max_depth - 2))
            if s.direct_vpls:
                base, alpha = self._direct_image(g, rng), self._alpha(g)
                P = max(P_all - float(luminance(base.sum(axis=0)).sum()), 0.0)
                if self.scene.has_delta:
                    delta = self._delta_paths()
                    base = base + delta
                    P = self._without_delta(P, delta)
            stats["P"], stats["P_all"] = P, P_all
            seeds, starts = self._chain_seeds(P, rng)
        with self._phase("chains", check=False):  # 2. ER chains
            chains = self._run_chains(seeds, starts, rng)
        # With a shortened run every chain made the same number of steps: e_d stays P/n.
        n_states = chains.n_chains * chains.steps_done
        e_d = P / n_states if n_states else 0.0
        self._chain_stats(chains, n_states)
        self._check()
        gmax = g_clamp(self.scene, s.clamp)
        with self._phase("vpls"):                 # 3. VPLs
            # compensated: Ê1 of the unclamped image (bias_compensation's module docstring)
            vpls = self._make_vpls(first_hits_only(g), chains, e_d,
                                   np.inf if compensates(s, gmax) else gmax, rng)
        with self._phase("tree"):                 # 4. light tree
            tree = self._light_tree(vpls)
        with self._phase("cuts", check=False):    # 5. lightcuts (or the brute-force ablation)
            gathered = self._gather(g, vpls, tree, gmax, base, alpha)
        if self.direct_rival is not None and self.direct_rival.extra:   # spare time went there too
            stats["direct_samples"] += self.direct_rival.extra
            stats["direct_samples_for_spare_time"] = self.direct_rival.extra
        scale = self._energy_scale(gathered, vpls, P)
        light = self._compose(base, gathered.parts, vpls, scale)
        complete = gathered.complete.all()
        if not complete:                    # cancelled: the rough image where not gathered
            missing = np.flatnonzero(~gathered.complete)
            light[:, missing] = rough.full_parts(missing)[0]
        # the direct passes (the mean of stats['direct_samples'] passes) pooled over the iterations
        n = stats["direct_samples"] if complete and not s.direct_vpls else 0
        film.set_pixels(light - base if n else light, alpha, base * n, n)
        self._finish(film, first_hits, chains, vpls, gathered, scale)

    def _gbuffer_poll(self, f: float) -> None:
        """Progress while the G-buffer is traced; stop the render (:class:`_Stopped`) on Esc."""
        if not self.clock.poll(self.schedule.fraction("ER chains", 0.0),
                               f"ER chains: shading points {100 * f:.0f}%"):
            raise _Stopped

    @contextmanager
    def _phase(self, name: str, check: bool = True):
        """Time the block as ``timings[name]``; then stop the render (:class:`_Stopped`) if it
        was cancelled or ran out of time, unless ``check`` is False."""
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.timings[name] = time.perf_counter() - t0
        if check:
            self._check()

    def _check(self) -> None:
        """Stop the render (:class:`_Stopped`) if it was cancelled or ran out of time."""
        if self.clock.cancelled:
            raise _Stopped

    # ------------------------------------------------------------------ phase 1
    def _rough_bdpt(self) -> RoughImage:
        """``rough_samples`` BDPT passes (fewer if the phase's time share runs out, or once P is
        known to :data:`~.initialization.ROUGH_P_ERROR` after at least ``ROUGH_MIN_PASSES``),
        at 1/k of the resolution when the full one would exceed the sample budget
        (:func:`~.initialization.rough_factor`)."""
        s, cam = self.settings, self.scene.camera
        k = rough_factor(cam.window.n_pixels, s.rough_samples)
        view = self.scene if k == 1 else scene_with_camera(self.scene, rough_camera(cam.desc, k))
        bdpt = BDPTIntegrator(view, s)
        energies: list[float] = []      # each pass's P (the one the chains use), any units

        def on_pass(part: Film) -> bool:
            energies.append(rough_image_energy(part.image()) if s.direct_vpls
                            else indirect_energy(part.light_parts()))
            err = p_relative_error(energies)
            if np.isfinite(err):
                self.stats["P_relative_error"] = err
            return len(energies) >= ROUGH_MIN_PASSES and err <= ROUGH_P_ERROR

        film = self._passes(bdpt, "BDPT", (), "bdpt", show=k == 1, samples=s.rough_samples,
                            on_pass=on_pass)
        rough = RoughImage(film, cam.window, (cam.width, cam.height), (view.camera.width, view.camera.height))
        # (the camera-side estimate of the delta paths' indirect energy, full-window units)
        per_pass = rough.pixel_area / max(film.passes_done, 1)
        rough.delta_indirect = bdpt.delta_indirect * per_pass
        rough.outside_indirect = bdpt.outside_indirect * per_pass
        rough.traced_indirect = bdpt.traced_indirect * per_pass
        return rough

    def _direct_light(self, paths: str) -> tuple[NDArray, NDArray]:
        """``direct_samples`` jittered passes of the light that reaches the camera directly or after
        one scattering (path tracing: next-event estimation from every light with MIS against
        BSDF sampling, emitters and world seen directly) and of the paths through a mirror or
        smooth glass that the VPLs cannot carry (``PathIntegrator(paths=paths)``:
        'direct_and_delta', every one; 'direct_and_late_delta', those the gather does not
        take over when it follows the camera through mirrors and windows), fewer if the
        phase's time share runs out; the rough image stays on screen meanwhile. The first two
        passes take :data:`PILOT_LIGHT_SAMPLES` light samples at the first camera hit, the
        others as many as :func:`~.balance.light_samples_for` finds best from their spread,
        in as many passes as cost what ``direct_samples`` passes with one light sample would
        (:func:`~.balance.passes_at_equal_cost`).

        Returns the passes' (3, h·w, 3) light passes and (h·w,) coverage; the film goes."""
        pilot = PILOT_LIGHT_SAMPLES
        path = direct_passes(self.scene, self.settings, paths, pilot or 1)
        n = self.scene.camera.window.n_pixels
        variance = PassVariance(n)

        def on_pass(part: Film) -> None:
            variance.add(luminance(part.light_parts().sum(axis=0)))

        t0 = time.perf_counter()
        samples = self.settings.direct_samples
        piloted = bool(pilot) and samples > 2
        first = 2 if piloted else samples
        if piloted:
            path.light_spread = np.zeros(n)
        direct = self._passes(path, "Direct light", (0xD1,), "direct", show=False, samples=first,
                              on_pass=on_pass, span=(0.0, first / samples))
        t1 = time.perf_counter()
        if direct.passes_done == first < samples:
            path.set_light_samples(light_samples_for(variance.per_pass(), path.light_spread / first, pilot,
                                                     variance.mean(), MAX_LIGHT_SAMPLES), first)
            path.light_spread = None
            direct = self._passes(path, "Direct light", (0xD1,), "direct", show=False,
                                  samples=passes_at_equal_cost(samples, first, pilot, path.light_samples),
                                  on_pass=on_pass, film=direct, first=first, span=(first / samples, 1.0))
        self.stats["direct_light_samples"] = path.light_samples
        self.stats["direct_samples"] = n_done = direct.passes_done
        base, alpha = direct.light_parts(), direct.alpha / max(n_done, 1)
        # seconds per pass: of the passes after the pilot when there are some
        since, count = (t1, n_done - first) if n_done > first else (t0, n_done)
        seconds = (time.perf_counter() - since) / max(count, 1)
        del direct                                       # (its AOVs are not needed: 1080p memory)

        def one_more() -> bool:
            """One more pass averaged into ``base`` and ``alpha`` in place (the gather's
            spare time, :mod:`.balance`); started only with time for it, so the time limit
            is not checked inside, a cancel is (the render clock's progress callback)."""
            nonlocal n_done
            part = run_passes(path, Film(path.window), Clock(0.0, self.clock.poll), samples=1,
                              batch=batch_pixels(self.memory, self.settings), phase="Lightcuts",
                              key=(0xD1,), first=n_done, show=False, on_pass=on_pass,
                              fraction=lambda f: self.schedule.fraction("Lightcuts", 1.0))
            if variance.count != n_done + 1:
                return False
            w = 1.0 / (n_done + 1)
            base[:] = base * (1.0 - w) + part.light_parts() * w
            alpha[:] = alpha * (1.0 - w) + part.alpha * w
            n_done += 1
            return True

        self.direct_rival = DirectRival(one_more, variance, seconds)
        return base, alpha

    def _follows_specular(self) -> bool:
        """The gather follows the camera through perfect mirrors and glass
        (:func:`~.vpl.follow_specular`): with ``direct_light='NEE'`` in scenes with such
        materials, unless :data:`FOLLOW_SPECULAR` (the ablation) is off."""
        return FOLLOW_SPECULAR and not self.settings.direct_vpls and self.scene.has_specular_or_glass

    def _delta_paths(self) -> NDArray:
        """(3, h·w, 3) light passes of the paths through a mirror or smooth glass
        (``direct_light='VPL'``; with 'NEE' :meth:`_direct_light` renders them)."""
        path = PathIntegrator(self.scene, self.settings, paths="delta")
        film = self._passes(path, "Direct light", (0xD2,), "direct", show=False,
                            samples=self.settings.direct_samples)
        return film.light_parts()

    def _without_delta(self, P: float, delta_parts: NDArray) -> float:
        """P less the energy of the paths with a delta vertex in ``delta_parts`` (n, h·w, 3)
        (the rough BDPT image measures them too, but the chains and VPLs do not carry them:
        the path tracer does). Clipped at 0; recorded as ``stats['P_delta']``."""
        if not self.scene.has_delta:
            return P
        e = float(luminance(np.asarray(delta_parts, np.float64).sum(axis=0)).sum())
        self.stats["P_delta"] = e
        return max(P - e, 0.0)

    def _passes(self, integrator, phase: str, key: tuple, share: str, show: bool, samples: int,
                on_pass=None, film: Film | None = None, first: int = 0,
                span: tuple[float, float] = (0.0, 1.0)) -> Film:
        """:func:`~ercuts_core.integrators.base.run_passes` within ``share``'s deadline (into
        ``film``, a new one by default, from pass ``first`` on), its progress the part
        ``span`` of the phase's."""
        s = self.settings
        film = Film(integrator.window) if film is None else film
        lo, hi = span
        return run_passes(integrator, film, self.clock, samples=samples, first=first,
                          batch=batch_pixels(self.memory, s), phase=phase,
                          key=key, fraction=lambda f: self.schedule.fraction(phase, lo + (hi - lo) * f),
                          deadline=self.schedule.deadline(share), show=show, on_pass=on_pass)

    def _seeds(self, rng, pix=None):
        s, scene = self.settings, self.scene
        clear_x1 = not self._follows_specular()
        if s.seeding == "BDPT":
            return seed_paths(scene, s, rng, pix, clear_x1=clear_x1)
        return seeds_from_path_tracer(scene, s.max_depth, rng, pix, direct=s.direct_vpls, clear_x1=clear_x1)

    def _chain_seeds(self, P: float, rng) -> tuple[PathBatch, NDArray]:
        """Seed paths (fresh paths, one sample per seed pixel) and their chain counts for
        chains whose states are worth e_d = P/n, n = C · N with C chains of N steps per
        iteration (:meth:`~ercuts_core.settings.RenderSettings.chain_plan`: up to max_chains
        chains of chain_length, beyond that shorter ones): the chains, and so the VPLs,
        follow a budget, not the pixel count (issue 17). Every pixel takes q =
        ``seed_samples`` seed samples on average (fewer when the cap binds: q ·= C /
        (chains_per_pixel · pixels); :func:`~.seeding.seed_pixels`), their energies divided
        by q (an unbiased estimate of the image energy). Traced in batches of ``memory.seed_pixels`` pixels
        (at most :func:`~ercuts_core.integrators.base.progress_batch_pixels`, reporting
        progress after each); only seeds that start a chain are kept, so the seed memory is
        that of one batch."""
        s, n = self.settings, self.scene.camera.window.n_pixels
        n_chains, self.chain_length = s.chain_plan(n)
        self.stats["chain_length"] = self.chain_length
        e_d = P / (n_chains * self.chain_length) if n_chains > 0 else 0.0
        pix, q = seed_pixels(n, s.seed_rate(n), rng)
        step = min(self.memory.seed_pixels, progress_batch_pixels(s))
        deadline = self._seed_deadline()
        if deadline is not None:     # any prefix of the batches is a uniform random subset
            pix = seed_order(pix, s.seed)
        batches = np.arange(0, len(pix), step)
        kept, counts, total, traced = [], [], 0, 0
        for i, start in enumerate(batches):
            batch = pix[start:start + step]
            traced += len(batch)
            seeds, energy = self._seeds(rng, batch)
            starts = chain_starts(energy / q, self.chain_length, e_d, rng)
            kept.append(seeds.take(np.flatnonzero(starts > 0)))
            counts.append(starts[starts > 0])
            total += len(seeds)
            f = (i + 1) / len(batches)
            if not self.schedule.report("ER chains", 0.1 * f, f"ER chains: seed paths {100 * f:.0f}%"):
                break
            if deadline is not None and time.perf_counter() > deadline and f < 1.0:
                self.stats["seed_pixels_planned"] = len(pix)
                break
        self.stats["seed_pixels"], self.stats["seed_paths"] = traced, total
        seeds, starts = PathBatch.concat(kept), np.concatenate(counts)
        return seeds.take(starts > 0), starts[starts > 0]

    def _seed_deadline(self) -> float | None:
        """When a paced iteration stops tracing seed paths: after :data:`SEED_SHARE` of the
        ER chains' time share (None: not paced). The chains' states are worth P / (the
        states made) (:meth:`_render`), so chains from the random subset of seed pixels
        traced by then carry the image's energy still."""
        end = self.schedule.deadline("chains")
        if end is None:
            return None
        now = time.perf_counter()
        return now + SEED_SHARE * max(end - now, 0.0)

    # ------------------------------------------------------------------ phase 2
    def _run_chains(self, seeds: PathBatch, starts: NDArray, rng):
        """``starts[i]`` chains of ``self.chain_length`` steps (:meth:`~ercuts_core.settings.
        RenderSettings.chain_plan`) from each seed (paper §3.2)."""
        s, clock, sched = self.settings, self.clock, self.schedule
        ctx = MutationContext(self.scene, s.max_depth + 1, direct=s.direct_vpls,
                              clear_x1=not self._follows_specular())
        enabled = (s.lens_perturbation, s.caustic_perturbation, s.multichain_perturbation,
                   s.bidirectional_mutation)
        deadline = sched.deadline("chains")
        label = f"| {int(starts.sum())} chains x {self.chain_length} steps"
        return run_chains(ctx, seeds, starts, self.chain_length, enabled, rng,
                          lambda f: sched.alive(deadline, "ER chains", 0.1 + 0.9 * f, label),
                          interrupt=lambda f: clock.poll(sched.fraction("ER chains", 0.1 + 0.9 * f),
                                                         f"ER chains {100 * f:.0f}% {label}"))

    # ------------------------------------------------------------------ phase 3
    def _make_vpls(self, g: GBuffer, chains, e_d: float, gmax: float, rng):
        """VPLs at the chains' x2, normalised with ``e1_samples`` light-traced samples each.
        A paced iteration fits them into the phase's time share: by a random share of the
        VPLs (``stats['vpls_kept_for_time_limit']``, :func:`~.vpl.thin_vpls`) while that
        leaves :data:`~.vpl.PACED_E1_FLOOR` samples each, and below it by fewer samples."""
        s, stats, sched = self.settings, self.stats, self.schedule
        n_e1, n_v = s.e1_samples, max(int((chains.count > 0).sum()), 1)
        if sched.paced:
            budget = max(sched.deadline("vpl") - time.perf_counter(), 0.0)
            rate = self.e1_rate or _E1_RATE / (1.0 + PIXEL_SAMPLE_RATE)
            keep = paced_vpl_share(budget * rate, n_v, n_e1)
            if keep < 1.0:          # fewer VPLs rather than fewer samples each
                chains = thin_vpls(chains, keep, rng)
                n_v = max(int((chains.count > 0).sum()), 1)
                stats["vpls_kept_for_time_limit"] = keep
            n_e1 = int(min(n_e1, max(16, budget * rate / n_v)))
        stats["e1_samples"] = n_e1
        label = f"| {stats['vpls_after_merge']} VPLs x {n_e1} E1 samples"
        t0 = time.perf_counter()
        vpls = make_vpls(self.scene, g, chains, e_d, gmax, n_e1, rng,
                         chunk=min(self.memory.e1_chunk, PROGRESS_E1_CHUNK),
                         clear_receivers=not self._follows_specular(),
                         keep_going=lambda f: sched.report("VPLs", f, f"VPLs {100 * f:.0f}% {label}"))
        if not self.clock.cancelled and n_v > 1:   # the measured rate paces later iterations
            self.e1_rate = n_e1 * n_v / max(time.perf_counter() - t0, 1e-3)
        stats["vpls"] = len(vpls)
        stats["vpls_emitter"] = int(vpls.emitter.sum())
        stats["vpls_unlit_fallback"] = int(chains.count[chains.count > 0].size - len(vpls))
        return vpls

    # ------------------------------------------------------------------ phase 4
    def _light_tree(self, vpls):
        """The light tree over the VPLs (None for the brute-force ablation or no VPLs)."""
        s, sched = self.settings, self.schedule
        tree = None
        label = f"| {len(vpls)} VPLs"
        if s.gather != "BRUTE_FORCE" and len(vpls):
            tree = build_light_tree(vpls.position, vpls.normal, vpls.intensity, seed=s.seed,
                                    pairing=s.tree_pairing.lower(),
                                    keep_going=lambda f: sched.report(
                                        "Light tree", f, f"Light tree {100 * f:.0f}% {label}"))
        if not self.clock.cancelled:
            sched.report("Light tree", 1.0, f"Light tree {label}")
        return tree

    # ------------------------------------------------------------------ phase 5
    def _gather(self, g: GBuffer, vpls, tree, gmax: float, base: NDArray, alpha: NDArray) -> Gathered:
        """Phase 5 (:class:`~.gather.Gather`), previewing the gathered pixels over the rough
        image after every batch."""
        window = self.scene.camera.window
        rough = self.rough

        def show(points):
            def image():
                point_parts, done = points()
                complete = done.reshape(-1, g.samples).all(axis=1)
                parts = self._compose(base, per_pixel_parts(point_parts, g.samples), None, 1.0)
                fallback = rough.full_film().light_parts()
                return _rgba(window, np.where(complete[None, :, None], parts, fallback), alpha)
            self.clock.show(image)

        gather = Gather(self.scene, self.settings, g, self.memory.gather_batch, self.iteration)
        return gather.run(vpls, tree, gmax, self.schedule, self.stats, show, rival=self.direct_rival)

    # ------------------------------------------------------------------ non-VPL light
    def _direct_image(self, g: GBuffer, rng, n_light_samples: int = 4) -> NDArray:
        """(3, h·w, 3) by light pass: [emitters and world seen directly, direct light from
        point, spot, sun and environment (next-event estimation), zeros]."""
        scene, s = self.scene, self.settings
        lights = scene.lights
        S = g.samples
        L = np.zeros((3, len(g.pixel), 3))
        hit = g.valid
        L[0, hit] = scene.emission(g.surf.subset(np.flatnonzero(hit)))
        if lights.env_light >= 0 and not s.film_transparent:
            L[0, ~hit] = lights.env_radiance(-g.wo[~hit])           # wo = −(camera ray)
        nonvpl = np.isin(lights.kind, [POINT, SUN, ENV])
        if nonvpl.any() and hit.any():
            h = np.flatnonzero(hit)
            bsdf = scene.bsdf(g.mat[h], g.ns[h], g.ng[h], g.p[h])
            acc = np.zeros((len(h), 3))
            for _ in range(n_light_samples):
                ls = lights.illuminate(g.p[h], rng.random(len(h)), rng.random((len(h), 2)))
                use = ls.valid & nonvpl[ls.light]
                f = bsdf.eval(g.wo[h], ls.wi) * np.abs(dot(g.ns[h], ls.wi))[:, None]
                c = f * ls.Li / np.where(use, ls.pdf_w, 1.0)[:, None] * use[:, None]
                t = np.flatnonzero(c.max(axis=1) > 0)
                if len(t):
                    infinite = ~np.isfinite(ls.dist[t])
                    target = np.where(infinite[:, None], g.p[h[t]] + ls.wi[t] * 4 * scene.scene_radius, ls.p[t])
                    vis = scene.tracer.visible(g.p[h[t]], g.ng[h[t]], target, None)
                    acc[t] += c[t] * vis[:, None]
            L[1, h] = acc / n_light_samples
        return per_pixel_parts(L, S)

    def _energy_scale(self, gathered: Gathered, vpls, P: float) -> float:
        """1, or with the ``normalize_to_p`` ablation the factor that makes the VPL image's
        energy P (paper §3.3: every path carries P/n); the light gathered at points seen in
        mirrors or through windows is not part of either.

        Each VPL is normalised by its own estimate Ê1 (vpl.py, two-stage: its Jensen bias
        is small); the ratio E(VPL image) / P is reported as ``vpl_energy_ratio`` (1 =
        unbiased) either way. The ablation rescales by P / E(VPL image), which hides any
        error of the normalisation (issue 13); an incomplete gather is never rescaled.
        """
        stats = self.stats
        energy = float(luminance(gathered.parts.sum(axis=0) + vpls.fallback).sum()) - gathered.through_energy
        stats["vpl_energy_ratio"] = energy / P if P > 0 else 0.0
        if not self.settings.normalize_to_p or energy <= 0 or P <= 0 or stats.get("gather_incomplete"):
            return 1.0
        return P / energy

    @staticmethod
    def _compose(base: NDArray, gather: NDArray, vpls, scale: float) -> NDArray:
        """(3, h·w, 3) light passes: ``base`` (emission, non-VPL direct) plus the gathered light
        of emitter VPLs (direct) and of the others (indirect), and the ERPT fallback of VPLs
        that lit no sampled pixel, all VPL light times ``scale``."""
        out = base.copy()
        out[1] += gather[0] * scale
        out[2] += gather[1] * scale
        if vpls is not None:
            out[1] += vpls.fallback_emitter * scale
            out[2] += (vpls.fallback - vpls.fallback_emitter) * scale
        return out

    def _alpha(self, g: GBuffer) -> NDArray:
        """(h·w,) coverage: the fraction of shading points that hit, or 1."""
        hit = g.valid.astype(np.float64) if self.settings.film_transparent else np.ones(len(g.pixel))
        return per_pixel(hit[:, None], self.scene.camera.window.n_pixels, g.samples)[:, 0]

    # ------------------------------------------------------------------ output
    def _chain_stats(self, chains, n_states: int) -> None:
        stats = self.stats
        stats["chains"] = chains.n_chains
        stats["chain_steps"] = chains.steps_done
        stats["chain_states"] = n_states
        stats["vpls_before_merge"] = n_states
        stats["vpls_after_merge"] = int((chains.count > 0).sum())
        stats["nan_acceptances"] = chains.nan_acceptances
        for i, name in enumerate(NAMES):
            if name in INACTIVE:
                continue
            stats[f"proposed_{name}"] = int(chains.proposed[i])
            stats[f"accepted_{name}"] = int(chains.accepted[i])
            stats[f"acceptance_{name}"] = float(chains.accepted[i] / chains.proposed[i]) if chains.proposed[i] else 0.0

    def _first_hit_aovs(self, g: GBuffer) -> dict[str, NDArray]:
        """The first-hit AOVs 'depth', 'normal', 'albedo' of the shading points, per pixel
        (taken before :func:`~.vpl.follow_specular` moves points on mirrors and glass)."""
        n, S = self.scene.camera.window.n_pixels, g.samples
        h = np.flatnonzero(g.valid)
        depth = np.where(g.valid, g.surf.t, 1e10)[:, None]
        albedo = np.zeros((len(g.pixel), 3))
        if len(h):
            albedo[h] = self.scene.bsdf(g.mat[h], g.ns[h], g.ng[h], g.p[h]).albedo()
        return {"depth": per_pixel(depth, n, S),
                "normal": per_pixel(np.where(g.valid[:, None], g.ns, 0.0), n, S),
                "albedo": per_pixel(albedo, n, S)}

    def _finish(self, film: Film, first_hits: dict, chains, vpls, gathered: Gathered, scale: float) -> None:
        """First-hit (``first_hits``, :meth:`_first_hit_aovs`) and Ercuts AOVs of the one-pass
        result (module docstring)."""
        film.aov_sum.update(first_hits)
        film.aov_sum["chain_deposits"] = chains.deposits_per_pixel[:, None].astype(np.float64)
        film.aov_sum["cut_size"] = gathered.cut
        film.aov_sum["vpl_density"] = self._vpl_density(vpls)[:, None]
        film.aov_sum["er_caustic"] = (gathered.glossy + vpls.fallback) * scale * gathered.complete[:, None]

    def _vpl_density(self, vpls) -> NDArray:
        """(h·w,) number of VPLs seen by the camera in each pixel (position projected to the
        image, unoccluded)."""
        scene = self.scene
        cam, window = scene.camera, scene.camera.window
        out = np.zeros(window.n_pixels)
        if len(vpls) == 0:
            return out
        raster, ok = cam.raster_of(vpls.position)
        pix, inside = window.pixel(raster)
        k = np.flatnonzero(ok & inside)
        if len(k) == 0:
            return out
        p = vpls.position[k]
        far = p - cam.forward * 4.0 * scene.scene_radius
        eye = far if cam.ortho else np.broadcast_to(cam.position, p.shape)
        n = vpls.normal[k] * np.where(dot(vpls.normal[k], eye - p) < 0, -1.0, 1.0)[:, None]
        vis = scene.tracer.visible(p, n, np.ascontiguousarray(eye), None)
        return np.bincount(pix[k[vis]], minlength=window.n_pixels).astype(np.float64)



def _rgba(window, parts: NDArray, alpha: NDArray) -> NDArray:
    """(h, w, 4) float32 image of (3, h·w, 3) light passes and (h·w,) alpha."""
    rgba = np.concatenate([parts.sum(axis=0), alpha[:, None]], axis=1)
    return rgba.reshape(window.height, window.width, 4).astype(np.float32)
