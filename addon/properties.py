"""Render settings stored in the scene as ``scene.ercuts``.

:class:`ErcutsRenderSettings` mirrors ``ercuts_core.settings.RenderSettings``
one-to-one: the same property names and defaults (a test checks it), plus a
description on every property. :meth:`ErcutsRenderSettings.to_core` turns it into the
core's frozen dataclass.
"""
from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty

INTEGRATOR_ITEMS = (
    ("BDPT", "Bidirectional", "Bidirectional path tracing with multiple importance sampling", 0),
    ("PATH", "Path Tracing", "Unidirectional path tracing with next-event estimation (reference)", 1),
)


def _get_film_transparent(self):
    return bool(self.id_data.render.film_transparent)


def _set_film_transparent(self, value):
    self.id_data.render.film_transparent = bool(value)


class ErcutsRenderSettings(bpy.types.PropertyGroup):
    """Ercuts core settings (``ercuts_core.RenderSettings``) of one scene."""

    integrator: EnumProperty(
        name="Integrator",
        description="Light transport algorithm",
        items=INTEGRATOR_ITEMS,
        default="BDPT",
    )
    samples: IntProperty(
        name="Samples",
        description="Number of samples per pixel",
        default=16, min=1, soft_max=4096,
    )
    seed: IntProperty(
        name="Seed",
        description="Random seed; the same seed and settings give the same image",
        default=0, min=0,
    )
    max_depth: IntProperty(
        name="Max Bounces",
        description="Maximum number of bounces of a light path (1 = direct light only)",
        default=8, min=1, soft_max=64, max=1024,
    )
    rr_depth: IntProperty(
        name="Russian Roulette Depth",
        description="Number of bounces before paths may be terminated at random (Russian roulette)",
        default=3, min=0, soft_max=64,
    )
    time_limit: FloatProperty(
        name="Time Limit",
        description=("Maximum time in seconds for the whole render, scene export included "
                     "(0 = no limit); the image rendered so far is kept when it runs out"),
        default=0.0, min=0.0, soft_max=3600.0, unit="TIME_ABSOLUTE",
    )
    film_transparent: BoolProperty(
        name="Transparent",
        description=("World background is transparent (alpha = coverage); the same setting as "
                     "Blender's Film > Transparent"),
        default=False,
        get=_get_film_transparent,
        set=_set_film_transparent,
    )
    batch_rays: IntProperty(
        name="Batch Rays",
        description="Rays traced per wavefront batch (more uses more memory but less overhead)",
        default=1 << 17, min=1024, soft_max=1 << 22,
    )
    threads: IntProperty(
        name="Threads",
        description=("Threads used to trace rays (0 = all cores, or Blender's fixed "
                     "Performance > Threads / -t setting)"),
        default=0, min=0, soft_max=256,
    )

    def to_core(self, **overrides):
        """The equivalent ``ercuts_core.settings.RenderSettings`` (``overrides`` win)."""
        from ercuts_core.settings import RenderSettings

        values = {name: getattr(self, name) for name in PROPERTY_NAMES}
        render = self.id_data.render
        if values["threads"] == 0 and render.threads_mode == "FIXED":
            values["threads"] = int(render.threads)
        values.update(overrides)
        return RenderSettings.from_dict(values)

    @classmethod
    def register(cls):
        bpy.types.Scene.ercuts = PointerProperty(
            type=cls, name="Ercuts Settings", description="Ercuts render settings")

    @classmethod
    def unregister(cls):
        del bpy.types.Scene.ercuts


#: Names of the mirrored settings, in ``RenderSettings`` order.
PROPERTY_NAMES = ("integrator", "samples", "seed", "max_depth", "rr_depth", "time_limit",
                  "film_transparent", "batch_rays", "threads")

classes = (ErcutsRenderSettings,)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
