"""Scaling of the Ercuts light tree + lightcuts with the number of VPLs.

Scene: a 4 × 4 × 3 m box room.  The VPLs lie on the four walls and the ceiling, with
inward normals and log-normal RGB intensities, plus a 20× brighter "window" patch.  The
shading points are diffuse receivers on the floor (albedo 0.7/0.6/0.5).  An opaque
0.8 × 0.8 × 2 m pillar in the middle is tested analytically by the ``visible``
callback.  The total VPL power is the same for every N, so the images agree.

For N = 10³ … 10⁵ (and 3·10⁵ when the 10⁵ run suggests it takes < 2 min) it measures
the tree build time (Zhu, Xu, Pan 2010 §3.4; locally-ordered pairing after Walter et
al. 2008), the lightcut shading time per point, the cut size, and the shadow rays per
point (Walter et al. 2005, 2 % rule, max cut 1000).  Brute force (all VPLs, the
ablation) runs on a subset of the points, and the relative luminance error of the cut
is measured against it.

Writes ``benchmarks/results/lightcuts_scaling.{md,png}``.
Run: ``.venv/bin/python benchmarks/bench_lightcuts.py [--quick]``.

``--kernels``: instead, the gather time per shading point with the compiled kernels
(``ercuts_core/kernels``, numba) against the numpy code, A/B interleaved, against the VPL
count and the cut size: bounded cuts ('bound' and 'total' rules) and stochastic cuts of 8,
32 and 128 nodes; writes ``benchmarks/results/gather_kernels.md``.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from ercuts_core import kernels  # noqa: E402
from ercuts_core.integrators.ercuts.light_tree import build_light_tree  # noqa: E402
from ercuts_core.integrators.ercuts.stochastic_lightcuts import stochastic_lightcut  # noqa: E402
from ercuts_core.sampling import luminance  # noqa: E402
from ercuts_core.integrators.ercuts.lightcuts import ShadingPoints, brute_force, lightcut  # noqa: E402

ROOM = np.array([4.0, 4.0, 3.0])
PILLAR = (np.array([1.6, 1.6, 0.0]), np.array([2.4, 2.4, 2.0]))
OUT = os.path.join(ROOT, "benchmarks", "results")


def room_vpls(n: int, seed: int) -> tuple[NDArray, NDArray, NDArray]:
    """VPLs on the walls (faces 0–3) and the ceiling (face 4): (n,3) pos, normal, RGB."""
    rng = np.random.default_rng(seed)
    face = rng.integers(0, 5, n)
    axis = np.array([0, 0, 1, 1, 2])[face]
    side = np.array([0, 1, 0, 1, 1])[face]
    pos = rng.random((n, 3)) * ROOM
    pos[np.arange(n), axis] = side * ROOM[axis]
    nrm = np.zeros((n, 3))
    nrm[np.arange(n), axis] = np.where(side == 1, -1.0, 1.0)
    inten = rng.lognormal(0.0, 1.0, (n, 1)) * (0.6 + 0.4 * rng.random((n, 3)))
    window = (face == 0) & (np.abs(pos[:, 1] - 2.0) < 0.5) & (np.abs(pos[:, 2] - 1.5) < 0.5)
    inten[window] *= 20.0
    return pos, nrm, inten * (1e4 / n)


def _segment_hits_box(o: NDArray, d: NDArray, lo: NDArray, hi: NDArray) -> NDArray:
    """Does the segment o + t·d, t ∈ [0, 1], meet the box [lo, hi]? (K,) bool (slab test)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (lo - o) / d, (hi - o) / d
    tmin = np.nanmax(np.minimum(t0, t1), axis=1)
    tmax = np.nanmin(np.maximum(t0, t1), axis=1)
    return (tmax >= np.maximum(tmin, 0.0)) & (tmin <= 1.0)


