"""Stochastic-lightcut cut size: the gather's noise per pass against its cost per pass.

The stochastic gather (Yuksel 2019; ``stochastic_lightcuts.py``) refines a cut of
``cut_size`` nodes per shading point by the Lightcuts bounds and evaluates each node with one
VPL drawn ∝ luminance.  Its variance per pass V_g and its seconds per pass τ set how much the
gather costs for a given noise: an iteration's gather error is V_g/n after n passes, so the
figure of merit is V_g·τ (lower is better; the error of a gather given t seconds is V_g·τ/t).

For each scene (160×120, one ERCUTS iteration at default settings but one pass and 4 rough
samples), this benchmark wraps the gather's ``stochastic_lightcut`` and, for batches 2–5 of the
first pass (batch 1 pays numba's compilation), evaluates the batch's points ``--repeats`` times
with each cut size on the same VPLs, tree and shading points (independent draws), timing each
call.  V_g is the relMSE-weighted sample variance of the points' luminance over the repeats,
mean_p var_p / (m_p² + 0.01) with m_p the points' mean over all cut sizes (the benchmarks'
relMSE regulariser), i.e. the relMSE one pass adds; τ is the mean time of one call scaled to
the batch.  The tree and VPLs are those of the render's first iteration (seed 0).

Writes ``benchmarks/results/stochastic_cut.md``.  Run:
``.venv/bin/python benchmarks/bench_stochastic_cut.py`` (≈ 6 min on 2 cores for the default
scenes); ``--scenes door_ajar`` for one.  Speed is measured here, never asserted by a test.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import metrics  # noqa: E402  (benchmarks/metrics.py: the relMSE regulariser)
import report  # noqa: E402  (benchmarks/report.py: the scenes)
from ercuts_core import RenderSettings, render  # noqa: E402
from ercuts_core.integrators.ercuts import gather  # noqa: E402
from ercuts_core.sampling import luminance  # noqa: E402

RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results", "stochastic_cut.md")
SCENES = ["door_ajar", "s_corridor", "baffled_lamp", "cornell_box", "veach_room", "textured_living_room"]


def measure(scene: str, sizes: list[int], repeats: int, batches: range) -> dict[int, tuple[float, float]]:
    """{cut size: (V_g per pass, seconds per batch call)} for ``scene`` (module docstring)."""
    original = gather.stochastic_lightcut
    acc = {c: [0.0, 0.0, 0] for c in sizes}
    calls = [0]

    def wrapped(tree, pos, nrm, inten, pts, rng, cut_size=32, clamp=0.0, cdf=None, ref=None):
        calls[0] += 1
        if calls[0] in batches:
            ys, secs = {}, {}
            for c in sizes:
                t0 = time.perf_counter()
                ys[c] = np.array([luminance(original(tree, pos, nrm, inten, pts, np.random.default_rng(1000 + r),
                                                     cut_size=c, clamp=clamp, cdf=cdf, ref=ref).radiance)
                                  for r in range(repeats)])
                secs[c] = (time.perf_counter() - t0) / repeats
            m = np.mean([y.mean(axis=0) for y in ys.values()], axis=0)
            for c in sizes:
                a = acc[c]
                a[0] += float((ys[c].var(axis=0, ddof=1) / (m * m + metrics.EPS)).sum())
                a[1] += secs[c]
                a[2] += m.size
        return original(tree, pos, nrm, inten, pts, rng, cut_size=cut_size, clamp=clamp, cdf=cdf, ref=ref)

    gather.stochastic_lightcut = wrapped
    try:
        render(report.scene_description(scene, 160, 120),
               RenderSettings(seed=0, stochastic_passes=1, rough_samples=4))
    finally:
        gather.stochastic_lightcut = original
    return {c: (a[0] / max(a[2], 1), a[1]) for c, a in acc.items()}


def table(rows: dict[str, dict[int, tuple[float, float]]], sizes: list[int]) -> str:
    """Markdown: per scene and cut size V_g, τ and V_g·τ relative to the smallest size's."""
    out = ["| scene | cut size | V_g per pass (relMSE) | seconds per batch | V_g·τ | V_g·τ vs "
           f"{sizes[0]} |", "|---|---|---|---|---|---|"]
    for scene, r in rows.items():
        base = r[sizes[0]][0] * r[sizes[0]][1]
        for c in sizes:
            v, t = r[c]
            out.append(f"| {scene} | {c} | {v:.4g} | {t:.3f} | {v * t:.3g} | {v * t / base:.2f} |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=SCENES, choices=list(report.SCENES))
    ap.add_argument("--sizes", type=int, nargs="+", default=[32, 128, 256, 512])
    ap.add_argument("--repeats", type=int, default=6)
    a = ap.parse_args()
    rows = {}
    for scene in a.scenes:
        rows[scene] = measure(scene, a.sizes, a.repeats, range(2, 6))
        print(scene, {c: f"V={v:.4g} t={t:.3f}" for c, (v, t) in rows[scene].items()}, flush=True)
    text = ("# Stochastic lightcuts: noise per pass against cost per pass\n\n"
            "Written by `benchmarks/bench_stochastic_cut.py` (method in its docstring): batches 2–5 of "
            "the first gather pass of one ERCUTS iteration (seed 0, 160×120), each evaluated "
            f"{a.repeats} times per cut size on the same VPLs and points. V_g is the relMSE one pass "
            "adds; lower V_g·τ is a cheaper gather for the same noise.\n\n" + table(rows, a.sizes) + "\n")
    with open(RESULTS, "w") as f:
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()
