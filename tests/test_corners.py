"""Room corners: the built-in Cornell box's walls share their edges with the floor and the
ceiling, and its camera looks straight down the box, so the pixel centres of a 1-pixel
diagonal staircase project exactly onto the corner edges. ERCUTS gathers VPL light at
jittered camera rays in every pixel (``shading_samples``); those points must see the room
(the tracer's offsets, :mod:`ercuts_core.tracer`; ``tests/test_tracer.py`` has the
geometric test)."""
from __future__ import annotations

import numpy as np

from ercuts_core import RenderSettings, render
from ercuts_core.scenes import cornell_box

TINY = dict(integrator="ERCUTS", rough_samples=1, chain_length=10, direct_samples=1, e1_samples=16, threads=1)


def test_cornell_box_corner_pixels_get_indirect_light():
    """Every pixel that sees the box gets VPL (indirect) light; before the fix the 13 pixels
    whose centres lie on the ceiling's and the floor's corner edges got none (at 160 × 120,
    29 pixels at ~0.0003 against ~0.02–0.08 around them)."""
    w, h = 40, 30
    result = render(cornell_box(w, h), RenderSettings(seed=0, **TINY))
    indirect = result.aovs["indirect"].sum(axis=-1)
    inside = result.aovs["depth"][..., 0] < 1e9
    assert inside.sum() > 400
    dark = np.argwhere(inside & (indirect <= 0))
    assert len(dark) == 0, f"pixels without indirect light (row, col): {dark.tolist()}"
