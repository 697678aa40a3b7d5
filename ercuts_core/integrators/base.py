"""What all integrators share: camera-sample generation, first-hit AOVs, the clock and the
pass loop.

An integrator is constructed with a :class:`~ercuts_core.scene.BuiltScene` and
:class:`~ercuts_core.settings.RenderSettings` and renders one batch of camera samples at
a time (``render_batch(film, pix, rng)``). :func:`run_passes` is the one pass loop: it
renders sample passes in progress-sized batches, so that the time limit and cancellation
(:class:`Clock`) are honoured between batches; the driver (:mod:`ercuts_core.render`) runs
PATH and BDPT with it, the Ercuts integrator its rough BDPT and direct-light phases.

Progress (api.md): ``progress(fraction, message)`` messages start with the phase name,
fractions rise monotonically over the whole render, and every phase reports at least every
~0.25 s of work. ``preview(image)`` receives the image so far ((h, w, 4) float32) at most
once per :data:`PREVIEW_INTERVAL` seconds.
"""
from __future__ import annotations

import time
from typing import TYPE_CHECKING, Callable

import numpy as np
from numpy.typing import NDArray

from ..film import Film
from ..memory import MemoryPlan
from .. import qmc
from ..scene import BuiltScene, Surface
from ..settings import RenderSettings

if TYPE_CHECKING:
    from ..bsdf import Bsdf
    from ..qmc import PassSequence, PixelSequence

Progress = Callable[[float, str], "bool | None"]
Preview = Callable[[np.ndarray], None]

#: Minimum seconds between two preview images.
PREVIEW_INTERVAL = 1.0


class Clock:
    """Deadline, progress, preview and cancel bookkeeping shared by all phases."""

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


def batch_pixels(memory: MemoryPlan, settings: RenderSettings) -> int:
    """Pixels per pass batch: the render's memory plan's (about ``batch_rays`` rays per
    bounce for PATH, a quarter of that for BDPT, whose batch holds two subpaths and all
    their connections; smaller when the memory budget asks for it,
    :func:`ercuts_core.memory.plan`), and at most :func:`progress_batch_pixels`, so a batch
    stays well under a second and the time limit and cancellation are honoured promptly."""
    return min(memory.batch_pixels, progress_batch_pixels(settings))


def progress_batch_pixels(settings: RenderSettings) -> int:
    """Largest batch that reports progress every ~0.25 s of work: BDPT batches of
    ``batch_rays``/32 pixels (4096 by default) take ~0.12 s on the S-corridor on 2 cores and
    are no slower per pixel than one batch per pass (measured: 0.49 s per 160×120 pass with
    4096 or 8192, 0.66 s with 19200); a PATH pass of ``batch_rays`` pixels takes ~0.2 s."""
    per = settings.batch_rays if settings.integrator == "PATH" else settings.batch_rays // 32
    return max(1024, per)


def run_passes(integrator: "Integrator", film: Film, clock: Clock, *, samples: int, batch: int,
               phase: str, key: tuple = (), fraction: Callable[[float], float] = lambda f: f,
               deadline: float | None = None, show: bool = True, first: int = 0,
               on_pass: Callable[[Film], bool | None] | None = None) -> Film:
    """The pass loop: up to ``samples`` passes of ``integrator`` over ``film``'s window.

    Each pass renders every pixel once, in batches of ``batch`` pixels with random streams
    ``[seed, *key, pass, batch start]`` and the pass's randomised Sobol point of the stream
    ``(seed, *key)`` (:class:`~ercuts_core.qmc.PassSequence`: over the passes a pixel's
    samples are stratified; integrators that do not use it ignore it), into its own film, merged into ``film`` when
    complete; a pass cut short (cancel, time limit) is kept only when it is the first, so
    every pixel keeps the same sample count. After every batch progress is reported as
    ``"{phase} sample k/samples"`` at ``fraction(f)`` of the render, f being the phase's
    fraction done (with a ``deadline``, at least its share of the time used). Stops after a
    pass once ``deadline`` is past (the first pass always completes unless cancelled; a second
    is not forced: a 1080p direct-light pass took ≈ 40 s when the film's accumulation was
    quadratic in pixels (≈ 6 s since), and a forced second one left the later phases of a
    120 s render no time).
    ``show``: send the merged image to the preview after each pass. ``first``: index of the
    first pass (its random streams; a later call continues a film's passes with new ones).
    ``on_pass(part)``: called with every complete pass's own film before it is merged; a true
    return value ends the loop after that pass (the rough BDPT once P is known well enough).
    Returns ``film``.
    """
    s, window = integrator.settings, film.window
    n = window.n_pixels
    t0 = time.perf_counter()
    enough = False
    for k in range(samples):
        part = Film(window)
        sequence = qmc.PassSequence((s.seed, *key), first + k) if qmc.ENABLED else None
        for start in range(0, n, batch):
            rng = np.random.default_rng([s.seed, *key, first + k, start])
            integrator.render_batch(part, np.arange(start, min(n, start + batch)), rng, sequence)
            f = (k + min(n, start + batch) / n) / samples
            if deadline is not None:    # with many samples, the time share says how far
                f = max(f, (time.perf_counter() - t0) / max(deadline - t0, 1e-9))
            if not clock.report(fraction(f), f"{phase} sample {k + 1}/{samples}"):
                break
        if not clock.cancelled or film.passes_done == 0:
            if on_pass is not None and not clock.cancelled:
                enough = bool(on_pass(part))
            film.merge(part)
            if show:
                clock.show(film.image)
        if enough or clock.cancelled or (deadline is not None and time.perf_counter() > deadline):
            break
    return film


