"""The Ercuts integrator (Zhu, Xu, Pan 2010): BDPT → ER chains → VPLs → light tree → lightcuts.

Phases (each a module named after the paper's step):

1. :mod:`~ercuts_core.initialization` — rough BDPT image, its energy P (paths with a
   surface x2), and fresh seed paths;
2. :mod:`~ercuts_core.er_sampling` — equal-length Markov chains, each state worth e_d = P/n;
3. :mod:`~ercuts_core.vpl` — a VPL at every chain's x2, merged by identity, normalised;
4. :mod:`~ercuts_core.light_tree` — the binary light tree with the paper's pairing weight;
5. :mod:`~ercuts_core.lightcuts` — per shading point, a cut refined until the error
   bound is under ``max_error`` of the estimate.

The image is the sum of what the VPLs cannot represent — light seen directly (emitters,
background) and direct light from point, spot, sun and environment lights, computed here
by next-event estimation at the shading points — and the VPL gather, plus the ERPT
fallback of VPLs that lit no sampled pixel.

Time: with ``time_limit`` > 0 each phase gets a share of the time left (rough BDPT 15 %,
chains 30 %, VPL normalisation 15 % — fewer E1 samples per VPL if needed — and the rest for
the gather, whose cut-size cap is fitted to the time left after each batch); a phase that
runs out stops cleanly (fewer passes, shorter chains, smaller cuts) and the stats say so.
"""
from __future__ import annotations

import time

import numpy as np
from numpy.typing import NDArray

from ..bsdf import Bsdf, bsdf_max_value
from ..film import Film
from ..initialization import rough_image_energy, seeds_from_path_tracer
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
from .base import dot

#: Shares of the remaining time limit per phase.
_SHARE = {"bdpt": 0.15, "chains": 0.30 / 0.85, "vpl": 0.15 / 0.55}
#: Conservative throughput of the E1 estimate (light-traced samples per second, 2 cores).
_E1_RATE = 1.0e6
#: Absolute lightcut error floor as a fraction of max_error × the mean pixel luminance.
ABS_FLOOR = 0.1


