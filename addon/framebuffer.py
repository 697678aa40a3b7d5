"""The core's image → Blender's RenderResult.

Conventions (shared docs ``blender.md`` §0.2–0.3, verified on 3.4.1 and 5.0.1):

* the core returns the rendered window top row first, with its origin
  ``window=(x0, y0, w, h)`` in full-frame pixels, y from the top;
* Blender's pass buffers are bottom row first, and cover only the border window when
  ``render.use_border`` is on: origin (⌊min_x·W⌋, ⌊min_y·H⌋) from the bottom-left,
  size ``result.resolution_x × resolution_y``;
* ``rect.foreach_set`` wants a flat array from 4.1 on and (N, C) before
  (``compat.rect_set``).
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from . import compat


def blender_window(render, width: int, height: int) -> tuple[int, int]:
    """Bottom-left origin (x0, y0), y from the bottom, of Blender's result buffer."""
    if not render.use_border:
        return 0, 0
    return int(render.border_min_x * width), int(render.border_min_y * height)


def place(image: np.ndarray, window, full_height: int,
          target_origin: tuple[int, int], target_size: tuple[int, int]) -> np.ndarray:
    """Paste a top-row-first window image into a bottom-row-first target buffer.

    Args:
        image: (h, w, C) top row first.
        window: (x0, y0, w, h) of ``image`` in full-frame pixels, y from the top.
        full_height: full-frame height H.
        target_origin: (x0, y0) of the target buffer, y from the bottom.
        target_size: (width, height) of the target buffer.
    Returns:
        (target_height, target_width, C) float32, row 0 = bottom; uncovered pixels are 0.
    """
    x0, y0_top, w, h = (int(v) for v in window)
    tw, th = target_size
    out = np.zeros((th, tw, image.shape[2]), np.float32)
    bottom_up = image[::-1]
    y0 = full_height - y0_top - h  # window origin measured from the bottom
    dx, dy = x0 - target_origin[0], y0 - target_origin[1]
    sx0, sy0 = max(0, -dx), max(0, -dy)
    tx0, ty0 = max(0, dx), max(0, dy)
    cw = min(w - sx0, tw - tx0)
    ch = min(h - sy0, th - ty0)
    if cw > 0 and ch > 0:
        out[ty0:ty0 + ch, tx0:tx0 + cw] = bottom_up[sy0:sy0 + ch, sx0:sx0 + cw]
    return out


def write_image(engine, render, image, window, layer_name: str,
                pass_name: str = "Combined") -> None:
    """Write ``image`` (core convention) into a fresh RenderResult and close it.

    ``image`` is one (h, w, C) array for ``pass_name``, or a mapping pass name → array
    to fill several passes of the same result (passes the result lacks are skipped).
    ``engine.begin_result`` is clipped by Blender to the border window; the pixels are
    placed at their full-frame position inside it.
    """
    images = image if isinstance(image, Mapping) else {pass_name: image}
    width, height = engine.resolution_x, engine.resolution_y
    result = engine.begin_result(0, 0, width, height, layer=layer_name)
    try:
        _fill(result, render, images, window, (width, height))
    finally:
        engine.end_result(result)


def show_preview(engine, render, image, window, layer_name: str) -> None:
    """Progressive display: write ``image`` into Combined and ``update_result`` it.

    Used while the core renders (its ``preview`` callback); the final
    :func:`write_image` overwrites it. Closing the result merges it into the frame, so
    a cancelled render keeps at least this image.
    """
    width, height = engine.resolution_x, engine.resolution_y
    result = engine.begin_result(0, 0, width, height, layer=layer_name)
    try:
        _fill(result, render, {"Combined": image}, window, (width, height))
        engine.update_result(result)
    finally:
        engine.end_result(result)


def _find_pass(layer, name: str):
    for render_pass in layer.passes:
        if render_pass.name == name:
            return render_pass
    return None


def _fill(result, render, images: Mapping, window, full_size) -> None:
    """Place every image of ``images`` (name → (h, w, C) top row first) into ``result``."""
    width, height = full_size
    target_size = (result.resolution_x, result.resolution_y)
    origin = blender_window(render, width, height)
    layer = result.layers[0]
    for name, data in images.items():
        render_pass = _find_pass(layer, name)
        if render_pass is None:
            if name != "Combined":
                continue
            render_pass = layer.passes[0]
        data = np.asarray(data, np.float32)
        if data.ndim == 2:
            data = data[..., None]
        pixels = place(data, window, height, origin, target_size)
        channels = render_pass.channels
        if pixels.shape[2] < channels:  # pad RGB → RGBA with alpha 1
            pad = np.ones(pixels.shape[:2] + (channels - pixels.shape[2],), np.float32)
            pixels = np.concatenate([pixels, pad], axis=2)
        compat.rect_set(render_pass, pixels[..., :channels].reshape(-1, channels))