def floor_points(count: int, seed: int) -> ShadingPoints:
    """Diffuse receivers on the floor outside the pillar; visibility against the pillar."""
    rng = np.random.default_rng(seed)
    xy = rng.random((4 * count, 2)) * ROOM[:2]
    inside = np.all((xy > PILLAR[0][:2]) & (xy < PILLAR[1][:2]), axis=1)
    xy = xy[~inside][:count]
    x = np.column_stack([xy, np.full(count, 1e-3)])
    up = np.tile([0.0, 0.0, 1.0], (count, 1))
    alb = np.tile([0.7, 0.6, 0.5], (count, 1))

    def eval_f(i: NDArray, wi: NDArray) -> NDArray:
        return alb[i] / np.pi * (wi[:, 2] > 0.0)[:, None]

    def visible(i: NDArray, q: NDArray, qn: NDArray) -> NDArray:
        return ~_segment_hits_box(x[i], q - x[i], *PILLAR)

    return ShadingPoints(x, up, up.copy(), alb / np.pi, eval_f, visible)


def subset(pts: ShadingPoints, k: int) -> ShadingPoints:
    """The first k points (the callbacks index the first k rows unchanged)."""
    return ShadingPoints(pts.p[:k], pts.n[:k], pts.wo[:k], pts.f_bound[:k], pts.eval_f,
                         pts.visible)


@dataclass
class Row:
    n: int
    build_s: float
    height: int
    cut_ms_per_pt: float
    cut_mean: float
    cut_max: int
    rays_per_pt: float
    rounds: int
    brute_ms_per_pt: float
    err_mean: float
    err_max: float
    capped: float


def rel_error(approx: NDArray, exact: NDArray) -> NDArray:
    ya, ye = luminance(approx), luminance(exact)
    return np.abs(ya - ye) / np.maximum(ye, 1e-300)


def best_of(repeats: int, fn):
    """(result, minimum CPU time of this process over ``repeats`` calls).

    CPU time rather than wall time: the benchmark machine is shared, and the lightcut
    and brute-force code is single-threaded numpy (the build's K-NN queries use two
    threads, so its CPU time is an upper bound of the wall time).
    """
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t0)
    return out, best


def run_one(n: int, pts: ShadingPoints, n_brute: int, repeats: int = 3) -> Row:
    pos, nrm, inten = room_vpls(n, seed=n)
    tree, build = best_of(repeats, lambda: build_light_tree(pos, nrm, inten, seed=1))
    res, shade = best_of(repeats, lambda: lightcut(tree, pos, nrm, inten, pts))
    sub = subset(pts, n_brute)
    exact, brute = best_of(1, lambda: brute_force(pos, nrm, inten, sub))
    err = rel_error(res.radiance[:n_brute], exact)
    return Row(n, build, tree.height, 1e3 * shade / pts.count, float(res.cut_size.mean()),
               int(res.cut_size.max()), res.shadow_rays / pts.count, res.rounds,
               1e3 * brute / n_brute, float(err.mean()), float(err.max()),
               float(np.mean(res.cut_size >= 1000)))


def variants(n: int, pts: ShadingPoints, n_brute: int) -> list[tuple[str, float, float, float]]:
    """(label, cut mean, ms/point, mean and max rel. error, capped fraction) per variant."""
    pos, nrm, inten = room_vpls(n, seed=n)
    exact = brute_force(pos, nrm, inten, subset(pts, n_brute))
    out = []
    for pairing in ("ploc", "greedy"):
        tree = build_light_tree(pos, nrm, inten, seed=1, pairing=pairing)
        for mode in ("bound", "literal", "total"):
            res, sec = best_of(2 if mode == "total" else 3,
                               lambda: lightcut(tree, pos, nrm, inten, pts, error_mode=mode))
            err = rel_error(res.radiance[:n_brute], exact)
            out.append((f"pairing={pairing}, error_mode={mode}", float(res.cut_size.mean()),
                        1e3 * sec / pts.count, float(err.mean()), float(err.max()),
                        float(np.mean(res.cut_size >= 1000))))
    return out