class ErcutsIntegrator:
    """Runs the five phases on a built scene (see the module docstring)."""

    def __init__(self, scene: BuiltScene, settings: RenderSettings):
        self.scene = scene
        self.settings = settings
        self.memory = plan(scene.camera.window.n_pixels, scene.desc.mesh.n_triangles, settings)

    # ------------------------------------------------------------------ driver
    def render(self, film: Film, clock, timings: dict, stats: dict) -> None:
        s, scene = self.settings, self.scene
        window = scene.camera.window
        rng = np.random.default_rng([s.seed, 0xE5C7])
        # 1. Rough BDPT image and P.
        t0 = time.perf_counter()
        rough, spp = self._rough_bdpt(clock, self._deadline(clock, _SHARE["bdpt"]))
        timings["bdpt"] = time.perf_counter() - t0
        stats["bdpt_samples"] = spp
        if clock.cancelled:
            film.merge(rough)
            return
        t0 = time.perf_counter()
        g, _ = build_gbuffer(scene, s.shading_samples, rng)
        direct = self._direct_image(g, rng)
        P_all = rough_image_energy(rough.image())
        P = max(P_all - float(luminance(direct).sum()), 0.0)
        stats["P"], stats["P_all"] = P, P_all
        # Seeds: fresh paths, one sample per pixel.
        n_target = s.chains_per_pixel * s.chain_length * window.n_pixels
        e_d = P / n_target if n_target > 0 else 0.0
        seeds, starts, stats["seed_paths"] = self._chain_seeds(e_d, rng)
        timings["seeds"] = time.perf_counter() - t0
        clock.report(0.3, "Ercuts: ER chains")
        # 2. ER chains.
        t0 = time.perf_counter()
        ctx = MutationContext(scene, s.max_depth + 1)
        enabled = (s.lens_perturbation, s.caustic_perturbation, s.multichain_perturbation,
                   s.bidirectional_mutation)
        deadline = self._deadline(clock, _SHARE["chains"])
        chains = run_chains(ctx, seeds.take(starts > 0), starts[starts > 0], s.chain_length, enabled,
                            rng, lambda f: self._alive(clock, deadline, 0.3 + 0.3 * f, "Ercuts: ER chains"))
        timings["chains"] = time.perf_counter() - t0
        # With a shortened run every chain made the same number of steps: e_d stays P/n.
        n_states = chains.n_chains * chains.steps_done
        e_d = P / n_states if n_states else 0.0
        self._chain_stats(stats, chains, n_states)
        if clock.cancelled:
            self._finish(film, direct, None, g, chains, None)
            return
        # 3. VPLs.
        t0 = time.perf_counter()
        gmax = g_clamp(scene, s.clamp)
        n_e1 = s.e1_samples
        if clock.deadline is not None:
            budget = max(clock.remaining(), 0.0) * _SHARE["vpl"]
            n_e1 = int(min(n_e1, max(16, budget * _E1_RATE / max(int((chains.count > 0).sum()), 1))))
        stats["e1_samples"] = n_e1
        vpls = make_vpls(scene, g, chains, e_d, gmax, n_e1, rng, chunk=self.memory.e1_chunk)
        timings["vpls"] = time.perf_counter() - t0
        stats["vpls"] = len(vpls)
        stats["vpls_unlit_fallback"] = int(chains.count[chains.count > 0].size - len(vpls))
        clock.report(0.7, "Ercuts: light tree")
        # 4. Light tree.
        t0 = time.perf_counter()
        tree = None
        if s.gather == "LIGHTCUTS" and len(vpls):
            tree = build_light_tree(vpls.position, vpls.normal, vpls.intensity, seed=s.seed)
        timings["tree"] = time.perf_counter() - t0
        # 5. Lightcuts (or the brute-force ablation).
        t0 = time.perf_counter()
        gather, cut = self._gather(g, vpls, tree, gmax, clock, stats)
        timings["cuts"] = time.perf_counter() - t0
        gather = self._conserve_energy(gather, vpls, P, stats)
        self._finish(film, direct + gather, vpls, g, chains, cut)

    def _deadline(self, clock, share: float) -> float | None:
        if clock.deadline is None:
            return None
        now = time.perf_counter()
        return now + max(clock.deadline - now, 0.0) * share

    def _alive(self, clock, deadline, fraction, message) -> bool:
        ok = clock.report(fraction, message)
        return ok and (deadline is None or time.perf_counter() < deadline)

    # ------------------------------------------------------------------ phase 1
    def _rough_bdpt(self, clock, deadline) -> tuple[Film, int]:
        """``samples`` BDPT passes (fewer if the phase's time share runs out)."""
        from .bdpt import BDPTIntegrator
        s, scene = self.settings, self.scene
        bdpt = BDPTIntegrator(scene, s)
        window = scene.camera.window
        rough = Film(window)
        n = window.n_pixels
        batch = self.memory.batch_pixels
        for k in range(s.samples):
            part = Film(window)
            for start in range(0, n, batch):
                rng = np.random.default_rng([s.seed, k, start])
                bdpt.render_batch(part, np.arange(start, min(n, start + batch)), rng)
                if not clock.report(0.25 * (k + min(n, start + batch) / n) / s.samples,
                                    f"Ercuts: BDPT sample {k + 1}/{s.samples}"):
                    break
            if not clock.cancelled or rough.passes_done == 0:
                rough.merge(part)
            if clock.cancelled or (deadline is not None and time.perf_counter() > deadline and k > 0):
                break
        return rough, rough.passes_done

    def _seeds(self, rng, pix=None):
        s, scene = self.settings, self.scene
        if s.seeding == "BDPT":
            from .bdpt import seed_paths
            return seed_paths(scene, s, rng, pix)
        return seeds_from_path_tracer(scene, s.max_depth, rng, pix)

    def _chain_seeds(self, e_d: float, rng):
        """Seed paths and their chain counts, in batches of ``memory.seed_pixels`` pixels; only
        seeds that start a chain are kept, so the seed memory is that of one batch."""
        s, n = self.settings, self.scene.camera.window.n_pixels
        step = self.memory.seed_pixels
        if step >= n:
            seeds, energy = self._seeds(rng)
            starts = chain_starts(energy, s.chain_length, e_d, rng)
            return seeds, starts, len(seeds)
        kept, counts, total = [], [], 0
        for start in range(0, n, step):
            seeds, energy = self._seeds(rng, np.arange(start, min(n, start + step)))
            starts = chain_starts(energy, s.chain_length, e_d, rng)
            kept.append(seeds.take(np.flatnonzero(starts > 0)))
            counts.append(starts[starts > 0])
            total += len(seeds)
        return PathBatch.concat(kept), np.concatenate(counts), total

    # ------------------------------------------------------------------ non-VPL light
    def _direct_image(self, g: GBuffer, rng, n_light_samples: int = 4) -> NDArray:
        """(h·w, 3) light seen directly plus direct light from point, spot, sun and environment."""
        scene, s = self.scene, self.settings
        lights = scene.lights
        window = scene.camera.window
        S = g.samples
        L = np.zeros((len(g.pixel), 3))
        hit = g.valid
        L[hit] = scene.emission(g.surf.subset(np.flatnonzero(hit)))
        if lights.env_light >= 0 and not s.film_transparent:
            L[~hit] = lights.env_L
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
            L[h] += acc / n_light_samples
        return self._per_pixel(L, window.n_pixels, S)

    @staticmethod
    def _per_pixel(values: NDArray, n_pixels: int, S: int) -> NDArray:
        """Average the S shading points of each pixel: (n_pixels·S, C) → (n_pixels, C)."""
        return values.reshape(n_pixels, S, -1).mean(axis=1)

    # ------------------------------------------------------------------ phase 5
    def _gather(self, g: GBuffer, vpls, tree, gmax: float, clock, stats) -> tuple[NDArray, NDArray]:
        scene, s = self.scene, self.settings
        window = scene.camera.window
        Q = len(g.pixel)
        L = np.zeros((Q, 3))
        cut = np.zeros(Q)
        if len(vpls) == 0:
            return self._per_pixel(L, window.n_pixels, g.samples), self._per_pixel(cut[:, None], window.n_pixels, g.samples)
        pts_all = np.flatnonzero(g.valid)
        # Absolute error floor (algorithm.md §G.6; not in the papers): below a small fraction
        # of the mean pixel luminance, Weber's law no longer applies (dark pixels would refine
        # to max_cut_size for errors nobody can see).
        floor = s.max_error * ABS_FLOOR * stats.get("P", 0.0) / max(window.n_pixels, 1)
        f_bound = bsdf_max_value(scene.materials, g.mat)
        clamp = 0.0 if not np.isfinite(gmax) else gmax
        rays = 0
        clamped = 0.0
        done = 0
        cap = s.max_cut_size
        t_start = time.perf_counter()
        # A small first batch calibrates the cost per point before the cap is fitted.
        edges = np.unique(np.r_[0, np.arange(min(256, len(pts_all)), len(pts_all), self.memory.gather_batch),
                                len(pts_all)])
        for start, stop in zip(edges[:-1], edges[1:]):
            idx = pts_all[start:stop]
            pts = self._shading_points(g, idx, f_bound)
            if s.gather == "LIGHTCUTS":
                res = lightcut(tree, vpls.position, vpls.normal, vpls.intensity, pts,
                               max_error=s.max_error, max_cut_size=cap, clamp=clamp,
                               abs_floor=floor)
                L[idx], cut[idx] = res.radiance, res.cut_size
                rays += res.shadow_rays
                clamped += res.clamped_energy
            else:
                L[idx] = brute_force(vpls.position, vpls.normal, vpls.intensity, pts, clamp=clamp)
                cut[idx] = len(vpls)
                rays += len(idx) * len(vpls)
            done = start + len(idx)
            cap = self._fit_cap(cap, cut[idx].mean(), done, len(pts_all) - done,
                                time.perf_counter() - t_start, clock.remaining())
            if not clock.poll(0.7 + 0.3 * done / max(len(pts_all), 1), "Ercuts: lightcuts") or \
                    (done < len(pts_all) and clock.remaining() <= 0):
                stats["gather_incomplete"] = 1
                clock.cancelled = True
                break
        if cap < s.max_cut_size:
            stats["cut_cap_for_time_limit"] = cap
        valid_cut = cut[pts_all[:done]] if done else np.zeros(1)
        stats["cut_size_mean"] = float(valid_cut.mean()) if done else 0.0
        stats["cut_size_max"] = int(valid_cut.max()) if done else 0
        stats["gather_shadow_rays"] = rays
        stats["clamped_energy"] = clamped / g.samples
        return (self._per_pixel(L, window.n_pixels, g.samples),
                self._per_pixel(cut[:, None], window.n_pixels, g.samples))

    @staticmethod
    def _fit_cap(cap: int, mean_cut: float, done: int, left: int, elapsed: float, remaining: float) -> int:
        """Lower the cut-size cap so that the rest of the gather fits the time left.

        A complete image with smaller cuts beats a partial one; the cost per point is
        taken as proportional to the mean cut size so far.
        """
        if left == 0 or not np.isfinite(remaining) or done == 0:
            return cap
        projected = elapsed / done * left
        if projected <= remaining:
            return cap
        scale = max(remaining, 0.0) / projected * 0.8
        return int(max(1, min(cap, mean_cut * scale)))

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

    def _conserve_energy(self, gather: NDArray, vpls, P: float, stats: dict) -> NDArray:
        """Scale the VPL image so that its energy is P (paper §3.3: every path carries P/n).

        Each VPL is normalised by its own estimate Ê1 (vpl.py); the average of 1/Ê1 is
        biased high (Jensen), a few per cent with 256 light-traced samples. The ratio
        P / E(VPL image) removes that bias globally while the per-VPL Ê1 keep the relative
        intensities. The raw ratio is reported as ``vpl_energy_ratio`` (1 = unbiased).
        """
        energy = float(luminance(gather + vpls.fallback).sum())
        stats["vpl_energy_ratio"] = energy / P if P > 0 else 0.0
        if energy <= 0 or P <= 0 or stats.get("gather_incomplete"):
            return gather
        scale = P / energy
        vpls.fallback *= scale
        return gather * scale

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

    def _finish(self, film: Film, image: NDArray, vpls, g: GBuffer, chains, cut) -> None:
        """Put the one-pass result into the film (color, alpha, AOVs)."""
        window = self.scene.camera.window
        if vpls is not None:
            image = image + vpls.fallback
        film.color[:] = image
        hit = g.valid.astype(np.float64) if self.settings.film_transparent else np.ones(len(g.pixel))
        film.alpha[:] = self._per_pixel(hit[:, None], window.n_pixels, g.samples)[:, 0]
        depth = np.where(g.valid, g.surf.t, 1e10)[:, None]
        film.aov_sum["depth"] = self._per_pixel(depth, window.n_pixels, g.samples)
        film.aov_sum["normal"] = self._per_pixel(np.where(g.valid[:, None], g.ns, 0.0), window.n_pixels, g.samples)
        if chains is not None:
            film.aov_sum["chain_deposits"] = chains.deposits_per_pixel[:, None].astype(np.float64)
        if cut is not None:
            film.aov_sum["cut_size"] = cut
        film.passes_done = 1
