"""Randomised Sobol passes (ercuts_core.qmc) against independent pseudo-random passes: PATH at
equal sample counts on the report's scenes, relMSE against the report's references
(Cycles, 63 bounces, no clamp), and seconds per pass.

    .venv/bin/python benchmarks/bench_qmc.py            # 160×120, 16 and 64 spp, 3 seeds, ≈ 6 min

Writes benchmarks/results/qmc.md. Not asserted by any test (tests/test_qmc.py tests the
numbers themselves).
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, nargs=2, default=(160, 120))
    ap.add_argument("--samples", type=int, nargs="+", default=[16, 64])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--scenes", nargs="+", default=list(SCENES))
    args = ap.parse_args()
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
            print(row, flush=True)
            lines.append(row)
    with open(OUT, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print("wrote", OUT)


if __name__ == "__main__":
    main()
