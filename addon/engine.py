"""The Ercuts ``RenderEngine``: export → ``ercuts_core.render`` → RenderResult.

``render()`` is called once per view layer. Everything happens there, so the time
limit covers the export too: the core gets what is left of ``time_limit``. The core's
progress callback drives the progress bar and the stats line and polls
``test_break()`` (returning False cancels; the image rendered so far is kept).
Failures are reported with ``self.report({'ERROR'}, ...)``, which aborts the render
and makes ``bpy.ops.render.render`` raise and a batch render exit non-zero (an
uncaught exception would only be printed, shared docs ``blender.md`` §0.6); the
traceback goes to the console. Warnings are reported once per render.

While the core runs, its ``preview`` callback (when the core has one) shows the image
so far (``framebuffer.show_preview``). In background mode (``blender -b``) Blender prints
a ``Fra:… | <stats>`` line for every ``update_stats`` call, so there the engine prints one
line per phase (of the first progressive iteration; each later iteration gets one
``Iteration N`` line when its first phase starts) and updates the stats at most every
:data:`BACKGROUND_STATS_INTERVAL` seconds (the core reports several times a second; the
details go to the JSON sidecar).

A render that reaches its time limit ends normally. One stopped by Blender's break flag
(Esc in the UI; Ctrl-C, i.e. SIGINT, in ``blender -b``) keeps its partial image in the UI,
but in background mode it is an error (:meth:`ErcutsRenderEngine._is_batch`): nobody is
watching, and the frame must not be saved as if it were complete.

The final image goes into Combined and the view layer's enabled passes (:mod:`.passes`,
declared in ``update_render_passes``); optionally a JSON statistics file is written next
to the frame (:mod:`.sidecar`). Preview thumbnails
(``is_preview``) use :func:`preview_settings`, without passes, border or statistics.
The Rendered viewport (``view_update``/``view_draw``) lives in :mod:`.viewport`.
"""
from __future__ import annotations

import functools
import inspect
import time
import traceback

import bpy

from .errors import error_message

#: Details of the last final render, for tests and debugging (plain Python data only).
last_render: dict = {}

#: Material/world/light preview thumbnails: unidirectional path tracing (no chains,
#: VPLs or light tree to build), few samples, shallow paths, at most 2 s.
PREVIEW_LIMITS = dict(integrator="PATH", samples=8, max_depth=4, time_limit=2.0)

#: Background mode: seconds between two stats updates (each prints a line) within a phase.
BACKGROUND_STATS_INTERVAL = 5.0

#: Phase names that start the core's progress messages: the Ercuts phases
#: (``ercuts_core.integrators.ercuts.pacing.PHASES``, read by :func:`phases`) and the pass
#: integrators' names.
PASS_PHASES = ("BDPT", "PATH")


def phases() -> tuple:
    """Every phase name a core progress message may start with (the core's own list)."""
    try:
        from ercuts_core.integrators.ercuts.pacing import PHASES
    except ImportError:  # no numpy in this Python: no core, no progress messages either
        return PASS_PHASES
    return tuple(dict.fromkeys((*PHASES, *PASS_PHASES)))


def preview_settings(settings):
    """The cheap settings used for preview thumbnails (``is_preview``)."""
    limit = settings.time_limit
    return settings.replace(
        integrator=PREVIEW_LIMITS["integrator"],
        samples=min(settings.samples, PREVIEW_LIMITS["samples"]),
        max_depth=min(settings.max_depth, PREVIEW_LIMITS["max_depth"]),
        time_limit=min(limit, PREVIEW_LIMITS["time_limit"]) if limit > 0 else PREVIEW_LIMITS["time_limit"])


def phase_of(message: str) -> str:
    """The phase a core progress message names (its known prefix, else its first field)."""
    for phase in phases():
        if message.startswith(phase):
            return phase
    return message.split("|")[0].strip().split(" ")[0] if message else ""


def _accepts_preview(render_fn) -> bool:
    """True when the core's ``render`` takes the ``preview`` callback (api.md)."""
    try:
        return "preview" in inspect.signature(render_fn).parameters
    except (TypeError, ValueError):
        return False