def write_table(rows: list[Row], var: list, n_var: int, n_pts: int, n_brute: int) -> str:
    lines = [
        "# Lightcuts scaling (ercuts_core.integrators.ercuts: light_tree + lightcuts)",
        "",
        f"Box room 4×4×3 m, VPLs on walls + ceiling, {n_pts} diffuse floor points, an "
        "analytic pillar occluder; max_error = 2 %, max_cut_size = 1000, "
        "error_mode='bound' (Walter 2005), pairing='ploc'. Brute force and the errors use "
        f"the first {n_brute} points. Errors are relative luminance errors vs brute force; "
        "\"capped\" = share of points whose cut reached max_cut_size. Times are process CPU "
        "seconds (shared 2-core machine), best of 3 for the build and the lightcut; the "
        "build's K-NN queries run on 2 threads; other jobs on the machine still make the "
        "times vary by up to ~2× between runs (cut sizes, rays and errors are "
        "deterministic). Generated by `benchmarks/bench_lightcuts.py`.",
        "",
        "| N VPLs | build [s] | height | lightcut [ms/pt] | cut mean | cut max | rays/pt "
        "| rounds | brute [ms/pt] | speed-up | err mean | err max | capped |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r.n:,} | {r.build_s:.2f} | {r.height} | {r.cut_ms_per_pt:.3f} | "
            f"{r.cut_mean:.1f} | {r.cut_max} | {r.rays_per_pt:.1f} | {r.rounds} | "
            f"{r.brute_ms_per_pt:.2f} | {r.brute_ms_per_pt / r.cut_ms_per_pt:.0f}× | "
            f"{100 * r.err_mean:.2f} % | {100 * r.err_max:.2f} % | {100 * r.capped:.0f} % |")
    if len(rows) >= 2:
        a, b = rows[0], rows[-1]
        slope = np.log(b.cut_mean / a.cut_mean) / np.log(b.n / a.n)
        tslope = np.log(b.cut_ms_per_pt / a.cut_ms_per_pt) / np.log(b.n / a.n)
        lines += ["", f"Growth from N = {a.n:,} to {b.n:,}: cut size ∝ N^{slope:.2f}, "
                  f"shading time per point ∝ N^{tslope:.2f} (brute force ∝ N^1)."]
    lines += ["", f"## Variants at N = {n_var:,} (same points)", "",
              "| variant | cut mean | lightcut [ms/pt] | err mean | err max | capped |",
              "|---|---:|---:|---:|---:|---:|"]
    for label, cut, ms, em, ex, cap in var:
        lines.append(f"| {label} | {cut:.1f} | {ms:.3f} | {100 * em:.2f} % | {100 * ex:.2f} % "
                     f"| {100 * cap:.0f} % |")
    lines += ["", "'bound' = Walter's per-node rule (L̄_C ≤ 2 % of the point's estimate); "
              "'literal' = the Ercuts text |L̄ − L| < 2 % L per node (not a true bound); "
              "'total' = Σ_C L̄_C ≤ 2 %/(1 + 2 %) of the estimate (guaranteed ≤ 2 % error "
              "unless the cap binds, which it does here for every point). 'greedy' pairs "
              "every cluster per level (the paper's literal pairing), 'ploc' carries "
              "unpaired clusters up."]
    return "\n".join(lines) + "\n"


