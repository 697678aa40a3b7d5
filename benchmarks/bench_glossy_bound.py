"""Old vs new lightcut material bound at glossy receivers (issue 13, part 3).

Scene: the box room of ``bench_lightcuts.py`` (VPLs on the walls and the ceiling, a
pillar occluder), with a *glossy* floor (GGX, Principled roughness 0.05, 0.2 or 0.5,
specular 0.5 and 1.0, some metallic) seen from a low eye (0.4 m above the floor near a
wall), so the far floor is seen at grazing angles (n·wo down to ~0.07).

"old" = the constant bound ``bsdf_max_value`` (the specular lobe's value at normal
incidence, F90/(4πα²)); "new" = the per-cluster GGX bound (``GlossyReceivers``).
For each error mode, it reports the lightcut time (process CPU, best of 2), the mean cut
size, the relative luminance error against brute force (mean, max), and the share of final
cut nodes whose *true* cluster luminance exceeds their bound L̄_C.

With ``--cornell`` it renders instead a 64×48 Cornell box (``scenes.cornell_box``) whose
white surfaces are glossy (GGX roughness 0.05 / 0.2 / 0.5, specular 1, metallic 0.5) with
the full Ercuts pipeline (seed 1, default settings: lightcut_error 'NODE'), gathered by brute
force, by lightcuts with the old bound (``gather.GLOSSY_CLUSTER_BOUND = False``) and with the
new one, and reports the gather time, the mean cut size, shadow rays and the per-pixel
relative luminance error against the brute-force gather of the same VPLs.

Writes ``benchmarks/results/glossy_bound.md`` (``glossy_bound_cornell.md`` with --cornell).
Run: ``.venv/bin/python benchmarks/bench_glossy_bound.py [--quick] [--cornell]``.
"""
from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))

from bench_lightcuts import PILLAR, ROOM, _segment_hits_box, best_of, room_vpls  # noqa: E402

from ercuts_core.bsdf import Bsdf, bsdf_max_value  # noqa: E402
from ercuts_core.description import MaterialTable  # noqa: E402
from ercuts_core.integrators.ercuts.light_tree import build_light_tree  # noqa: E402
from ercuts_core.integrators.ercuts.lightcuts import (  # noqa: E402
    GlossyReceivers,
    ShadingPoints,
    brute_force,
    evaluate_lights,
    lightcut,
)
from ercuts_core.sampling import luminance  # noqa: E402

EYE = np.array([2.0, 0.05, 0.4])
OUT = os.path.join(ROOT, "benchmarks", "results")


def glossy_floor(count: int, roughness: float, seed: int) -> ShadingPoints:
    """Glossy floor points outside the pillar, wo toward EYE; new (per-cluster) bound."""
    rng = np.random.default_rng(seed)
    xy = rng.random((4 * count, 2)) * ROOM[:2]
    inside = np.all((xy > PILLAR[0][:2]) & (xy < PILLAR[1][:2]), axis=1)
    xy = xy[~inside & (xy[:, 1] > 0.3)][:count]
    x = np.column_stack([xy, np.full(len(xy), 1e-3)])
    n = len(x)
    up = np.tile([0.0, 0.0, 1.0], (n, 1))
    wo = EYE - x
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    metal = (np.arange(n) % 3 == 0).astype(float)
    table = MaterialTable([f"m{i}" for i in range(n)], np.tile([0.8, 0.6, 0.4], (n, 1)),
                          np.full(n, roughness), metal, np.where(np.arange(n) % 2, 1.0, 0.5),
                          np.zeros((n, 3)))
    idx = np.arange(n)
    bsdf = Bsdf.from_table(table, idx, up, up)

    def eval_f(i: NDArray, wi: NDArray) -> NDArray:
        return bsdf.subset(i).eval(wo[i], wi)

    def visible(i: NDArray, q: NDArray, qn: NDArray) -> NDArray:
        return ~_segment_hits_box(x[i], q - x[i], *PILLAR)

    return ShadingPoints(x, up, wo, bsdf_max_value(table, idx), eval_f, visible,
                         glossy=GlossyReceivers.from_bsdf(bsdf, wo, up))


def exceeded(tree, lights, pts: ShadingPoints, res) -> float:
    """Share of final internal cut nodes whose exact cluster luminance (V included)
    exceeds L̄_C."""
    pos, nrm, inten = lights
    internal = ~tree.is_leaf[res.cut_node]
    pt, node = res.cut_point[internal], res.cut_node[internal]
    count = tree.leaf_count[node]
    rows = np.repeat(np.arange(len(node)), count)
    start = np.repeat(tree.leaf_start[node] - np.cumsum(count) + count, count)
    vpl = tree.leaf_order[start + np.arange(len(rows))]
    unit, _, _ = evaluate_lights(pts, pt[rows], vpl, pos, nrm)
    truth = np.bincount(rows, luminance(unit * inten[vpl]), len(node))
    return float(np.mean(truth > res.cut_bound[internal] * (1 + 1e-9)))


