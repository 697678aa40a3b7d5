"""The Ercuts ``RenderEngine``: export → ``ercuts_core.render`` → RenderResult.

``render()`` is called once per view layer. Everything happens there, so the time
limit covers the export too: the core gets what is left of ``time_limit``. The core's
progress callback drives the progress bar and the stats line and polls
``test_break()`` (returning False cancels; the image rendered so far is kept).
Failures are reported with ``self.report({'ERROR'}, ...)``, which aborts the render
and makes ``bpy.ops.render.render`` raise and a batch render exit non-zero (an
uncaught exception would only be printed, shared docs ``blender.md`` §0.6); the
traceback goes to the console. Warnings are reported once per render.
"""
from __future__ import annotations

import time
import traceback

import bpy

#: Details of the last final render, for tests and debugging (plain Python data only).
last_render: dict = {}

#: Settings used for material/world preview thumbnails (fast, low noise is not needed).
PREVIEW_LIMITS = dict(samples=8, max_depth=4, time_limit=5.0)


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

    # ------------------------------------------------------------------ entry point
    def render(self, depsgraph):
        self._start = time.monotonic()
        try:
            self._render(depsgraph)
        except Exception as exc:  # noqa: BLE001 - every failure must reach the user
            message = self._error_message(exc)
            print(f"Ercuts: render failed: {message}")
            traceback.print_exc()
            self.report({"ERROR"}, f"Ercuts: {message}")

    @staticmethod
    def _error_message(exc: Exception) -> str:
        from .export import ExportError

        known = (ExportError,)
        try:
            from ercuts_core.validate import SceneError
            known += (SceneError,)
        except ImportError:
            pass
        if isinstance(exc, known):
            return str(exc)
        missing = getattr(exc, "name", None) or ""
        if isinstance(exc, ModuleNotFoundError) and missing.split(".")[0] in {
                "numpy", "embreex", "ercuts_core"}:
            return (f"cannot load the Ercuts core ({exc}); numpy, embreex and ercuts_core "
                    "must be importable by Blender's Python")
        return f"{type(exc).__name__}: {exc} (see the console for details)"

    # ------------------------------------------------------------------ the render
    def _render(self, depsgraph):
        from . import compat

        compat.preload_embreex()
        import ercuts_core

        from . import framebuffer
        from .export import ExportCancelled, export_scene

        scene = depsgraph.scene
        layer_name = depsgraph.view_layer.name
        settings = scene.ercuts.to_core()
        if self.is_preview:
            settings = settings.replace(
                samples=min(settings.samples, PREVIEW_LIMITS["samples"]),
                max_depth=min(settings.max_depth, PREVIEW_LIMITS["max_depth"]),
                time_limit=PREVIEW_LIMITS["time_limit"])
        self._stats_prefix = f"{layer_name} | " if len(scene.view_layers) > 1 else ""
        self.update_stats("Ercuts", f"{self._stats_prefix}Exporting scene")

        try:
            exported = export_scene(
                depsgraph, camera_override=self.camera_override,
                size=(self.resolution_x, self.resolution_y),
                use_border=False if self.is_preview else None,
                should_stop=self._should_stop)
        except ExportCancelled:
            return
        desc = exported.description

        # The time limit covers the whole render: the core gets what is left.
        if settings.time_limit > 0:
            remaining = settings.time_limit - (time.monotonic() - self._start)
            settings = settings.replace(time_limit=max(remaining, 1e-3))
        result = ercuts_core.render(desc, settings, progress=self._progress)

        framebuffer.write_image(self, scene.render, result.image, result.window, layer_name)
        self.update_progress(1.0)
        warnings = list(exported.warnings)
        warnings += [i.message for i in result.issues if i.severity == "warning"]
        if not exported.has_emitters and not any(i.code == "no_lights" for i in result.issues):
            warnings.append("scene has no lights: the image is black")
        elapsed = time.monotonic() - self._start
        self.update_stats("Ercuts", f"{self._stats_prefix}{result.summary()} | "
                                    f"{_format_time(elapsed)}")
        if not self.is_preview:
            last_render.clear()
            last_render.update(
                settings=settings.to_dict(), warnings=warnings, cancelled=result.cancelled,
                export_seconds=exported.seconds, total_seconds=elapsed,
                summary=result.summary(), window=tuple(result.window),
                export_stats=dict(exported.stats), stats=dict(result.stats))
            if warnings:
                unique = list(dict.fromkeys(warnings))
                for w in unique:
                    print(f"Ercuts warning: {w}")
                self.report({"WARNING"}, "Ercuts: " + "; ".join(unique))
            if result.cancelled:
                print(f"Ercuts: render stopped early: {result.summary()}")

    def _progress(self, fraction: float, message: str) -> bool:
        """Core progress callback: progress bar, stats line, cancel polling."""
        self.update_progress(min(max(float(fraction), 0.0), 1.0))
        elapsed = time.monotonic() - self._start
        self.update_stats("Ercuts", f"{self._stats_prefix}{message} | {_format_time(elapsed)}")
        return not self._should_stop()

    def _should_stop(self) -> bool:
        """True when the user cancelled (Esc); a Python-level hook, so tests can stand in."""
        return bool(self.test_break())


classes = (ErcutsRenderEngine,)


register, unregister = bpy.utils.register_classes_factory(classes)
