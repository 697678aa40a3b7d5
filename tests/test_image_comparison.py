"""The renderer-agreement statistic itself (``stats.compare_images``, used by the Cycles
agreement tests in tests/blender): synthetic "renders" with known means and noise.

* Under the null (same mean) it rejects at about its level — also for skewed noise and for
  noise correlated across pixels (a per-seed factor over 8×8 blocks or over the whole image,
  as one VPL set lights many pixels), which the between-seed inflation absorbs;
* it detects a 3 % bias of the whole image and a 15 % bias of a 16×16 patch at a per-pixel
  noise of 30 % per sample-set, four seeds each (block standard error 1.9 %);
* noise-free blocks (a background) count only when they differ beyond float32 rounding.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import binom

sys.path.insert(0, str(Path(__file__).resolve().parent))
from stats import FLOAT_RTOL, compare_images  # noqa: E402

SHAPE = (48, 64, 3)
MEAN = np.ones(SHAPE) * np.linspace(0.2, 1.0, SHAPE[1])[None, :, None]
TRIALS = 150
#: At most this many of TRIALS null comparisons may reject: the 1 − 10⁻⁴ quantile of the
#: binomial count at the comparison's own level 10⁻³.
MAX_REJECTIONS = int(binom.ppf(1 - 1e-4, TRIALS, 1e-3))


def _renders(rng, mean, S=4, kind="gaussian", block_factor=0.0, image_factor=0.0):
    out = []
    for _ in range(S):
        if kind == "gamma":                        # skewed: shape 2, mean 1, sd 0.71
            x = mean * rng.gamma(2.0, 0.5, size=mean.shape)
        else:
            x = mean * (1.0 + 0.3 * rng.standard_normal(mean.shape))
        if block_factor:
            b = 1.0 + block_factor * rng.standard_normal((SHAPE[0] // 8, SHAPE[1] // 8, 1))
            x = x * np.repeat(np.repeat(b, 8, axis=0), 8, axis=1)
        if image_factor:
            x = x * (1.0 + image_factor * rng.standard_normal())
        out.append(x)
    return out


@pytest.mark.parametrize("noise", [dict(kind="gamma"), dict(block_factor=0.05), dict(image_factor=0.02)],
                         ids=["skewed", "block_correlated", "image_correlated"])
def test_null_rejections_at_the_level(noise):
    rng = np.random.default_rng(3)
    results = [compare_images(_renders(rng, MEAN, **noise), _renders(rng, MEAN)) for _ in range(TRIALS)]
    rejections = sum(not r.passed for r in results)
    mean_z2 = float(np.mean([r.mean_z2 for r in results]))
    assert rejections <= MAX_REJECTIONS, f"{rejections}/{TRIALS} rejections under the null"
    assert 0.8 < mean_z2 < 1.2, mean_z2                  # z is standard normal: E z² = 1


@pytest.mark.parametrize("case", ["global_3pct", "patch_15pct"])
def test_detects_a_bias(case):
    rng = np.random.default_rng(4)
    biased = MEAN * 1.03 if case == "global_3pct" else MEAN.copy()
    if case == "patch_15pct":
        biased[16:32, 16:32] *= 1.15
    misses = sum(compare_images(_renders(rng, biased), _renders(rng, MEAN)).passed for _ in range(20))
    assert misses == 0, f"{misses}/20 biased comparisons passed"


def test_noise_free_blocks():
    rng = np.random.default_rng(5)
    ours, ref = _renders(rng, MEAN), _renders(rng, MEAN)
    for images, value in ((ours, 0.6), (ref, 0.6 * (1.0 - 0.25 * FLOAT_RTOL))):
        for x in images:
            x[:8] = value                              # a noise-free top row of blocks
    result = compare_images(ours, ref)
    assert result.passed and np.all(result.z[0] == 0.0)
    assert result.blocks.tolist() == [40, 40, 40]      # 48 blocks, 8 of them left out
    for x in ref:
        x[:8] = 0.6 * 1.001
    result = compare_images(ours, ref)
    assert not result.passed and np.all(np.isinf(result.z[0]))
