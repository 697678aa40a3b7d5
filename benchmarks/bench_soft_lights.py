"""Cost of soft lights and depth of field: PATH and BDPT on the point-lit box with radius 0,
radius 0.15 m (sphere and soft-falloff disk) and through a thin lens, interleaved repeats.

    .venv/bin/python benchmarks/bench_soft_lights.py            # 64×48, 16 spp, 3 repeats

Prints the fastest of the repeats per case (seconds). Not asserted by any test.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [ROOT, os.path.join(ROOT, "tests")]

from ercuts_core import RenderSettings, render  # noqa: E402
from ercuts_core.scenes import point_lit_box  # noqa: E402
from test_soft_lights import soft_box  # noqa: E402


def cases(w: int, h: int) -> dict:
    def lens():
        d = point_lit_box(w, h)
        return d.replace(camera=dataclasses.replace(d.camera, aperture_radius=0.05, focus_distance=1.0))
    return {"radius 0": lambda: point_lit_box(w, h), "sphere r=0.15": lambda: soft_box(True, w, h),
            "disk r=0.15": lambda: soft_box(False, w, h), "thin lens": lens}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, nargs=2, default=(64, 48))
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    table = cases(*args.size)
    for integrator in ("PATH", "BDPT"):
        best = {k: float("inf") for k in table}
        for rep in range(args.repeats):
            for name, make in table.items():
                desc = make()
                t0 = time.perf_counter()
                render(desc, RenderSettings(integrator=integrator, samples=args.samples, seed=rep))
                best[name] = min(best[name], time.perf_counter() - t0)
        print(integrator, "  ".join(f"{k}: {v:.2f} s" for k, v in best.items()))


if __name__ == "__main__":
    main()
