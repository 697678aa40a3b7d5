"""Regenerate the converged references the statistical tests compare against.

    .venv/bin/python tests/make_references.py

Each reference is the mean of K independent path-traced renders together with the
per-pixel variance of that mean (so tests can state how converged it is), rendered by the
simple reference integrator (PATH), as style-and-testing.md §2.8 recommends.
"""
from __future__ import annotations

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from ercuts_core import RenderSettings, render  # noqa: E402
from ercuts_core.scenes import closed_room  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))


def make(name: str, desc, k: int, spp: int) -> None:
    imgs = np.stack([render(desc, RenderSettings(integrator="PATH", samples=spp, seed=1000 + i,
                                                 max_depth=8)).image for i in range(k)])
    mean = imgs.mean(axis=0)
    var = imgs.var(axis=0, ddof=1) / k
    path = os.path.join(HERE, "data", f"{name}.npz")
    np.savez_compressed(path, mean=mean.astype(np.float32), var=var.astype(np.float32),
                        spp=k * spp)
    print(f"wrote {path}: mean {mean[..., :3].mean():.4f}, rel. std of mean "
          f"{np.sqrt(var[..., :3]).mean() / mean[..., :3].mean():.4f}")


if __name__ == "__main__":
    make("closed_room_48x36_path_2048spp", closed_room(48, 36), 16, 128)
