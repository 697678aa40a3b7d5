"""Bias and variance of the resolution sweep's errors, from its seeds (issue 17's misses).

    .venv/bin/python benchmarks/error_split.py [--scenes door_ajar] [--engines ERCUTS]

For every (scene, engine, size) of ``results/resolution_runs/`` with n ≥ 2 seeds: the mean
single-seed relMSE E₁ and the relMSE E_n of the seeds' mean image (both floor-corrected as in
:mod:`bench_resolution`). With independent seeds E₁ = B + V and E_n = B + V/n, so the
variance part is V = (E₁ − E_n)·n/(n − 1) and the rest, B = E₁ − V, is error that more seeds
of the same render do not remove (bias: clamping, interpolation, the normalisation) plus any
error of the floor estimate, which is subtracted from both: the reference's own relMSE, as
large as the errors measured here at 160 wide (door: 0.0061), so B is only as good as that
estimate. The same split of the 4×4-block blurred images gives the low-frequency part; it is
not floor-corrected, and the reference's noise, if white, adds ≈ floor/16 to its B. Writes ``results/error_split.md`` and, per split, a map of
Y(mean of the seeds) / Y(reference) (``error_split_<scene>_<engine>_<w>x<h>.png``).
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [os.path.dirname(HERE), HERE]

import metrics  # noqa: E402
from bench_resolution import RESULTS, box_filter, load_runs, reference, reference_size  # noqa: E402
from ercuts_core.sampling import luminance  # noqa: E402

#: Block size of the low-frequency part (4×4 blocks of the 160-wide comparison image).
BLOCK = 4


def blur(img: np.ndarray, k: int = BLOCK) -> np.ndarray:
    """(H/k, W/k, 3) means of k×k blocks of an (H, W, 3) image (edges cropped)."""
    h, w = img.shape[0] // k, img.shape[1] // k
    return box_filter(img[:h * k, :w * k, :3], w, h)


def split(images: list[np.ndarray], ref: np.ndarray, floor: float) -> dict:
    """Bias/variance split (module docstring) of n ≥ 2 seeds' ``images`` against ``ref``."""
    n = len(images)
    mean = np.mean(images, axis=0)
    out = {"seeds": n}
    for part, f, fl in (("", lambda x: x, floor), ("blurred_", blur, 0.0)):
        e1 = float(np.mean([metrics.relmse(f(im), f(ref)) for im in images])) - fl
        en = metrics.relmse(f(mean), f(ref)) - fl
        var = (e1 - en) * n / (n - 1)
        out.update({f"{part}single": e1, f"{part}mean": en, f"{part}variance": var, f"{part}bias": e1 - var})
    return out


def ratio_map(images: list[np.ndarray], ref: np.ndarray, path: str, title: str) -> None:
    """Y(mean of ``images``) / Y(``ref``), 0.7–1.3, to ``path``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = luminance(np.mean(images, axis=0)[..., :3]) / np.maximum(luminance(ref[..., :3]), 1e-9)
    fig, ax = plt.subplots(figsize=(6, 4))
    im = ax.imshow(r, cmap="RdBu_r", vmin=0.7, vmax=1.3)
    fig.colorbar(im, ax=ax)
    ax.set_title(title, fontsize=9)
    fig.savefig(path, dpi=80, bbox_inches="tight")
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+")
    ap.add_argument("--engines", nargs="+", default=["ERCUTS"])
    args = ap.parse_args(argv)
    groups: dict = {}
    for r in load_runs():
        if "image" in r and r["engine"] in args.engines and (not args.scenes or r["scene"] in args.scenes):
            groups.setdefault((r["scene"], r["engine"], r["width"], r["height"]), []).append(r)
    rows = ["| scene | engine | size | seeds | relMSE, one seed | of the seeds' mean | variance | bias "
            "| blurred: one seed | bias | reference floor |", "|" + "---|" * 11]
    for (scene, engine, w, h), rs in sorted(groups.items()):
        ref = reference(scene, *reference_size(w, h))
        if len(rs) < 2 or ref is None:
            continue
        images = [r["image"] for r in rs]
        s = split(images, ref["image"], ref["floor"])
        rows.append(f"| {scene} | {engine} | {w}×{h} | {s['seeds']} | {s['single']:.5f} | {s['mean']:.5f} "
                    f"| {s['variance']:.5f} | {s['bias']:.5f} | {s['blurred_single']:.5f} | {s['blurred_bias']:.5f} "
                    f"| {ref['floor']:.5f} |")
        ratio_map(images, ref["image"], os.path.join(RESULTS, f"error_split_{scene}_{engine}_{w}x{h}.png"),
                  f"{scene} {engine} {w}x{h}: mean of {len(rs)} seeds / reference")
    text = "# Bias and variance of the resolution sweep's errors\n\n" + (__doc__.split("\n\n", 2)[2]) + "\n" + \
        "\n".join(rows) + "\n"
    with open(os.path.join(RESULTS, "error_split.md"), "w") as fh:
        fh.write(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