def cornell() -> None:
    """The --cornell table (module docstring)."""
    from ercuts_core import scenes
    from ercuts_core.integrators.ercuts import gather
    from ercuts_core.render import render
    from ercuts_core.settings import RenderSettings

    lines = ["# Glossy Cornell box: lightcut gather with the old vs the new glossy bound", "",
             "64×48 Cornell box, white surfaces GGX (roughness below, specular 1, metallic "
             "0.5), Ercuts defaults (seed 1, lightcut_error 'NODE', 2 %, cut ≤ 1000). "
             "'cuts' = wall seconds of the gather phase (shared 2-core machine); errors = "
             "per-pixel relative luminance error against the brute-force gather (pixels "
             "above 1e-3 × the mean). Generated by `benchmarks/bench_glossy_bound.py "
             "--cornell`.", "",
             "| roughness | gather | cuts [s] | cut mean | shadow rays | err mean | err p99 "
             "| err max |", "|---:|---|---:|---:|---:|---:|---:|---:|"]
    base = scenes.cornell_box(64, 48)
    m = base.materials
    for rough in (0.05, 0.2, 0.5):
        mats = MaterialTable(m.names, m.base_color, [rough, 1, 1, 1], [0.5, 0, 0, 0],
                             [1.0, 0, 0, 0], m.emission)
        desc = replace(base, materials=mats)
        ref = None
        for name in ("brute force", "old bound", "new bound"):
            gather.GLOSSY_CLUSTER_BOUND = name != "old bound"
            try:
                r = render(desc, RenderSettings(
                    seed=1, gather="BRUTE_FORCE" if name == "brute force" else "LIGHTCUTS"))
            finally:
                gather.GLOSSY_CLUSTER_BOUND = True
            y = luminance(r.image[..., :3].reshape(-1, 3).astype(np.float64))
            if ref is None:
                ref, err = y, ""
            else:
                lit = ref > 1e-3 * ref.mean()
                rel = np.abs(y - ref)[lit] / ref[lit]
                err = (f"{100 * rel.mean():.2f} % | {100 * np.quantile(rel, 0.99):.2f} % | "
                       f"{100 * rel.max():.1f} %")
            row = (f"| {rough} | {name} | {r.timings['cuts']:.2f} | "
                   f"{r.stats['cut_size_mean']:.1f} | {int(r.stats['gather_shadow_rays']):,} | "
                   + (err or "– | – | –") + " |")
            print(row, flush=True)
            lines.append(row)
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "glossy_bound_cornell.md"), "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--cornell", action="store_true")
    args = ap.parse_args()
    if args.cornell:
        cornell()
        return
    n_vpl, n_pts = (5000, 300) if args.quick else (20000, 600)
    lights = room_vpls(n_vpl, seed=n_vpl)
    tree = build_light_tree(*lights, seed=1)
    lines = ["# Lightcut material bound at glossy receivers: old (lobe peak) vs new (per cluster)",
             "", f"Room of `bench_lightcuts.py`, {n_vpl:,} VPLs, {n_pts} glossy floor points "
             "seen from a low eye (n·wo ≥ ~0.07); max_error = 2 %, max_cut_size = 1000. "
             "Times: process CPU seconds, best of 2 (shared 2-core machine). "
             "'bound exceeded' = share of final internal cut nodes whose exact luminance "
             "(visibility included) is above L̄_C. Generated by "
             "`benchmarks/bench_glossy_bound.py`" + (" --quick" if args.quick else "") + ".", "",
             "| roughness | error_mode | bound | lightcut [ms/pt] | cut mean | err mean | "
             "err max | bound exceeded |", "|---:|---|---|---:|---:|---:|---:|---:|"]
    for rough in (0.05, 0.2, 0.5):
        new = glossy_floor(n_pts, rough, seed=7)
        old = replace(new, glossy=None)
        exact = luminance(brute_force(*lights, new))
        for mode in ("bound", "total"):
            for name, pts in (("old", old), ("new", new)):
                res, sec = best_of(2, lambda: lightcut(tree, *lights, pts, error_mode=mode,
                                                       return_cut=True))
                rel = np.abs(luminance(res.radiance) - exact) / np.maximum(exact, 1e-300)
                row = (f"| {rough} | {mode} | {name} | {1e3 * sec / pts.count:.3f} | "
                       f"{res.cut_size.mean():.1f} | {100 * rel.mean():.2f} % | "
                       f"{100 * rel.max():.2f} % | {100 * exceeded(tree, lights, pts, res):.2f} % |")
                print(row, flush=True)
                lines.append(row)
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "glossy_bound.md"), "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
