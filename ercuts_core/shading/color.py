"""Colour-space helpers of the shading nodes, after Cycles' ``intern/cycles/util/color.h`` and
``kernel/svm/color_util.h`` (own numpy code, vectorized over (N, 3) rows)."""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

#: Luminance weights of linear Rec.709 (Blender's default OCIO config ``luminance``); the
#: RGB to BW node and implicit colour → float conversions use them.
LUMA = np.array([0.2126, 0.7152, 0.0722])


def rgb_to_gray(c: NDArray) -> NDArray:
    """(N, 3) → (N,) luminance (Cycles ``linear_rgb_to_gray``)."""
    return np.asarray(c, np.float64) @ LUMA


def rgb_to_hsv(rgb: NDArray) -> NDArray:
    """(N, 3) RGB → HSV, each in [0, 1] for RGB in [0, 1] (Cycles ``rgb_to_hsv``).

    v = max, s = (max − min)/max (0 if max = 0), h from the max channel, wrapped to [0, 1).
    """
    r, g, b = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    cmax, cmin = rgb.max(axis=1), rgb.min(axis=1)
    cdelta = cmax - cmin
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(cmax != 0.0, cdelta / np.where(cmax != 0.0, cmax, 1.0), 0.0)
        safe = np.where(cdelta != 0.0, cdelta, 1.0)
        cr, cg, cb = (cmax - r) / safe, (cmax - g) / safe, (cmax - b) / safe
    h = np.where(r == cmax, cb - cg, np.where(g == cmax, 2.0 + cr - cb, 4.0 + cg - cr)) / 6.0
    h = np.where(h < 0.0, h + 1.0, h)
    h = np.where(s != 0.0, h, 0.0)
    return np.stack([h, s, cmax], axis=1)


def hsv_to_rgb(hsv: NDArray) -> NDArray:
    """(N, 3) HSV → RGB (Cycles ``hsv_to_rgb``: the six-sector formula; s = 0 gives grey v)."""
    h, s, v = hsv[:, 0], hsv[:, 1], hsv[:, 2]
    h6 = np.where(h == 1.0, 0.0, h) * 6.0
    i = np.floor(h6)
    f = h6 - i
    p, q, t = v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f))
    i = np.where((i >= 0) & (i <= 4), i, 5).astype(np.int64)     # Cycles' final ``else``
    table = np.stack([np.stack([v, t, p], 1), np.stack([q, v, p], 1), np.stack([p, v, t], 1),
                      np.stack([p, q, v], 1), np.stack([t, p, v], 1), np.stack([v, p, q], 1)], axis=0)
    out = table[i, np.arange(len(h))]
    return np.where((s != 0.0)[:, None], out, v[:, None])


def rgb_to_hsl(rgb: NDArray) -> NDArray:
    """(N, 3) RGB → HSL (Cycles ``rgb_to_hsl``)."""
    cmax, cmin = rgb.max(axis=1), rgb.min(axis=1)
    l_ = np.minimum(1.0, 0.5 * (cmax + cmin))
    d = cmax - cmin
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(d != 0.0, d / np.where(l_ > 0.5, 2.0 - cmax - cmin, cmax + cmin), 0.0)
    s = np.where(np.isfinite(s), s, 0.0)
    h = rgb_to_hsv(rgb)[:, 0]
    return np.stack([np.where(d != 0.0, h, 0.0), s, l_], axis=1)


def hsl_to_rgb(hsl: NDArray) -> NDArray:
    """(N, 3) HSL → RGB (Cycles ``hsl_to_rgb``): c = (1 − |2l − 1|)·s, then the hue ramp."""
    h, s, l_ = hsl[:, 0], hsl[:, 1], hsl[:, 2]
    nr = np.abs(h * 6.0 - 3.0) - 1.0
    ng = 2.0 - np.abs(h * 6.0 - 2.0)
    nb = 2.0 - np.abs(h * 6.0 - 4.0)
    n = np.clip(np.stack([nr, ng, nb], axis=1), 0.0, 1.0)
    chroma = (1.0 - np.abs(2.0 * l_ - 1.0)) * s
    return (n - 0.5) * chroma[:, None] + l_[:, None]
