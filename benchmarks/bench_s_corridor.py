"""The paper's Fig. 5 claim, measured: ERCUTS vs BDPT vs PATH at equal wall time on the S-corridor.

    .venv/bin/python benchmarks/bench_s_corridor.py                 # 60 s budgets, 3 seeds
    .venv/bin/python benchmarks/bench_s_corridor.py --budget 30 --seeds 2 --width 80 --height 60

The reference is BDPT rendered for a long time (the mean of several independent runs, cached
in ``benchmarks/results/s_corridor_ref_<W>x<H>.npz`` with its per-pixel variance, so its own
contribution to the error is known and reported). Each integrator gets the same wall-clock
``time_limit`` (the whole render call). Errors: relMSE = mean((x − r)² / (r² + 0.01)),
and the image energy relative to the reference. Writes ``s_corridor.md``/``.png``/``.json``
to ``benchmarks/results/``.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from benchmarks.metrics import relmse  # noqa: E402
from ercuts_core import RenderSettings, render  # noqa: E402
from ercuts_core.image_io import linear_to_srgb  # noqa: E402
from ercuts_core.sampling import luminance  # noqa: E402
from ercuts_core.scenes import s_corridor  # noqa: E402

OUT = os.path.join(ROOT, "benchmarks", "results")


def reference(w: int, h: int, runs: int, spp: int) -> tuple[np.ndarray, np.ndarray]:
    path = os.path.join(OUT, f"s_corridor_ref_{w}x{h}.npz")
    if os.path.exists(path):
        z = np.load(path)
        return z["mean"], z["var"]
    imgs = []
    for i in range(runs):
        t0 = time.perf_counter()
        imgs.append(render(s_corridor(w, h), RenderSettings(integrator="BDPT", samples=spp,
                                                           seed=5000 + i)).image[..., :3])
        print(f"reference run {i + 1}/{runs}: {time.perf_counter() - t0:.0f} s", flush=True)
    imgs = np.stack(imgs)
    mean, var = imgs.mean(0), imgs.var(0, ddof=1) / runs
    np.savez_compressed(path, mean=mean, var=var, spp=runs * spp)
    return mean, var


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=float, default=60.0, help="seconds per render")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--width", type=int, default=160)
    ap.add_argument("--height", type=int, default=120)
    ap.add_argument("--ref-runs", type=int, default=8)
    ap.add_argument("--ref-spp", type=int, default=128)
    args = ap.parse_args()
    os.makedirs(OUT, exist_ok=True)
    ref, ref_var = reference(args.width, args.height, args.ref_runs, args.ref_spp)
    ref_floor = float(np.mean(ref_var / (ref**2 + 1e-2)))      # E[relMSE] the reference itself adds
    configs = {
        "ERCUTS": dict(integrator="ERCUTS"),
        "BDPT": dict(integrator="BDPT", samples=100000),
        "PATH": dict(integrator="PATH", samples=100000),
    }
    rows, images = {}, {}
    for name, kw in configs.items():
        errs, energies, times, stats = [], [], [], []
        for seed in range(args.seeds):
            t0 = time.perf_counter()
            r = render(s_corridor(args.width, args.height),
                       RenderSettings(**kw, seed=seed, time_limit=args.budget))
            times.append(time.perf_counter() - t0)
            img = r.image[..., :3]
            errs.append(relmse(img, ref))
            energies.append(float(luminance(img).mean() / luminance(ref).mean()))
            stats.append({k: v for k, v in r.stats.items() if isinstance(v, (int, float))})
            if seed == 0:
                images[name] = img
            print(f"{name} seed {seed}: {times[-1]:.1f} s relMSE {errs[-1]:.4f} energy {energies[-1]:.3f}",
                  flush=True)
        rows[name] = dict(relmse=errs, energy=energies, time=times, stats=stats)
    _write(args, rows, images, ref, ref_floor)
    return 0


def _write(args, rows, images, ref, ref_floor) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    base = os.path.join(OUT, "s_corridor")
    with open(base + ".json", "w") as fh:
        json.dump(dict(args=vars(args), rows=rows, reference_relmse_floor=ref_floor), fh, indent=1)
    lines = [f"# S-corridor, equal wall time ({args.budget:.0f} s, {args.width}×{args.height}, "
             f"{args.seeds} seeds)", "",
             "Reference: BDPT, mean of independent runs; its own expected relMSE contribution is "
             f"{ref_floor:.4f} (included in every number below).", "",
             "| integrator | relMSE median | relMSE min–max | energy / reference | wall time (s) |",
             "|---|---|---|---|---|"]
    for name, r in rows.items():
        e = np.array(r["relmse"])
        lines.append(f"| {name} | {np.median(e):.4f} | {e.min():.4f}–{e.max():.4f} | "
                     f"{np.median(r['energy']):.3f} | {np.median(r['time']):.1f} |")
    er, bd = np.median(rows["ERCUTS"]["relmse"]), np.median(rows["BDPT"]["relmse"])
    lines += ["", f"ERCUTS / BDPT relMSE ratio: **{er / bd:.3f}** (target ≤ 0.5); ERCUTS energy "
              f"{np.median(rows['ERCUTS']['energy']):.3f} of the reference (target within 5 %).", "",
              "![side by side](s_corridor.png)", ""]
    with open(base + ".md", "w") as fh:
        fh.write("\n".join(lines))
    exposure = 0.5 / max(float(np.percentile(ref, 99)), 1e-6)
    names = list(images) + ["reference"]
    pics = list(images.values()) + [ref]
    fig, axes = plt.subplots(1, len(pics), figsize=(3.2 * len(pics), 2.8))
    for ax, name, img in zip(axes, names, pics):
        ax.imshow(linear_to_srgb(img * exposure), interpolation="nearest")
        ax.set_title(name)
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(base + ".png", dpi=110)
    print("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
