"""Sampling presets (Preview, Final), applied by an operator from the Sampling panel's header.

Operators rather than Blender's file-based preset system (``AddPresetBase``): the two
presets ship with the add-on, need no files in the user's config directory, work the
same on 3.4 and 5.0, and are testable headless (``bpy.ops.ercuts.sampling_preset``).
Only quality/speed settings are touched; the integrator, seed, passes and output stay.

* **Preview**: a few seconds for a look at the light: few samples and short chains,
  small cuts at a 5 % error bound, shallow paths.
* **Final**: the core's defaults (``ercuts_core.RenderSettings()``; the settings of the
  README's S-corridor benchmark), read from the core when it can be imported.
"""
from __future__ import annotations

import bpy
from bpy.props import EnumProperty

PREVIEW = {
    "samples": 16,
    "rough_samples": 4,
    "max_depth": 4,
    "rr_depth": 2,
    "chains_per_pixel": 0.1,
    "seed_samples": 1,
    "chain_length": 30,
    "max_cut_size": 200,
    "max_error": 0.05,
    "e1_samples": 64,
    "shading_samples": 1,
    "direct_samples": 8,
}

#: Fallback for the Final preset when the core cannot be imported (its defaults).
_FINAL_FALLBACK = {
    "samples": 4096,
    "rough_samples": 16,
    "max_depth": 64,
    "rr_depth": 3,
    "chains_per_pixel": 0.25,
    "seed_samples": 4,
    "chain_length": 100,
    "max_cut_size": 1000,
    "max_error": 0.02,
    "e1_samples": 256,
    "shading_samples": 0,
    "direct_samples": 64,
}


def final() -> dict:
    """The Final preset: the core's defaults for the keys the presets set."""
    try:
        from ercuts_core.settings import RenderSettings
    except Exception:  # noqa: BLE001 - no numpy in this Python: the same literal defaults
        return dict(_FINAL_FALLBACK)
    defaults = RenderSettings().to_dict()
    return {name: defaults[name] for name in _FINAL_FALLBACK}


def preset_values(name: str) -> dict:
    """Settings of preset ``name`` ('PREVIEW' or 'FINAL')."""
    return dict(PREVIEW) if name == "PREVIEW" else final()


def apply(settings, name: str) -> None:
    """Set ``settings`` (``scene.ercuts``) to preset ``name``."""
    for key, value in preset_values(name).items():
        setattr(settings, key, value)


def matching(settings) -> str | None:
    """The preset ``settings`` currently equal (floats to 1e-6), or None."""
    for name in ("PREVIEW", "FINAL"):
        values = preset_values(name)
        if all(abs(getattr(settings, k) - v) <= 1e-6 * max(1.0, abs(v)) for k, v in values.items()):
            return name
    return None


PRESET_ITEMS = (
    ("PREVIEW", "Preview", "Fast, noisy: few samples, short chains, small lightcuts"),
    ("FINAL", "Final", "Final quality: the Ercuts core's default settings"),
)


class ERCUTS_OT_sampling_preset(bpy.types.Operator):
    """Apply a sampling preset to the scene's Ercuts settings"""

    bl_idname = "ercuts.sampling_preset"
    bl_label = "Apply Sampling Preset"
    bl_options = {"REGISTER", "UNDO"}

    preset: EnumProperty(name="Preset", items=PRESET_ITEMS, default="FINAL")

    def execute(self, context):
        apply(context.scene.ercuts, self.preset)
        return {"FINISHED"}


class ERCUTS_MT_sampling_presets(bpy.types.Menu):
    bl_label = "Sampling Presets"

    def draw(self, context):
        for identifier, label, _ in PRESET_ITEMS:
            self.layout.operator(ERCUTS_OT_sampling_preset.bl_idname, text=label).preset = identifier


def header_label(settings) -> str:
    """Text of the preset menu button: the matching preset's name, or 'Presets'."""
    name = matching(settings)
    return dict((i, label) for i, label, _ in PRESET_ITEMS).get(name, "Presets")


classes = (ERCUTS_OT_sampling_preset, ERCUTS_MT_sampling_presets)

register, unregister = bpy.utils.register_classes_factory(classes)
