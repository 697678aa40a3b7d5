"""The render driver: validate → build → integrate in passes → RenderResult.

One *pass* renders one sample for every pixel of the window, in batches of pixels so
that the time limit and the cancel callback are honoured at least once per batch (a
batch is sized to take well under a second). The time limit covers the whole call:
validation, building the acceleration structure and rendering. A pass that is cut short
is discarded so that every pixel keeps the same sample count.

Progress (api.md): ``progress(fraction, message)`` messages start with the phase name
("PATH", "BDPT", "ER chains", "VPLs", "Light tree", "Lightcuts"), fractions rise
monotonically over the whole render, and every phase reports at least every ~0.25 s of
work. ``preview(image)`` receives the image so far ((h, w, 4) float32, like
``RenderResult.image``) at most once per :data:`PREVIEW_INTERVAL` seconds.
"""
from __future__ import annotations

import time
from typing import Callable

import numpy as np

from .description import SceneDescription
from .film import Film
from .integrators.base import Integrator
from .memory import plan as memory_plan, plan_for
from .result import RenderResult
from .scene import BuiltScene
from .settings import RenderSettings
from .validate import sanitize

Progress = Callable[[float, str], "bool | None"]
Preview = Callable[[np.ndarray], None]

#: Minimum seconds between two preview images.
PREVIEW_INTERVAL = 1.0


def make_integrator(scene: BuiltScene, settings: RenderSettings) -> Integrator:
    """The integrator named by ``settings.integrator``."""
    if settings.integrator == "PATH":
        from .integrators.path import PathIntegrator
        return PathIntegrator(scene, settings)
    from .integrators.bdpt import BDPTIntegrator
    return BDPTIntegrator(scene, settings)


class _Clock:
    """Deadline and cancel bookkeeping shared by all phases."""

    def __init__(self, time_limit: float, progress: Progress | None, preview: Preview | None = None):
        self.start = time.perf_counter()
        self.deadline = self.start + time_limit if time_limit > 0 else None
        self.progress = progress
        self.preview = preview
        self.last_preview = -np.inf
        self.cancelled = False
        #: Why the render stopped early: None, 'time_limit' or 'cancel' (progress returned False).
        self.stopped_by: str | None = None

    def show(self, image: Callable[[], np.ndarray]) -> None:
        """Send ``image()`` to the preview callback unless one was sent less than
        :data:`PREVIEW_INTERVAL` seconds ago (``image`` is only evaluated when sent)."""
        if self.preview is None or time.perf_counter() - self.last_preview < PREVIEW_INTERVAL:
            return
        self.preview(image())
        self.last_preview = time.perf_counter()

    def expired(self) -> bool:
        return self.deadline is not None and time.perf_counter() >= self.deadline

    def report(self, fraction: float, message: str) -> bool:
        """Call the progress callback; returns False (and remembers it) when cancelled."""
        self.poll(fraction, message)
        if self.expired():
            self.cancelled = True
            self.stopped_by = self.stopped_by or "time_limit"
        return not self.cancelled

    def poll(self, fraction: float, message: str) -> bool:
        """Call the progress callback only (the deadline is the caller's business)."""
        if self.progress is not None and self.progress(float(fraction), message) is False:
            self.cancelled, self.stopped_by = True, "cancel"
        return not self.cancelled

    def stop_reason(self) -> str | None:
        """Why the render stopped early (None: it did not): 'cancel' or 'time_limit'; a stop
        flagged without a reason (``cancelled`` set when a phase ran out of time) is the
        time limit once the deadline has passed."""
        if not self.cancelled:
            return None
        return self.stopped_by or ("time_limit" if self.expired() else "cancel")

    def remaining(self) -> float:
        """Seconds left before the deadline (inf without a time limit)."""
        if self.deadline is None:
            return float("inf")
        return self.deadline - time.perf_counter()


def _batch_pixels(n_pixels: int, settings: RenderSettings, n_triangles: int = 0) -> int:
    """Pixels per batch: about ``batch_rays`` rays per bounce for PATH; a quarter of that for
    BDPT, whose batch holds two subpaths and all their connections (a batch then stays well
    under a second, so the time limit and cancellation are honoured promptly); smaller when
    the memory budget asks for it (:func:`ercuts_core.memory.plan`), and at most
    :func:`progress_batch_pixels`."""
    return min(memory_plan(n_pixels, n_triangles, settings).batch_pixels, progress_batch_pixels(settings))


def progress_batch_pixels(settings: RenderSettings) -> int:
    """Largest batch that reports progress every ~0.25 s of work: BDPT batches of
    ``batch_rays``/32 pixels (4096 by default) take ~0.12 s on the S-corridor on 2 cores and
    are no slower per pixel than one batch per pass (measured: 0.49 s per 160×120 pass with
    4096 or 8192, 0.66 s with 19200); a PATH pass of ``batch_rays`` pixels takes ~0.2 s."""
    per = settings.batch_rays if settings.integrator == "PATH" else settings.batch_rays // 32
    return max(1024, per)


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
    settings = settings or RenderSettings()
    clock = _Clock(settings.time_limit, progress, preview)
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
            from .integrators.ercuts import ErcutsIntegrator
            t0 = time.perf_counter()
            ErcutsIntegrator(scene, settings).render(film, clock, timings, stats)
            timings["render"] = time.perf_counter() - t0
        else:
            _integrate(scene, settings, film, clock, timings)
    finally:
        stats["rays"] = scene.tracer.rays_traced
        scene.close()
    stats["samples"] = film.passes_done
    stats["nonfinite_samples"] = film.nonfinite
    timings["total"] = time.perf_counter() - clock.start
    return RenderResult(
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


def _integrate(scene: BuiltScene, settings: RenderSettings, film: Film, clock: _Clock,
               timings: dict[str, float]) -> None:
    """Run passes until ``samples`` are done, the deadline passes or the user cancels.

    Each pass renders into its own film and is merged when complete; a pass cut short is
    kept only when it is the first (so a cancelled render still shows what was done).
    """
    integrator = make_integrator(scene, settings)
    n = film.window.n_pixels
    batch = _batch_pixels(n, settings, scene.desc.mesh.n_triangles)
    t0 = time.perf_counter()
    label = settings.integrator
    for k in range(settings.samples):
        part = Film(film.window)
        for start in range(0, n, batch):
            rng = np.random.default_rng([settings.seed, k, start])
            integrator.render_batch(part, np.arange(start, min(n, start + batch)), rng)
            done = (k + min(n, start + batch) / n) / settings.samples
            if not clock.report(done, f"{label} sample {k + 1}/{settings.samples}"):
                break
        if not clock.cancelled or film.passes_done == 0:
            film.merge(part)
        if clock.cancelled:
            break
        clock.show(film.image)
    timings["render"] = time.perf_counter() - t0
