"""Why is the VPL image's energy off before the rescale to P (issue 13, item 4)?

``vpl_energy_ratio`` = Y(VPL image + fallback) / P. Every chain state carries e_d = P/n,
so Σ_v k_v·e_d = P exactly, and the ratio is the count-weighted mean of
E1_gather(v) / Ê1(v) (plus the exact fallback share): E1_gather is the energy the gather
really gives a unit VPL (one shading point per pixel, clamp, visibility), Ê1 the
light-traced estimate that normalised it. The script renders a scene with ERCUTS
(BRUTE_FORCE gather), captures the VPLs, draws a subset of VPLs ∝ k_v and measures, per
candidate cause, the ratio with that cause switched off:

1. Jensen bias of 1/Ê1: Ê1 with 256 / 1024 / 4096 samples and a converged Ê1;
2. the geometry clamp: both sides without it;
3. one shading point at the pixel centre vs the pixel integral: E1 over 16 jittered
   shading points per pixel;
4. visibility/offsets: the converged light-traced E1 against the jittered pixel sum
   (both exact integrals of the same thing);
5. the fallback share (VPLs that lit no sampled pixel);
6. the chain counts: Σ k_v·e_d vs P.

Run:  .venv/bin/python benchmarks/e1_bias.py [--quick]
Writes benchmarks/results/e1_bias.md.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from ercuts_core import RenderSettings, render  # noqa: E402
from ercuts_core.integrators.ercuts import integrator as integ_mod  # noqa: E402
from ercuts_core.integrators.ercuts.gather import Gather  # noqa: E402
from ercuts_core.integrators.ercuts.lightcuts import evaluate_lights  # noqa: E402
from ercuts_core.integrators.ercuts.vpl import (build_gbuffer,  # noqa: E402
                                                 estimate_e1_light_tracing)
from ercuts_core.bsdf import bsdf_max_value  # noqa: E402
from ercuts_core.sampling import luminance  # noqa: E402
from ercuts_core.scenes import closed_room, cornell_box, door_ajar, s_corridor  # noqa: E402

SCENES = {"cornell_box": cornell_box, "closed_room": closed_room, "s_corridor": s_corridor,
          "door_ajar": door_ajar}
FAST = dict(integrator="ERCUTS", samples=8, chain_length=40, chains_per_pixel=0.5,
            gather="BRUTE_FORCE")


def capture(desc, settings):
    """Render and keep what ``make_vpls`` saw and returned."""
    cap = {}
    orig = integ_mod.make_vpls

    def wrapper(scene, g, chains, e_d, gmax, n_samples, rng, *a, **kw):
        vpls = orig(scene, g, chains, e_d, gmax, n_samples, rng, *a, **kw)
        cap.update(scene=scene, g=g, chains=chains, e_d=e_d, gmax=gmax, vpls=vpls, n_e1=n_samples)
        return vpls

    integ_mod.make_vpls = wrapper
    try:
        res = render(desc, settings)
    finally:
        integ_mod.make_vpls = orig
    return res, cap


def gather_energy(scene, settings, g, pos, normal, color, gmax, block=1 << 20):
    """(V,) Σ_pixels Y(pixel value of each unit VPL) with the gather's own evaluation
    (:func:`evaluate_lights`, pixel value = mean of the G-buffer's S points)."""
    gat = Gather(scene, settings, g, 1 << 30)
    pts_idx = np.flatnonzero(g.valid)
    pts = gat._shading_points(pts_idx, bsdf_max_value(scene.materials, g.mat))
    clamp = 0.0 if not np.isfinite(gmax) else gmax
    V, Q = len(pos), len(pts_idx)
    out = np.zeros(V)
    vstep = max(1, block // Q)
    for v0 in range(0, V, vstep):
        v1 = min(V, v0 + vstep)
        pidx = np.tile(np.arange(Q), v1 - v0)
        vidx = np.repeat(np.arange(v0, v1), Q)
        unit, _, _ = evaluate_lights(pts, pidx, vidx, pos, normal, clamp)
        y = luminance(unit * color[vidx])
        out[v0:v1] = np.bincount(vidx - v0, weights=y, minlength=v1 - v0)
    return out / g.samples


def lt(scene, pos, normal, color, gmax, n, seed):
    return estimate_e1_light_tracing(scene, pos, normal, color, gmax, n, np.random.default_rng(seed))


def analyse(name, W, H, seed, n_sub=150, jitter=16, n_conv=16384, log=print):
    desc = SCENES[name](W, H)
    settings = RenderSettings(**FAST, seed=seed)
    t0 = time.time()
    res, cap = capture(desc, settings)
    scene, g, vpls, e_d, gmax = cap["scene"], cap["g"], cap["vpls"], cap["e_d"], cap["gmax"]
    chains = cap["chains"]
    st = res.stats
    P = st["P"]
    V = len(vpls)
    color = vpls.intensity / luminance(vpls.intensity)[:, None]
    k = vpls.count.astype(float)
    fb = float(luminance(vpls.fallback).sum())
    # (6) chain bookkeeping: Σ k·e_d over all VPLs (lit + fallback) vs P
    k_all = float(chains.count.sum())
    row = dict(scene=name, res=f"{W}x{H}", seed=seed, V=V, ratio_stat=st["vpl_energy_ratio"],
               sum_k_ed_over_P=k_all * e_d / P, fallback_share=fb / P,
               fallback_vpls=int((chains.count > 0).sum()) - V)
    # full reconstruction of the stat with the gather's own per-VPL energy
    e1g_all = gather_energy(scene, settings, g, vpls.position, vpls.normal, color, gmax)
    row["ratio_reconstructed"] = float((k * e_d * e1g_all / vpls.e1).sum() + fb) / P
    # subset ∝ k (with replacement): the mean of a per-VPL ratio estimates the weighted mean
    rng = np.random.default_rng([seed, 77])
    sub = rng.choice(V, size=min(n_sub, V), p=k / k.sum())
    pos, nrm, col = vpls.position[sub], vpls.normal[sub], color[sub]
    w_lit = float((k * e_d).sum()) / P          # share of P carried by lit VPLs

    def wmean(num, den):
        return float(np.mean(num / den)) * w_lit + fb / P

    e1g = e1g_all[sub]
    e1_run = vpls.e1[sub]
    inf = np.inf
    # (1) Jensen
    e1_n = {n: lt(scene, pos, nrm, col, gmax, n, [seed, n]) for n in (256, 1024, 4096)}
    e1_conv = np.mean([lt(scene, pos, nrm, col, gmax, 4096, [seed, 9, i])
                       for i in range(n_conv // 4096)], axis=0)
    e1_conv_nc = np.mean([lt(scene, pos, nrm, col, inf, 4096, [seed, 19, i])
                          for i in range(n_conv // 4096)], axis=0)
    # (2) clamp off in the gather
    e1g_nc = gather_energy(scene, settings, g, pos, nrm, col, inf)
    # (3) pixel integral: jittered shading points
    gj, _ = build_gbuffer(scene, jitter, np.random.default_rng([seed, 5]))
    e1j = gather_energy(scene, settings, gj, pos, nrm, col, gmax)
    e1j_nc = gather_energy(scene, settings, gj, pos, nrm, col, inf)
    row.update(
        ratio_subset_run=wmean(e1g, e1_run),
        jensen_256=wmean(e1g, e1_n[256]), jensen_1024=wmean(e1g, e1_n[1024]),
        jensen_4096=wmean(e1g, e1_n[4096]), conv=wmean(e1g, e1_conv),
        E_1_over_e1_256=float(np.mean(e1_conv / e1_n[256])),
        E_1_over_e1_1024=float(np.mean(e1_conv / e1_n[1024])),
        E_1_over_e1_4096=float(np.mean(e1_conv / e1_n[4096])),
        noclamp_conv=wmean(e1g_nc, e1_conv_nc),
        clamp_mismatch=wmean(e1g, e1_conv_nc),       # gather clamps, Ê1 does not
        jitter_conv=wmean(e1j, e1_conv), jitter_noclamp_conv=wmean(e1j_nc, e1_conv_nc),
        centre_over_jitter=float(np.mean(e1g / e1j)),
        time=time.time() - t0)
    row["_per_vpl"] = dict(pos=pos, nrm=nrm, e1g=e1g, e1j=e1j, e1j_nc=e1j_nc, e1g_nc=e1g_nc,
                           e1_conv=e1_conv, e1_conv_nc=e1_conv_nc, e1_run=e1_run, e1_n=e1_n,
                           emitter=vpls.emitter[sub], scene=scene)
    log({k_: (round(v, 4) if isinstance(v, float) else v) for k_, v in row.items() if k_ != "_per_vpl"})
    return row


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="cornell_box")
    ap.add_argument("--res", default="48x36")
    ap.add_argument("--seeds", default="1")
    a = ap.parse_args()
    W, H = map(int, a.res.split("x"))
    for s in map(int, a.seeds.split(",")):
        analyse(a.scene, W, H, s)


def energy_ratios(scenes=("cornell_box", "closed_room", "s_corridor"), seeds=(1, 2, 3), res=(64, 48)):
    """``vpl_energy_ratio`` of plain renders (FAST settings, brute-force gather)."""
    out = {}
    for name in scenes:
        for seed in seeds:
            r = render(SCENES[name](*res), RenderSettings(**FAST, seed=seed))
            out[f"{name}/{seed}"] = r.stats["vpl_energy_ratio"]
            print(name, seed, round(r.stats["vpl_energy_ratio"], 4), flush=True)
    return out