def _render_function(settings, is_preview: bool, scene):
    """The core's ``render``, or with a Cluster address (final renders) the cluster's, which
    streams the merged iterations to the same progress and preview callbacks."""
    import ercuts_core

    if not settings.cluster or is_preview:
        return ercuts_core.render
    from ercuts_core import cluster

    return functools.partial(cluster.render, scene=scene.name, frame=scene.frame_current)


class RenderInterrupted(Exception):
    """Blender's break flag stopped a background render: reported as an error."""


def _format_time(seconds: float) -> str:
    minutes, secs = divmod(int(seconds), 60)
    return f"{minutes:02d}:{secs:02d}"


class ErcutsRenderEngine(bpy.types.RenderEngine):
    bl_idname = "ERCUTS"
    bl_label = "Ercuts"
    bl_use_preview = True
    bl_use_shading_nodes_custom = False
    bl_use_eevee_viewport = True

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)  # required from Blender 4.4 on
        self._start = time.monotonic()
        self._stats_prefix = ""
        self._layer_name = ""
        self._phase = None
        self._phases_seen = []
        self._stats_time = -float("inf")
        self._user_cancelled = False

    # ------------------------------------------------------------------ entry point
    def render(self, depsgraph):
        self._start = time.monotonic()
        self._user_cancelled = False
        try:
            self._render(depsgraph)
        except RenderInterrupted as exc:   # the reason is the message; no traceback
            print(f"Ercuts: {exc}", flush=True)
            self.report({"ERROR"}, f"Ercuts: {exc}")
        except Exception as exc:  # noqa: BLE001 - every failure must reach the user
            message = error_message(exc)
            print(f"Ercuts: render failed: {message}")
            traceback.print_exc()
            self.report({"ERROR"}, f"Ercuts: {message}")

    # ------------------------------------------------------------------ viewport
    def view_update(self, context, depsgraph):
        """Rendered viewport: the scene changed (:mod:`.viewport`)."""
        from . import viewport

        viewport.view_update(self, context, depsgraph)

    def view_draw(self, context, depsgraph):
        """Rendered viewport: draw the newest image, restart on view changes (:mod:`.viewport`)."""
        from . import viewport

        try:
            viewport.view_draw(self, context, depsgraph)
        except Exception as exc:  # noqa: BLE001 - never a traceback in the UI
            traceback.print_exc()
            self.update_stats("Ercuts", f"Error: {error_message(exc)}")

    def __del__(self):
        try:
            session = getattr(self, "_viewport_session", None)
        except ReferenceError:      # bpy 5 may free the engine's RNA first: nothing to stop
            return
        if session is not None:     # a viewport engine is freed: stop its render thread
            session.stop()

    # ------------------------------------------------------------------ passes
    def update_render_passes(self, scene=None, renderlayer=None):
        """Declare our passes so the compositor's Render Layers node shows them."""
        from . import passes

        passes.register_passes(self, scene, renderlayer)

    # ------------------------------------------------------------------ the render
    def _settings(self, scene):
        """Core settings for this render: animated seed, preview thumbnail limits."""
        ercuts = scene.ercuts
        settings = ercuts.to_core(seed=ercuts.seed_for_frame(scene.frame_current))
        return preview_settings(settings) if self._is_preview() else settings

    def _render(self, depsgraph):
        from . import compat

        compat.preload_embreex()
        import ercuts_core

        from . import framebuffer, passes
        from .export import ExportCancelled, export_scene

        scene = depsgraph.scene
        view_layer = depsgraph.view_layer
        layer_name = view_layer.name
        if not view_layer.use:  # Blender skips disabled layers itself; never render one
            return
        settings = self._settings(scene)
        enabled = [] if self._is_preview() else passes.enabled_passes(scene, view_layer)
        for p in enabled:  # before begin_result (a registered pass is not added twice)
            self.add_pass(p.name, p.channels, p.chan_id, layer=layer_name)
        self._layer_name = layer_name
        self._stats_prefix = f"{layer_name} | " if len(scene.view_layers) > 1 else ""
        self._phase = None
        self._phases_seen = []
        self._stats_time = -float("inf")
        self.update_stats("Ercuts", f"{self._stats_prefix}Exporting scene")

        try:
            exported = export_scene(
                depsgraph, camera_override=self.camera_override,
                size=(self.resolution_x, self.resolution_y),
                use_border=False if self._is_preview() else None,
                should_stop=self._should_stop)
        except ExportCancelled:
            self._stop_if_batch("while exporting the scene")
            return
        desc = exported.description

        # The time limit covers the whole render: the core gets what is left.
        if settings.time_limit > 0:
            remaining = settings.time_limit - (time.monotonic() - self._start)
            settings = settings.replace(time_limit=max(remaining, 1e-3))
        kwargs = {}
        if _accepts_preview(ercuts_core.render):
            kwargs["preview"] = self._preview_callback(scene.render, desc, layer_name)
        result = _render_function(settings, self._is_preview(), scene)(
            desc, settings, progress=self._progress, **kwargs)

        images, missing = passes.pass_images(result, enabled)
        framebuffer.write_image(self, scene.render, images, result.window, layer_name)
        self.update_progress(1.0)
        elapsed = time.monotonic() - self._start
        self.update_stats("Ercuts", f"{self._stats_prefix}{result.summary()} | "
                                    f"{_format_time(elapsed)}")
        if not self._is_preview():
            self._report(scene, layer_name, exported, result, settings, images, missing,
                         elapsed, progressive=bool(kwargs))
            if self._user_cancelled or getattr(result, "stopped_by", None) == "cancel":
                self._stop_if_batch(f"after {elapsed:.1f} s, in phase {self._phase or '?'}")

    def _stop_if_batch(self, when: str) -> None:
        """The user (or Blender's break flag) stopped the render: an error in background mode."""
        if self._is_batch():
            raise RenderInterrupted(
                f"render cancelled by Blender's break signal (Ctrl-C / SIGINT) {when}: "
                "the image is incomplete and is not saved")

    def _report(self, scene, layer_name, exported, result, settings, images, missing,
                elapsed, progressive):
        """After a final render: ``last_render``, the sidecar, one warning report."""
        warnings = self._warnings(scene, exported, result, missing, settings)
        last_render.clear()
        last_render.update(
            settings=settings.to_dict(), warnings=warnings, cancelled=result.cancelled,
            stopped_by=getattr(result, "stopped_by", None),
            export_seconds=exported.seconds, total_seconds=elapsed,
            summary=result.summary(), window=tuple(result.window),
            export_stats=dict(exported.stats), stats=dict(result.stats), passes=list(images),
            missing_passes=[p.name for p in missing], progressive=progressive,
            layer=layer_name)
        if scene.ercuts.write_sidecar:
            if self._user_cancelled:
                # Blender writes no image for a cancelled frame; its statistics file (maybe
                # of an earlier good render) stays as it is too.
                print("Ercuts: render cancelled: statistics file not written")
            else:
                last_render["sidecar"] = self._write_sidecar(scene, layer_name, result, settings,
                                                             exported, warnings, elapsed)
        if warnings:
            unique = list(dict.fromkeys(warnings))
            for w in unique:
                print(f"Ercuts warning: {w}")
            self.report({"WARNING"}, "Ercuts: " + "; ".join(unique))
        if result.cancelled and not self._user_cancelled and \
                getattr(result, "stopped_by", "time_limit") == "time_limit":
            limit = scene.ercuts.time_limit
            print(f"Ercuts: time limit of {limit:g} s reached: {result.summary()}")
        elif result.cancelled:
            print(f"Ercuts: render stopped early: {result.summary()}")

    @staticmethod
    def _warnings(scene, exported, result, missing, settings) -> list[str]:
        """Everything worth one warning line after a render."""
        from . import compat, denoise, passes

        warnings = list(exported.warnings)
        warnings += [i.message for i in result.issues if i.severity == "warning"]
        if not exported.has_emitters and not any(i.code == "no_lights" for i in result.issues):
            warnings.append("scene has no lights: the image is black")
        missing_warning = passes.missing_warning(missing, settings.integrator)
        if missing_warning:
            warnings.append(missing_warning)
        if scene.ercuts.use_denoising and not compat.oidn_available():
            warnings.append(denoise.NO_OIDN_WARNING)
        return warnings

    def _write_sidecar(self, scene, layer_name, result, settings, exported, warnings, elapsed):
        """Add this layer's statistics to the frame's JSON sidecar; its path (None on failure)."""
        from . import sidecar

        enabled = [vl.name for vl in scene.view_layers if vl.use]
        first = scene.render.use_single_layer or not enabled or enabled[0] == layer_name
        report = sidecar.layer_report(result, settings, dict(
            view_layer=layer_name, export_seconds=exported.seconds, total_seconds=elapsed,
            export_stats=dict(exported.stats), warnings=list(dict.fromkeys(warnings))))
        try:
            return sidecar.add_layer(scene, scene.frame_current, bool(self.is_animation),
                                     layer_name, report, first_layer=first)
        except OSError as exc:  # the image still renders; say why the file is missing
            warnings.append(f"statistics file not written: {exc}")
            return None

    def _preview_callback(self, render, desc, layer_name):
        """The core's ``preview(image)``: show the image so far in the render window."""
        from ercuts_core.camera import render_window

        from . import framebuffer

        window = render_window(desc.camera).rect

        def preview(image):
            framebuffer.show_preview(self, render, image, window, layer_name)

        return preview

    def _phase_line(self, phase: str) -> str | None:
        """What the background log says when ``phase`` starts: the phase's name the first
        time; ``Iteration N`` when the first phase starts again (a new progressive
        iteration, N counted from 1); nothing for a later iteration's other phases."""
        seen = self._phases_seen
        if phase not in seen:
            seen.append(phase)
            return phase
        if phase == seen[0]:
            seen.append(phase)
            return f"Iteration {seen.count(phase)}"
        return None

    def _progress(self, fraction: float, message: str) -> bool:
        """Core progress callback: progress bar, stats line, cancel polling.

        In background mode (``blender -b``) one line is printed per phase change, and the
        stats (a ``Fra:`` line each) are updated at most every
        :data:`BACKGROUND_STATS_INTERVAL` seconds within a phase.
        """
        fraction = min(max(float(fraction), 0.0), 1.0)
        self.update_progress(fraction)
        now = time.monotonic()
        elapsed = now - self._start
        phase = phase_of(message)
        background = bpy.app.background
        if phase != self._phase:
            self._phase = phase
            line = self._phase_line(phase)
            if background and line:
                print(f"Ercuts: {self._layer_name} | {line} | "
                      f"{fraction:4.0%} | {_format_time(elapsed)}", flush=True)
                self._stats_time = now          # that line says it: no stats line now
        if not background or now - self._stats_time >= BACKGROUND_STATS_INTERVAL:
            self.update_stats("Ercuts", f"{self._stats_prefix}{message} | {_format_time(elapsed)}")
            self._stats_time = now
        if self._should_stop():
            self._user_cancelled = True
        return not self._user_cancelled

    def _is_preview(self) -> bool:
        """True for material/world/light preview thumbnails; a Python-level hook (like
        :meth:`_should_stop`), so tests can take the thumbnail path headless, where Blender
        renders no previews."""
        return bool(self.is_preview)

    def _is_batch(self) -> bool:
        """True in background mode (``blender -b``, the bpy module), where a cancelled
        render is an error; a Python-level hook, so tests can take the interactive path."""
        return bool(bpy.app.background)

    def _should_stop(self) -> bool:
        """True when the user cancelled (Esc); a Python-level hook, so tests can stand in."""
        return bool(self.test_break())


classes = (ErcutsRenderEngine,)


register, unregister = bpy.utils.register_classes_factory(classes)