def plot(rows: list[Row], path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = np.array([r.n for r in rows], float)
    fig, ax = plt.subplots(1, 3, figsize=(14, 4.2))
    ax[0].loglog(n, [r.cut_ms_per_pt for r in rows], "o-", label="lightcut")
    ax[0].loglog(n, [r.brute_ms_per_pt for r in rows], "s--", label="brute force")
    ax[0].set(xlabel="number of VPLs N", ylabel="ms per shading point", title="shading time")
    ax[1].loglog(n, [r.cut_mean for r in rows], "o-", label="mean cut size")
    ax[1].loglog(n, [r.rays_per_pt for r in rows], "^-", label="shadow rays / point")
    ax[1].loglog(n, n, ":", color="gray", label="N (brute force)")
    ax[1].set(xlabel="number of VPLs N", ylabel="nodes / rays per point", title="cut size")
    ax[2].loglog(n, [r.build_s for r in rows], "o-", label="tree build")
    ref = rows[-1].build_s * (n * np.log2(n)) / (n[-1] * np.log2(n[-1]))
    ax[2].loglog(n, ref, ":", color="gray", label="∝ N log N")
    ax[2].set(xlabel="number of VPLs N", ylabel="seconds", title="light tree build")
    for a in ax:
        a.grid(True, which="both", alpha=0.3)
        a.legend()
    fig.suptitle("Ercuts light tree + lightcuts (2 % rule, max cut 1000), box room")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def kernel_table(sizes: list[int], pts: ShadingPoints, repeats: int = 3) -> str:
    """Gather ms per point, numba vs numpy (interleaved, best CPU time of ``repeats``)."""
    lines = ["# Gather kernels: numba against numpy", "",
             f"Box room of `bench_lightcuts.py`, {pts.count} floor points; ms of CPU per shading "
             "point, best of interleaved runs (shared 2-core machine, load "
             f"{os.getloadavg()[0]:.1f}); the two paths give the same cuts and radiance "
             "(tests/test_kernels.py). Generated by `benchmarks/bench_lightcuts.py --kernels`.", "",
             "| N VPLs | gather | cut mean | numpy ms/pt | numba ms/pt | speed-up |",
             "|---:|---|---:|---:|---:|---:|"]
    for n in sizes:
        pos, nrm, inten = room_vpls(n, seed=n)
        tree = build_light_tree(pos, nrm, inten, seed=1)
        cases = [(f"lightcut '{m}'", lambda m=m: lightcut(tree, pos, nrm, inten, pts, error_mode=m))
                 for m in ("bound", "total")]
        cases += [(f"stochastic, cut {c}", lambda c=c: stochastic_lightcut(
            tree, pos, nrm, inten, pts, np.random.default_rng(0), cut_size=c)) for c in (8, 32, 128)]
        for label, fn in cases:
            best = {"numba": np.inf, "numpy": np.inf}
            for _ in range(repeats):
                for b in best:
                    with kernels.backend(b):
                        res, sec = best_of(1, fn)
                    best[b] = min(best[b], sec)
            lines.append(f"| {n:,} | {label} | {res.cut_size.mean():.1f} | "
                         f"{1e3 * best['numpy'] / pts.count:.3f} | {1e3 * best['numba'] / pts.count:.3f} | "
                         f"{best['numpy'] / best['numba']:.1f}× |")
            print(lines[-1], flush=True)
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes only (smoke test)")
    ap.add_argument("--points", type=int, default=1024)
    ap.add_argument("--brute-points", type=int, default=128)
    ap.add_argument("--kernels", action="store_true", help="numba vs numpy gather table only")
    args = ap.parse_args()
    sizes = [1000, 3000, 10000] if args.quick else [1000, 3000, 10000, 30000, 100000]
    pts = floor_points(args.points, seed=0)
    if args.kernels:
        with kernels.backend("numba"):
            kernel_table([1000], subset(pts, 64), repeats=1)     # JIT warm-up
        md = kernel_table(sizes[:4], pts)
        os.makedirs(OUT, exist_ok=True)
        with open(os.path.join(OUT, "gather_kernels.md"), "w") as f:
            f.write(md)
        return
    run_one(sizes[0], pts, 8, repeats=1)                # warm-up (caches, first calls)
    rows = []
    for n in sizes:
        t0 = time.perf_counter()
        rows.append(run_one(n, pts, args.brute_points))
        took = time.perf_counter() - t0
        print(rows[-1], f"({took:.1f} s)", flush=True)
    r = rows[-1]                                        # 3·10⁵ only if it fits in 2 min
    single = r.build_s + 1e-3 * (r.cut_ms_per_pt * args.points + r.brute_ms_per_pt
                                 * args.brute_points)
    if not args.quick and 3.5 * single < 120.0:
        rows.append(run_one(300000, pts, args.brute_points))
        print(rows[-1], flush=True)
    n_var = 10000
    var = variants(n_var, pts, args.brute_points)
    os.makedirs(OUT, exist_ok=True)
    md = write_table(rows, var, n_var, args.points, args.brute_points)
    with open(os.path.join(OUT, "lightcuts_scaling.md"), "w") as f:
        f.write(md)
    plot(rows, os.path.join(OUT, "lightcuts_scaling.png"))
    print(md)


if __name__ == "__main__":
    main()
