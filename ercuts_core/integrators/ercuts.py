"""The Ercuts integrator (Zhu, Xu, Pan 2010): BDPT → ER chains → VPLs → light tree → lightcuts.

Phases (each a module named after the paper's step):

1. :mod:`~ercuts_core.initialization` — rough BDPT image, its energy P (paths with a
   surface x2 that VPLs stand for), and fresh seed paths;
2. :mod:`~ercuts_core.er_sampling` — equal-length Markov chains, each state worth e_d = P/n;
3. :mod:`~ercuts_core.vpl` — a VPL at every chain's x2, merged by identity, normalised;
4. :mod:`~ercuts_core.light_tree` — the binary light tree with the paper's pairing weight;
5. :mod:`~ercuts_core.lightcuts` — per shading point, a cut refined until the error
   bound is under ``max_error`` of the estimate.

Direct light (``direct_light``). With 'NEE' (the default) the light that reaches the
camera directly or after one scattering — emitters and world seen directly, and direct
light from every light — is rendered in its own phase after the rough image, ``direct_samples``
jittered (anti-aliased) passes of next-event estimation with MIS (:meth:`_direct_passes`);
the chains are restricted to indirect paths (x2 scatters, k ≥ 3), P is the rough image's
indirect energy, and the VPLs carry indirect light only. VPLs standing for area lights
(the paper's and Lightcuts' representation, kept as 'VPL') make soft shadows blotchy and,
through the per-VPL normalisation 1/Ê1 of VPLs that light few pixels, give occasional
bright faces (directly lit benchmark scene, 10 s: relMSE 0.005–0.29 over three seeds).
With 'VPL' the image is the sum of what the VPLs cannot represent — light seen directly
and direct light from point, spot, sun and environment lights, by next-event estimation at
the shading points — and the VPL gather. Either way the ERPT fallback of VPLs that lit no
sampled pixel is added.

Time: with ``time_limit`` > 0 each phase gets its share (:data:`_SHARE`: rough BDPT 15 %,
direct light 5 % plus up to 45 % more as the rough image's light is direct, chains 30 %,
VPL normalisation 15 % — fewer E1 samples per VPL if needed — and the rest for the gather)
of the time left, paced by :class:`GatherPace`: the
shading points are gathered in a shuffled order of short runs, so every batch is a sample
of the whole image, and after each batch the lightcut error threshold is raised (or
lowered back toward ``max_error``) so the rest fits the time left; only above
:data:`MAX_PACED_ERROR` is the cut size capped; a phase that runs out stops cleanly (fewer
passes, shorter chains, coarser cuts) and the stats say so.

Progress and cancellation (api.md): messages start with the phase ("BDPT", "Direct light",
"ER chains", "VPLs", "Light tree", "Lightcuts", fractions in :data:`PHASES`); previews show
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
  implementation deposits no separate caustic ERPT energy (the material model has no delta
  lobes and every chain state deposits into its VPL), so er_caustic is a *part* of
  direct + indirect, not an addition to the image; 0 in scenes without glossy surfaces and
  fallback deposits.
* 'cut_size' (h, w, 1) mean lightcut size, 'chain_deposits' (h, w, 1) chain states whose
  x1 lies in the pixel, and 'depth', 'normal', 'albedo' of the first shading point.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..bsdf import Bsdf, bsdf_max_value
from ..film import Film
from ..initialization import indirect_energy, rough_image_energy, seeds_from_path_tracer
from ..light_tree import build_light_tree
from ..lightcuts import ShadingPoints, brute_force, lightcut
from ..lights import ENV, POINT, SUN
from ..memory import plan
from ..mutations import NAMES, MutationContext
from ..paths import PathBatch
from ..er_sampling import chain_starts, run_chains
from ..sampling import luminance
from ..scene import BuiltScene
from ..settings import RenderSettings
from ..vpl import GBuffer, build_gbuffer, g_clamp, make_vpls
from ..render import progress_batch_pixels
from .base import dot

#: Shares of the time limit per phase (the gather gets the rest); a phase's deadline gives
#: it its share of the time *left*, so time an earlier phase did not need flows on. The
#: direct-light share grows by :data:`_DIRECT_SHARE_GROWTH` × the rough image's direct
#: fraction (the other shares shrink in proportion): a directly lit scene spends its time
#: on the direct passes, a corridor lit around corners on the chains and the gather.
_SHARE = {"bdpt": 0.15, "direct": 0.05, "chains": 0.30, "vpl": 0.15}
_DIRECT_SHARE_GROWTH = 0.45
#: Conservative throughput of the E1 estimate (light-traced samples per second, 2 cores).
_E1_RATE = 1.0e6
#: Absolute lightcut error floor as a fraction of max_error × the mean pixel luminance.
ABS_FLOOR = 0.1
#: Progress fractions (start, end) of each phase over the whole render (messages start
#: with the phase name, api.md); roughly the phases' time shares at default settings.
PHASES = {"BDPT": (0.0, 0.22), "Direct light": (0.22, 0.25), "ER chains": (0.25, 0.35),
          "VPLs": (0.35, 0.4), "Light tree": (0.4, 0.42), "Lightcuts": (0.42, 1.0)}
#: Largest gather batch (shading points) and E1 chunk (samples) for progress reports every
#: ~0.25 s of work: a lightcut round of 2048 points took up to 0.97 s of CPU on the
#: S-corridor, of 512 points 0.20 s, at the same total cost.
PROGRESS_GATHER_POINTS = 512
PROGRESS_E1_CHUNK = 1 << 16
#: Shading points whose specular lobe has a roughness below this count as glossy (er_caustic).
GLOSSY_ROUGHNESS = 0.5
#: Largest lightcut error threshold the time limit may ask for; past it the cut size is
#: capped instead (cuts of a few clusters show their representatives as streaks).
MAX_PACED_ERROR = 0.25
#: Consecutive shading points kept together in the shuffled gather order (coherent rays).
GATHER_RUN = 32


class ErcutsIntegrator:
    """Runs the five phases on a built scene (see the module docstring)."""

    def __init__(self, scene: BuiltScene, settings: RenderSettings):
        self.scene = scene
        self.settings = settings
        self.memory = plan(scene.camera.window.n_pixels, scene.desc.mesh.n_triangles, settings)
        self.share = dict(_SHARE)       # time shares of this render (:data:`_SHARE`)

    # ------------------------------------------------------------------ driver
    def render(self, film: Film, clock, timings: dict, stats: dict) -> None:
        s, scene = self.settings, self.scene
        window = scene.camera.window
        rng = np.random.default_rng([s.seed, 0xE5C7])
        nee = not s.direct_vpls
        # 1. Rough BDPT image and P.
        t0 = time.perf_counter()
        rough, spp = self._rough_bdpt(clock, self._deadline(clock, "bdpt"))
        timings["bdpt"] = time.perf_counter() - t0
        stats["bdpt_samples"] = spp
        if clock.cancelled:
            film.merge(rough)
            return
        clock.show(rough.image)
        P_all = rough_image_energy(rough.image())
        if nee:     # light seen directly and scattered once: its own anti-aliased passes
            P = indirect_energy(rough.light_parts())
            f_direct = 1.0 - P / P_all if P_all > 0 else 0.0
            self.share["direct"] = _SHARE["direct"] + _DIRECT_SHARE_GROWTH * min(max(f_direct, 0.0), 1.0)
            t0 = time.perf_counter()
            direct = self._direct_passes(clock, self._deadline(clock, "direct"))
            timings["direct"] = time.perf_counter() - t0
            stats["direct_samples"] = direct.passes_done
            if clock.cancelled:
                film.merge(rough)
                return
            # Keep the light passes and the coverage; the film itself goes.
            base, alpha = direct.light_parts(), direct.alpha / max(direct.passes_done, 1)
            del direct
        t0 = time.perf_counter()
        g, _ = build_gbuffer(scene, s.shading_samples, rng)
        if not nee:
            base, alpha = self._direct_image(g, rng), self._alpha(g)
            P = max(P_all - float(luminance(base.sum(axis=0)).sum()), 0.0)
        stats["P"], stats["P_all"] = P, P_all
        # Seeds: fresh paths, one sample per pixel.
        n_target = s.chains_per_pixel * s.chain_length * window.n_pixels
        e_d = P / n_target if n_target > 0 else 0.0
        seeds, starts, stats["seed_paths"] = self._chain_seeds(e_d, rng, clock)
        timings["seeds"] = time.perf_counter() - t0
        if clock.cancelled:
            film.merge(rough)
            return
        # 2. ER chains.
        t0 = time.perf_counter()
        ctx = MutationContext(scene, s.max_depth + 1, direct=s.direct_vpls)
        enabled = (s.lens_perturbation, s.caustic_perturbation, s.multichain_perturbation,
                   s.bidirectional_mutation)
        deadline = self._deadline(clock, "chains")
        label = f"| {int(starts.sum())} chains x {s.chain_length} steps"
        chains = run_chains(ctx, seeds.take(starts > 0), starts[starts > 0], s.chain_length, enabled,
                            rng, lambda f: self._alive(clock, deadline, "ER chains", 0.1 + 0.9 * f, label),
                            interrupt=lambda f: clock.poll(self._fraction("ER chains", 0.1 + 0.9 * f),
                                                           f"ER chains {100 * f:.0f}% {label}"))
        timings["chains"] = time.perf_counter() - t0
        # With a shortened run every chain made the same number of steps: e_d stays P/n.
        n_states = chains.n_chains * chains.steps_done
        e_d = P / n_states if n_states else 0.0
        self._chain_stats(stats, chains, n_states)
        if clock.cancelled:
            film.merge(rough)
            return
        # 3. VPLs.
        t0 = time.perf_counter()
        gmax = g_clamp(scene, s.clamp)
        n_e1 = s.e1_samples
        if clock.deadline is not None:
            budget = max(self._deadline(clock, "vpl") - time.perf_counter(), 0.0)
            n_e1 = int(min(n_e1, max(16, budget * _E1_RATE / max(int((chains.count > 0).sum()), 1))))
        stats["e1_samples"] = n_e1
        label = f"| {stats['vpls_after_merge']} VPLs x {n_e1} E1 samples"
        vpls = make_vpls(scene, g, chains, e_d, gmax, n_e1, rng,
                         chunk=min(self.memory.e1_chunk, PROGRESS_E1_CHUNK),
                         keep_going=lambda f: clock.report(self._fraction("VPLs", f),
                                                           f"VPLs {100 * f:.0f}% {label}"))
        timings["vpls"] = time.perf_counter() - t0
        if clock.cancelled:
            film.merge(rough)
            return
        stats["vpls"] = len(vpls)
        stats["vpls_emitter"] = int(vpls.emitter.sum())
        stats["vpls_unlit_fallback"] = int(chains.count[chains.count > 0].size - len(vpls))
        # 4. Light tree.
        t0 = time.perf_counter()
        tree = None
        label = f"| {len(vpls)} VPLs"
        if s.gather == "LIGHTCUTS" and len(vpls):
            tree = build_light_tree(vpls.position, vpls.normal, vpls.intensity, seed=s.seed,
                                    keep_going=lambda f: clock.report(
                                        self._fraction("Light tree", f), f"Light tree {100 * f:.0f}% {label}"))
        timings["tree"] = time.perf_counter() - t0
        if clock.cancelled or not clock.report(self._fraction("Light tree", 1.0), f"Light tree {label}"):
            film.merge(rough)
            return
        # 5. Lightcuts (or the brute-force ablation).
        t0 = time.perf_counter()
        rough_parts = rough.light_parts()

        def show(point_parts, complete):
            def image():
                parts = self._compose(base, self._per_pixel_parts(point_parts, g.samples), None, 1.0)
                return _rgba(window, np.where(complete[None, :, None], parts, rough_parts), alpha)
            clock.show(image)

        gathered = self._gather(g, vpls, tree, gmax, clock, stats, show)
        timings["cuts"] = time.perf_counter() - t0
        scale = self._energy_scale(gathered.parts.sum(axis=0), vpls, P, stats)
        light = self._compose(base, gathered.parts, vpls, scale)
        if not gathered.complete.all():     # cancelled: the rough image where not gathered
            light = np.where(gathered.complete[None, :, None], light, rough_parts)
        film.set_pixels(light, alpha)
        self._finish(film, g, chains, vpls, gathered, scale)

    @staticmethod
    def _fraction(phase: str, f: float) -> float:
        """Progress over the whole render of fraction ``f`` of ``phase`` (:data:`PHASES`)."""
        lo, hi = PHASES[phase]
        return lo + (hi - lo) * min(max(f, 0.0), 1.0)

    def _deadline(self, clock, phase: str) -> float | None:
        """End of ``phase``'s share (:data:`_SHARE`) of the time left, or None without a limit."""
        if clock.deadline is None:
            return None
        share = self.share
        order = [p for p in share if p != "direct" or not self.settings.direct_vpls]
        later = sum(share[p] for p in order[order.index(phase):])
        gather = 1.0 - sum(_SHARE[p] for p in order)
        now = time.perf_counter()
        return now + max(clock.deadline - now, 0.0) * share[phase] / (later + gather)

    def _alive(self, clock, deadline, phase: str, f: float, label: str) -> bool:
        ok = clock.report(self._fraction(phase, f), f"{phase} {100 * f:.0f}% {label}")
        return ok and (deadline is None or time.perf_counter() < deadline)

    # ------------------------------------------------------------------ phase 1
    def _rough_bdpt(self, clock, deadline) -> tuple[Film, int]:
        """``samples`` BDPT passes (fewer if the phase's time share runs out)."""
        from .bdpt import BDPTIntegrator
        rough = self._passes(BDPTIntegrator(self.scene, self.settings), "BDPT", (), clock, deadline,
                             show=True)
        return rough, rough.passes_done

    def _direct_passes(self, clock, deadline) -> Film:
        """``direct_samples`` jittered passes of the light that reaches the camera directly or after
        one scattering (path tracing with ``max_depth`` = 1: next-event estimation from every
        light with MIS against BSDF sampling, emitters and world seen directly), fewer if the
        phase's time share runs out; the rough image stays on screen meanwhile."""
        from .path import PathIntegrator
        path = PathIntegrator(self.scene, self.settings.replace(max_depth=1))
        return self._passes(path, "Direct light", (0xD1,), clock, deadline, show=False,
                            samples=self.settings.direct_samples)

    def _passes(self, integrator, phase: str, key: tuple, clock, deadline, show: bool,
                samples: int | None = None) -> Film:
        """Up to ``samples`` (default: the setting) passes of ``integrator`` in progress-sized
        batches (random streams ``[seed, *key, pass, batch start]``); stops after a pass once
        ``deadline`` is past, and keeps a cut-short pass only when it is the first."""
        s, window = self.settings, self.scene.camera.window
        acc, n = Film(window), window.n_pixels
        batch = min(self.memory.batch_pixels, progress_batch_pixels(s))
        samples = s.samples if samples is None else samples
        t0 = time.perf_counter()
        for k in range(samples):
            part = Film(window)
            for start in range(0, n, batch):
                rng = np.random.default_rng([s.seed, *key, k, start])
                integrator.render_batch(part, np.arange(start, min(n, start + batch)), rng)
                f = (k + min(n, start + batch) / n) / samples
                if deadline is not None:    # with many samples, the time share says how far
                    f = max(f, (time.perf_counter() - t0) / max(deadline - t0, 1e-9))
                if not clock.report(self._fraction(phase, f), f"{phase} sample {k + 1}/{samples}"):
                    break
            if not clock.cancelled or acc.passes_done == 0:
                acc.merge(part)
                if show:
                    clock.show(acc.image)
            if clock.cancelled or (deadline is not None and time.perf_counter() > deadline and k > 0):
                break
        return acc

    def _seeds(self, rng, pix=None):
        s, scene = self.settings, self.scene
        if s.seeding == "BDPT":
            from .bdpt import seed_paths
            return seed_paths(scene, s, rng, pix)
        return seeds_from_path_tracer(scene, s.max_depth, rng, pix, direct=s.direct_vpls)

    def _chain_seeds(self, e_d: float, rng, clock):
        """Seed paths and their chain counts, in batches of ``memory.seed_pixels`` pixels (at
        most :func:`~ercuts_core.render.progress_batch_pixels`, reporting progress after each);
        only seeds that start a chain are kept, so the seed memory is that of one batch."""
        s, n = self.settings, self.scene.camera.window.n_pixels
        step = min(self.memory.seed_pixels, progress_batch_pixels(s))
        if step >= n:
            seeds, energy = self._seeds(rng)
            starts = chain_starts(energy, s.chain_length, e_d, rng)
            clock.report(self._fraction("ER chains", 0.1), "ER chains: seed paths 100%")
            return seeds, starts, len(seeds)
        kept, counts, total = [], [], 0
        for start in range(0, n, step):
            seeds, energy = self._seeds(rng, np.arange(start, min(n, start + step)))
            starts = chain_starts(energy, s.chain_length, e_d, rng)
            kept.append(seeds.take(np.flatnonzero(starts > 0)))
            counts.append(starts[starts > 0])
            total += len(seeds)
            f = min(n, start + step) / n
            if not clock.report(self._fraction("ER chains", 0.1 * f),
                                f"ER chains: seed paths {100 * f:.0f}%"):
                break
        return PathBatch.concat(kept), np.concatenate(counts), total

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
            L[0, ~hit] = lights.env_L
        nonvpl = np.isin(lights.kind, [POINT, SUN, ENV])
        if nonvpl.any() and hit.any():
            h = np.flatnonzero(hit)
            bsdf = Bsdf.from_table(scene.materials, g.mat[h], g.ns[h], g.ng[h])
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
        return self._per_pixel_parts(L, S)

    @staticmethod
    def _per_pixel(values: NDArray, n_pixels: int, S: int) -> NDArray:
        """Average the S shading points of each pixel: (n_pixels·S, C) → (n_pixels, C)."""
        return values.reshape(n_pixels, S, -1).mean(axis=1)

    @staticmethod
    def _per_pixel_parts(values: NDArray, S: int) -> NDArray:
        """(K, n_pixels·S, 3) → (K, n_pixels, 3): :meth:`_per_pixel` of each part."""
        K, Q = values.shape[:2]
        return values.reshape(K, Q // S, S, 3).mean(axis=2)

    # ------------------------------------------------------------------ phase 5
    def _gather(self, g: GBuffer, vpls, tree, gmax: float, clock, stats, show) -> "_Gathered":
        """VPL light at every shading point, split into the light of emitter VPLs (direct) and
        of the others (indirect); ``show(point_parts, complete)`` after every batch (preview).

        Cancelling (or running out of time) stops after the current batch; a cancel during a
        lightcut batch stops its refinement, so the batch keeps coarser but complete cuts.
        """
        scene, s = self.scene, self.settings
        window = scene.camera.window
        Q, S = len(g.pixel), g.samples
        L = np.zeros((2, Q, 3))              # [from emitter VPLs, from the others]
        cut = np.zeros(Q)
        done_pt = ~g.valid                   # misses need no gather
        pts_all = _spread_order(np.flatnonzero(g.valid), s.seed)
        if len(vpls) == 0:
            pts_all = pts_all[:0]
        # Absolute error floor (algorithm.md §G.6; not in the papers): below a small fraction
        # of the mean pixel luminance, Weber's law no longer applies (dark pixels would refine
        # to max_cut_size for errors nobody can see).
        floor = s.max_error * ABS_FLOOR * stats.get("P", 0.0) / max(window.n_pixels, 1)
        f_bound = bsdf_max_value(scene.materials, g.mat)
        clamp = 0.0 if not np.isfinite(gmax) else gmax
        share = _emitter_share(tree, vpls) if tree is not None else None
        rays = 0
        clamped = 0.0
        done = 0
        pace = GatherPace(s.max_error, s.max_cut_size)

        def report(f_done):
            f = f_done / max(len(pts_all), 1)
            return clock.poll(self._fraction("Lightcuts", f),
                              f"Lightcuts {100 * f:.0f}% | {rays / 1e6:.2f}M shadow rays") \
                and clock.remaining() > 0

        # A small first batch calibrates the cost per point before the cap is fitted.
        step = min(self.memory.gather_batch, PROGRESS_GATHER_POINTS)
        edges = np.unique(np.r_[0, np.arange(min(256, len(pts_all)), len(pts_all), step), len(pts_all)])
        for start, stop in zip(edges[:-1], edges[1:]):
            idx = pts_all[start:stop]
            t_batch = time.perf_counter()
            pts = self._shading_points(g, idx, f_bound)
            if s.gather == "LIGHTCUTS":
                res = lightcut(tree, vpls.position, vpls.normal, vpls.intensity, pts,
                               max_error=pace.error, max_cut_size=pace.cap, clamp=clamp,
                               abs_floor=floor, return_cut=True, on_round=lambda: report(start))
                em = _sum_rows(res.cut_point, res.cut_estimate * share[res.cut_node], len(idx))
                L[0, idx], L[1, idx], cut[idx] = em, res.radiance - em, res.cut_size
                rays += res.shadow_rays
                clamped += res.clamped_energy
            else:
                for part, sel in enumerate((vpls.emitter, ~vpls.emitter)):
                    if sel.any():
                        L[part, idx] = brute_force(vpls.position[sel], vpls.normal[sel],
                                                   vpls.intensity[sel], pts, clamp=clamp)
                cut[idx] = len(vpls)
                rays += len(idx) * len(vpls)
            done = start + len(idx)
            done_pt[idx] = True
            pace.update(len(idx), time.perf_counter() - t_batch, cut[idx].mean(),
                        len(pts_all) - done, clock.remaining())
            if not report(done) and done < len(pts_all):
                stats["gather_incomplete"] = 1
                clock.cancelled = True
                break
            show(L, done_pt.reshape(-1, S).all(axis=1))
        pace.record(stats, done)
        valid_cut = cut[pts_all[:done]] if done else np.zeros(1)
        stats["cut_size_mean"] = float(valid_cut.mean()) if done else 0.0
        stats["cut_size_max"] = int(valid_cut.max()) if done else 0
        stats["gather_shadow_rays"] = rays
        stats["clamped_energy"] = clamped / S
        glossy = self._glossy(g)
        return _Gathered(parts=self._per_pixel_parts(L, S),
                         glossy=self._per_pixel(L.sum(axis=0) * glossy[:, None], window.n_pixels, S),
                         cut=self._per_pixel(cut[:, None], window.n_pixels, S),
                         complete=done_pt.reshape(-1, S).all(axis=1))

    def _glossy(self, g: GBuffer) -> NDArray:
        """(Q,) shading points with a specular lobe of roughness < :data:`GLOSSY_ROUGHNESS`."""
        table = self.scene.materials
        h = np.flatnonzero(g.valid)
        out = np.zeros(len(g.pixel), bool)
        if len(h):
            bsdf = Bsdf.from_table(table, g.mat[h], g.ns[h], g.ng[h])
            out[h] = ~bsdf.is_diffuse & (np.asarray(table.roughness)[g.mat[h]] < GLOSSY_ROUGHNESS)
        return out

    def _shading_points(self, g: GBuffer, idx: NDArray, f_bound: NDArray) -> ShadingPoints:
        scene = self.scene
        bsdf = Bsdf.from_table(scene.materials, g.mat[idx], g.ns[idx], g.ng[idx])
        wo, ng = g.wo[idx], g.ng[idx]
        p = g.p[idx]

        def eval_f(k, wi):
            return bsdf.subset(k).eval(wo[k], wi)

        def visible(k, q, qn):
            return scene.tracer.visible(p[k], ng[k], q, qn)

        return ShadingPoints(p, g.ns[idx], wo, f_bound[idx], eval_f, visible)

    def _energy_scale(self, gather: NDArray, vpls, P: float, stats: dict) -> float:
        """The factor that makes the VPL image's energy P (paper §3.3: every path carries P/n).

        Each VPL is normalised by its own estimate Ê1 (vpl.py); the average of 1/Ê1 is
        biased high (Jensen), a few per cent with 256 light-traced samples. The ratio
        P / E(VPL image) removes that bias globally while the per-VPL Ê1 keep the relative
        intensities. The raw ratio is reported as ``vpl_energy_ratio`` (1 = unbiased); an
        incomplete gather is not rescaled (returns 1).
        """
        energy = float(luminance(gather + vpls.fallback).sum())
        stats["vpl_energy_ratio"] = energy / P if P > 0 else 0.0
        if energy <= 0 or P <= 0 or stats.get("gather_incomplete"):
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
        return self._per_pixel(hit[:, None], self.scene.camera.window.n_pixels, g.samples)[:, 0]

    # ------------------------------------------------------------------ output
    def _chain_stats(self, stats: dict, chains, n_states: int) -> None:
        stats["chains"] = chains.n_chains
        stats["chain_steps"] = chains.steps_done
        stats["chain_states"] = n_states
        stats["vpls_before_merge"] = n_states
        stats["vpls_after_merge"] = int((chains.count > 0).sum())
        stats["nan_acceptances"] = chains.nan_acceptances
        for i, name in enumerate(NAMES):
            stats[f"proposed_{name}"] = int(chains.proposed[i])
            stats[f"accepted_{name}"] = int(chains.accepted[i])
            stats[f"acceptance_{name}"] = float(chains.accepted[i] / chains.proposed[i]) if chains.proposed[i] else 0.0

    def _finish(self, film: Film, g: GBuffer, chains, vpls, gathered: "_Gathered", scale: float) -> None:
        """First-hit and Ercuts AOVs of the one-pass result (module docstring)."""
        window = self.scene.camera.window
        n, S = window.n_pixels, g.samples
        h = np.flatnonzero(g.valid)
        depth = np.where(g.valid, g.surf.t, 1e10)[:, None]
        albedo = np.zeros((len(g.pixel), 3))
        if len(h):
            albedo[h] = Bsdf.from_table(self.scene.materials, g.mat[h], g.ns[h], g.ng[h]).albedo()
        film.aov_sum["depth"] = self._per_pixel(depth, n, S)
        film.aov_sum["normal"] = self._per_pixel(np.where(g.valid[:, None], g.ns, 0.0), n, S)
        film.aov_sum["albedo"] = self._per_pixel(albedo, n, S)
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
        ix = np.floor(raster[:, 0]).astype(np.int64) - window.x0
        iy = np.floor(raster[:, 1]).astype(np.int64) - window.y0
        k = np.flatnonzero(ok & (ix >= 0) & (ix < window.width) & (iy >= 0) & (iy < window.height))
        if len(k) == 0:
            return out
        p = vpls.position[k]
        far = p - cam.forward * 4.0 * scene.scene_radius
        eye = far if cam.ortho else np.broadcast_to(cam.position, p.shape)
        n = vpls.normal[k] * np.where(dot(vpls.normal[k], eye - p) < 0, -1.0, 1.0)[:, None]
        vis = scene.tracer.visible(p, n, np.ascontiguousarray(eye), None)
        return np.bincount((iy * window.width + ix)[k[vis]], minlength=window.n_pixels).astype(np.float64)


class GatherPace:
    """Lightcut error threshold and cut cap for the next gather batch under a time limit.

    After each batch the cost per point c at the current threshold ε is measured and the
    rest is projected, T = c·left. Lightcut cost falls roughly as 1/ε (cut sizes in
    ``benchmarks/results/lightcuts_scaling.md``), so ε ← ε·T/(0.9·remaining) keeps the
    gather on schedule in both directions, within [``max_error``, :data:`MAX_PACED_ERROR`];
    only when even that ε is too slow is the cut size capped (cap ← mean cut·0.9·remaining/T),
    and the cap is lifted before ε is lowered. Without a time limit nothing changes.
    """

    def __init__(self, max_error: float, max_cut_size: int):
        self.min_error, self.max_cut_size = max_error, max_cut_size
        self.error, self.cap = max_error, max_cut_size
        self.points_paced = 0          # points gathered with a raised threshold or a cap
        self.largest_error, self.smallest_cap = max_error, max_cut_size

    def update(self, n: int, seconds: float, mean_cut: float, left: int, remaining: float) -> None:
        """Pace the next batch from the one just gathered (``n`` points in ``seconds`` with
        the current threshold and cap, mean cut ``mean_cut``; ``left`` points to go)."""
        if self.error > self.min_error or self.cap < self.max_cut_size:
            self.points_paced += n
        if n == 0 or left == 0 or not np.isfinite(remaining):
            return
        ratio = seconds / n * left / max(0.9 * remaining, 1e-6)   # > 1: behind schedule
        if ratio > 1.0 and self.error >= MAX_PACED_ERROR:
            self.cap = int(max(1, min(self.cap, mean_cut / ratio)))
        elif ratio < 1.0 and self.cap < self.max_cut_size:
            self.cap = int(min(self.max_cut_size, max(self.cap + 1, self.cap / ratio)))
        else:
            self.error = float(np.clip(self.error * ratio, self.min_error, MAX_PACED_ERROR))
        self.largest_error = max(self.largest_error, self.error)
        self.smallest_cap = min(self.smallest_cap, self.cap)

    def record(self, stats: dict, done: int) -> None:
        """Stats of a paced gather: the largest threshold and smallest cap used, and the
        share of the ``done`` points gathered with either."""
        if self.points_paced:
            stats["paced_points_for_time_limit"] = self.points_paced / max(done, 1)
        if self.largest_error > self.min_error:
            stats["max_error_for_time_limit"] = self.largest_error
        if self.smallest_cap < self.max_cut_size:
            stats["cut_cap_for_time_limit"] = self.smallest_cap


def _spread_order(points: NDArray, seed: int) -> NDArray:
    """``points`` in a shuffled order of runs of :data:`GATHER_RUN` (deterministic per
    seed): every gather batch samples the whole image (for pacing and an even partial
    image) while neighbouring points stay together (coherent shadow rays)."""
    runs = np.arange(0, len(points), GATHER_RUN)
    order = np.random.default_rng([seed, 0x6A7]).permutation(len(runs))
    starts = runs[order]
    idx = (starts[:, None] + np.arange(GATHER_RUN)[None, :]).ravel()
    return points[idx[idx < len(points)]]


@dataclass
class _Gathered:
    """The VPL gather per pixel: ``parts`` (2, h·w, 3) light of emitter VPLs (direct) and of
    the others (indirect), before the energy scale; ``glossy`` (h·w, 3) the part gathered at
    glossy shading points; ``cut`` (h·w, 1) mean cut size; ``complete`` (h·w,) every shading
    point of the pixel was gathered."""

    parts: NDArray
    glossy: NDArray
    cut: NDArray
    complete: NDArray


def _emitter_share(tree, vpls) -> NDArray:
    """(n_nodes, 3) fraction of each light-tree node's intensity that comes from emitter VPLs
    (the subtree sums of ``vpls.emitter`` intensities over the node's intensity)."""
    em = vpls.intensity * vpls.emitter[:, None]
    cs = np.vstack([np.zeros((1, 3)), np.cumsum(em[tree.leaf_order], axis=0)])
    sub = cs[tree.leaf_start + tree.leaf_count] - cs[tree.leaf_start]
    return np.divide(sub, tree.intensity, out=np.zeros_like(sub), where=tree.intensity > 0)


def _sum_rows(group: NDArray, values: NDArray, n: int) -> NDArray:
    """(n, 3) per-group sums of (K, 3) rows."""
    return np.stack([np.bincount(group, weights=values[:, c], minlength=n) for c in range(3)], axis=1)


def _rgba(window, parts: NDArray, alpha: NDArray) -> NDArray:
    """(h, w, 4) float32 image of (3, h·w, 3) light passes and (h·w,) alpha."""
    rgba = np.concatenate([parts.sum(axis=0), alpha[:, None]], axis=1)
    return rgba.reshape(window.height, window.width, 4).astype(np.float32)