class Integrator:
    """Base class: holds the scene and settings, makes camera rays, records AOVs."""

    def __init__(self, scene: BuiltScene, settings: RenderSettings):
        self.scene = scene
        self.settings = settings
        self.camera = scene.camera
        self.window = scene.camera.window

    def camera_rays(self, pix: NDArray, rng: np.random.Generator,
                    u: "PixelSequence | None" = None) -> tuple[NDArray, NDArray]:
        """Jittered rays through window pixels ``pix`` (N,) (box filter; a lens point each
        with depth of field); the jitter and lens numbers from ``u`` (the pass's quasi-random
        numbers of ``pix``, :mod:`ercuts_core.qmc`) when given, else from ``rng``."""
        return self.camera.generate_rays(*self.camera_samples(pix, rng, u))

    def camera_samples(self, pix: NDArray, rng: np.random.Generator,
                       u: "PixelSequence | None" = None) -> tuple[NDArray, NDArray | None]:
        """(N, 2) jittered raster positions in pixels ``pix`` (N,) and (N, 2) lens uniforms
        (None for a pinhole), from ``u`` when given, else from ``rng``."""
        raster = self.window.raster(pix).astype(np.float64)
        if u is None:
            raster += rng.random((len(pix), 2))
            return raster, self.camera.lens_samples(rng, len(pix))
        lanes = np.arange(len(pix))
        raster += u.take(lanes, 2)
        return raster, (u.take(lanes, 2) if self.camera.has_lens else None)

    def record_first_hit(self, film: Film, pix: NDArray, keep: NDArray, surf: Surface | None,
                         bsdf: "Bsdf | None") -> None:
        """First-hit AOVs of camera samples ``pix``: depth (ray distance, Blender's Z pass),
        shading normal and albedo; lanes ``keep`` hit ``surf`` (others: 1e10 and zeros)."""
        n = len(pix)
        depth = np.full((n, 1), 1e10)
        normal = np.zeros((n, 3))
        albedo = np.zeros((n, 3))
        if len(keep):
            depth[keep, 0] = surf.t
            normal[keep] = surf.ns
            if bsdf is not None:
                albedo[keep] = bsdf.albedo()
        film.add_aov("depth", pix, depth)
        film.add_aov("normal", pix, normal)
        film.add_aov("albedo", pix, albedo)

    def alpha(self, surf: Surface) -> NDArray:
        """(N,) coverage: 1 for hits, and for misses unless the film is transparent."""
        if self.settings.film_transparent:
            return surf.valid.astype(np.float64)
        return np.ones(len(surf.valid))

    def render_batch(self, film: Film, pix: NDArray, rng: np.random.Generator,
                     sequence: "PassSequence | None" = None) -> None:
        """One camera sample per pixel ``pix`` (N,) into ``film``, from ``rng`` and, where
        the integrator uses it, the pass's quasi-random ``sequence``."""
        raise NotImplementedError
