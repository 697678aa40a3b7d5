"""Compile the gather's numba kernels (:mod:`ercuts_core.kernels`) in the background.

The first render on a machine compiles them (11–21 s measured, ``benchmarks/results/
jit_warmup.md``; later processes load numba's on-disk cache in 0.3 s). Done inside the gather
that would freeze the render — no progress, Esc not noticed — for that long, so the Ercuts
integrator starts :func:`start` when a render begins, the compilation overlaps the phases
before the gather, and the gather :func:`wait`\\ s for it while still reporting progress and
noticing a cancel. Once per process; nothing happens on the numpy fallback.
"""
from __future__ import annotations

import threading
from typing import Callable

import numpy as np

from ... import kernels

_thread: threading.Thread | None = None


def _compile() -> None:
    """Call every kernel once on a tiny case (200 VPLs over 64 points, half of them rough
    glass for :func:`ercuts_core.kernels.bounds.glass_bounds`): numba compiles them."""
    from ...bsdf import Bsdf
    from .light_tree import build_light_tree
    from .lightcuts import GlossyReceivers, ShadingPoints, lightcut
    from .stochastic_lightcuts import stochastic_lightcut

    rng = np.random.default_rng(0)
    pos = np.column_stack([rng.random((200, 2)) * 4, np.full(200, 3.0)])
    nrm = np.tile([0.0, 0.0, -1.0], (200, 1))
    inten = rng.random((200, 3))
    tree = build_light_tree(pos, nrm, inten, 0)
    x = np.column_stack([rng.random((64, 2)) * 4, np.zeros(64)])
    up = np.tile([0.0, 0.0, 1.0], (64, 1))
    f = np.full((64, 3), 0.5 / np.pi)
    pts = ShadingPoints(x, up, up.copy(), f, lambda i, wi: f[i], lambda i, q, qn: np.ones(len(i), bool))
    for mode in ("total", "bound", "literal"):
        lightcut(tree, pos, nrm, inten, pts, error_mode=mode)
    stochastic_lightcut(tree, pos, nrm, inten, pts, np.random.default_rng(1), cut_size=8)
    glass = Bsdf.from_params(np.full((64, 3), 0.8), 0.3, 0.0, 0.5, up, up,
                             transmission=np.arange(64) % 2, ior=1.5)
    wo = np.tile([0.6, 0.0, 0.8], (64, 1))
    lightcut(tree, pos, nrm, inten, ShadingPoints(x, up, wo, f, lambda i, wi: glass.subset(i).eval(wo[i], wi),
                                                  pts.visible, transmissive=np.arange(64) % 2 == 1,
                                                  glossy=GlossyReceivers.from_bsdf(glass, wo, up)))


def start() -> None:
    """Start compiling the kernels in a daemon thread (first call of a process, numba only)."""
    global _thread
    if _thread is None and kernels.enabled():
        _thread = threading.Thread(target=_compile, name="ercuts-kernel-warm-up", daemon=True)
        _thread.start()


def wait(poll: Callable[[], bool], interval: float = 0.2) -> bool:
    """Wait for :func:`start`'s compilation, calling ``poll()`` every ``interval`` s; False as
    soon as ``poll`` returns False (cancelled: the compilation goes on in the background)."""
    while _thread is not None and _thread.is_alive():
        _thread.join(interval)
        if not poll():
            return False
    return True
