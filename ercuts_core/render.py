"""The render driver: validate → build → integrate → RenderResult.

PATH and BDPT run the pass loop of :mod:`ercuts_core.integrators.base` (one sample for
every pixel per pass, in batches, so that the time limit and the cancel callback are
honoured at least once per batch; a pass cut short is discarded so that every pixel keeps
the same sample count); ERCUTS runs its phases (:mod:`ercuts_core.integrators.ercuts`). The
time limit covers the whole call: validation, building the acceleration structure and
rendering. Progress and preview callbacks: :mod:`ercuts_core.integrators.base`.
"""
from __future__ import annotations

import time

import numpy as np

from .description import SceneDescription
from .film import Film
from .integrators.base import PREVIEW_INTERVAL, Clock, Integrator, Preview, Progress, batch_pixels, run_passes
from .integrators.bdpt import BDPTIntegrator
from .integrators.ercuts import ErcutsIntegrator
from .integrators.path import PathIntegrator
from .memory import MemoryPlan, plan_for
from .result import RenderResult
from .scene import BuiltScene
from .settings import RenderSettings
from .validate import sanitize

__all__ = ["render", "render_film", "make_integrator", "PREVIEW_INTERVAL", "Progress", "Preview"]


def make_integrator(scene: BuiltScene, settings: RenderSettings) -> Integrator:
    """The pass integrator named by ``settings.integrator`` (PATH or BDPT)."""
    if settings.integrator == "PATH":
        return PathIntegrator(scene, settings)
    return BDPTIntegrator(scene, settings)


def render(desc: SceneDescription, settings: RenderSettings | None = None,
           progress: Progress | None = None, preview: Preview | None = None) -> RenderResult:
    """Render ``desc`` with ``settings``.

    Args:
        desc: the scene description (validated here; see :mod:`ercuts_core.validate`).
        settings: render settings (defaults if None).
        progress: optional ``progress(fraction, message) -> bool | None``; returning False
            cancels the render and the image rendered so far is returned.
        preview: optional ``preview(image)`` called with the image so far (module docstring);
            exceptions raised by it propagate.
    Returns:
        :class:`RenderResult` (image of the rendered window, top row first).
    Raises:
        SceneError: when the scene cannot be rendered (no camera, empty resolution, ...).
    """
    return render_film(desc, settings, progress, preview)[1]


def render_film(desc: SceneDescription, settings: RenderSettings | None = None,
                progress: Progress | None = None,
                preview: Preview | None = None) -> tuple[Film, RenderResult]:
    """:func:`render`, also returning its :class:`~ercuts_core.film.Film`: the float64 sums that
    :meth:`Film.merge <ercuts_core.film.Film.merge>` adds, so that renders of separate iteration
    ranges of one frame (``iteration_start``, ``iterations``) merge into the image that one
    render of all of them gives (:mod:`ercuts_core.cluster`)."""
    settings = settings or RenderSettings()
    clock = Clock(settings.time_limit, progress, preview)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    checked = sanitize(desc)
    timings["validate"] = time.perf_counter() - t0
    clean = checked.desc
    memory = plan_for(clean, settings)      # raises MemoryBudgetError before allocating
    t0 = time.perf_counter()
    scene = BuiltScene(clean, threads=settings.threads)
    timings["build"] = time.perf_counter() - t0
    window = scene.camera.window
    film = Film(window)
    stats: dict[str, float] = dict(checked.stats)
    stats["memory_estimate_mb"] = memory.total / (1 << 20)
    try:
        if scene.lights.empty:
            film.passes_done = settings.samples
            _black_pass(film, scene, settings)
        elif settings.integrator == "ERCUTS":
            t0 = time.perf_counter()
            ErcutsIntegrator(scene, settings, memory).render(film, clock, timings, stats)
            timings["render"] = time.perf_counter() - t0
        else:
            _integrate(scene, settings, memory, film, clock, timings)
    finally:
        stats["rays"] = scene.tracer.rays_traced
        scene.close()
    stats["samples"] = film.passes_done
    stats["nonfinite_samples"] = film.nonfinite
    timings["total"] = time.perf_counter() - clock.start
    return film, RenderResult(
        image=film.image(),
        window=window.rect,
        full_size=(scene.camera.width, scene.camera.height),
        timings=timings, stats=stats, issues=checked.issues,
        cancelled=clock.cancelled, aovs=film.aovs(),
        stopped_by=clock.stop_reason(),
    )


def _black_pass(film: Film, scene: BuiltScene, settings: RenderSettings) -> None:
    """No lights: a black image with correct alpha (coverage) and no light transport."""
    n = film.window.n_pixels
    if settings.film_transparent:
        # Coverage still needs primary rays; one pass suffices for the alpha.
        integ = Integrator(scene, settings)
        pix = np.arange(n)
        o, d = integ.camera_rays(pix, np.random.default_rng(settings.seed))
        film.alpha[:] = scene.intersect(o, d).valid * float(film.passes_done)
    else:
        film.alpha[:] = float(film.passes_done)


def _integrate(scene: BuiltScene, settings: RenderSettings, memory: MemoryPlan, film: Film, clock: Clock,
               timings: dict[str, float]) -> None:
    """Run passes until ``samples`` are done or the user cancels (or the time limit)."""
    t0 = time.perf_counter()
    run_passes(make_integrator(scene, settings), film, clock, samples=settings.samples,
               batch=batch_pixels(memory, settings),
               phase=settings.integrator)
    timings["render"] = time.perf_counter() - t0
