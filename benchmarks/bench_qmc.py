"""Randomised Sobol passes (ercuts_core.qmc) against independent pseudo-random passes: PATH at
equal sample counts on the report's scenes, relMSE against the report's references
(Cycles, 63 bounces, no clamp), and seconds per pass.

    .venv/bin/python benchmarks/bench_qmc.py            # 160×120, 16 and 64 spp, 3 seeds, ≈ 8 min
    .venv/bin/python benchmarks/bench_qmc.py --ercuts 60 --seeds 3 --scenes directly_lit cornell_box

Writes benchmarks/results/qmc.md. With ``--ercuts BUDGET`` it renders ERCUTS (defaults, that
time limit) and Cycles (matched settings, the report's ``cycles_runner``, its samples per
second calibrated once per scene) alternately per seed instead, so both run at the machine's
speed of the moment, writing benchmarks/results/qmc_ercuts_<budget>s.md. Not asserted by any test (tests/test_qmc.py tests
the numbers themselves).
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [ROOT, os.path.join(ROOT, "benchmarks")]

import metrics  # noqa: E402
import report  # noqa: E402
from ercuts_core import RenderSettings, qmc, render  # noqa: E402

SCENES = ("directly_lit", "cornell_box", "s_corridor", "door_ajar", "veach_room")
OUT = os.path.join(ROOT, "benchmarks", "results", "qmc.md")


def run(scene: str, samples: int, seed: int, quasi: bool, w: int, h: int) -> tuple[float, float]:
    """(relMSE, seconds per pass) of one PATH render."""
    qmc.ENABLED = quasi
    try:
        desc = report.scene_description(scene, w, h)
        t0 = time.perf_counter()
        r = render(desc, RenderSettings(integrator="PATH", samples=samples, seed=seed))
        seconds = (time.perf_counter() - t0) / samples
    finally:
        qmc.ENABLED = True
    ref = report.load_reference(scene, w, h)
    return metrics.relmse(r.image[..., :3].astype(np.float64), ref["image"]), seconds


def _add_row(lines: list[str], row: str) -> None:
    print(row, flush=True)
    lines.append(row)


def _write(path: str, lines: list[str]) -> None:
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print("wrote", path)


def ercuts_table(args) -> None:
    """ERCUTS at its defaults and ``--ercuts`` seconds against Cycles at the same budget."""
    import cycles_runner

    w, h = args.size
    b = float(args.ercuts)
    out = os.path.join(ROOT, "benchmarks", "results", f"qmc_ercuts_{b:g}s.md")
    lines = [f"# ERCUTS at {b:g} s with the Sobol passes, against the report's Cycles cells", "",
             f"`benchmarks/bench_qmc.py --ercuts {b:g}`, {w}×{h}, ERCUTS at its defaults, seeds 0–{args.seeds - 1}; "
             "Cycles at matched settings for the same budget, the engines alternating per seed; relMSE "
             "against the report's references, floor-corrected as in the report; medians.", "",
             "| scene | ERCUTS relMSE (seeds) | median | energy | iterations | Cycles relMSE (spp) | ERCUTS / Cycles |",
             "|---|---|---|---|---|---|---|"]
    for scene in args.scenes:
        ref = report.load_reference(scene, w, h)
        if ref is None:
            print(f"{scene}: no reference at {w}×{h}, skipped")
            continue
        rate = cycles_runner.calibrate(scene, w, h, samples=128)
        errs, energies, its, cyc, spp = [], [], [], [], []
        for seed in range(args.seeds):
            img, rec = report.render_ercuts(scene, "ERCUTS", b, seed, w, h)
            img = img.astype(np.float64)
            errs.append(metrics.relmse(img, ref["image"]) - ref["floor"]["relmse"])
            energies.append(metrics.energy_ratio(img, ref["image"]))
            its.append(rec["stats"].get("iterations", 1))
            c = cycles_runner.render_cycles(scene, b, seed, w, h, rate)
            cyc.append(metrics.relmse(c["image"][..., :3].astype(np.float64), ref["image"]) - ref["floor"]["relmse"])
            spp.append(c["samples"])
        e, c = float(np.median(errs)), float(np.median(cyc))
        row = (f"| {scene} | {' / '.join(f'{x:.3g}' for x in errs)} | {e:.3g} | {np.median(energies):.3f} "
               f"| {'/'.join(str(i) for i in its)} | {' / '.join(f'{x:.3g}' for x in cyc)} "
               f"({'/'.join(str(int(x)) for x in spp)}) | {e / c:.3g} |")
        _add_row(lines, row)
    _write(out, lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, nargs=2, default=(160, 120))
    ap.add_argument("--samples", type=int, nargs="+", default=[16, 64])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--scenes", nargs="+", default=list(SCENES))
    ap.add_argument("--ercuts", type=float, default=0.0, help="render ERCUTS at this budget instead")
    args = ap.parse_args()
    if args.ercuts:
        report.warm_up(["ERCUTS", "CYCLES"], *args.size)
        return ercuts_table(args)
    w, h = args.size
    lines = ["# Randomised Sobol passes vs independent passes (PATH, equal samples)", "",
             f"`benchmarks/bench_qmc.py`, {w}×{h}, {args.seeds} seeds (medians), relMSE against the "
             "report's references; s/pass is the median seconds per pass (2 cores).", "",
             "| scene | spp | relMSE random | relMSE Sobol | ratio | s/pass random | s/pass Sobol |",
             "|---|---|---|---|---|---|---|"]
    for scene in args.scenes:
        if report.load_reference(scene, w, h) is None:
            print(f"{scene}: no reference at {w}×{h}, skipped")
            continue
        for n in args.samples:
            res = {q: [run(scene, n, seed, q, w, h) for seed in range(args.seeds)] for q in (False, True)}
            e = {q: float(np.median([r[0] for r in res[q]])) for q in res}
            t = {q: float(np.median([r[1] for r in res[q]])) for q in res}
            row = (f"| {scene} | {n} | {e[False]:.3g} | {e[True]:.3g} | {e[True] / e[False]:.2f} "
                   f"| {t[False]:.3f} | {t[True]:.3f} |")
            _add_row(lines, row)
    _write(OUT, lines)


if __name__ == "__main__":
    main()
