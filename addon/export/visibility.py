"""Ray-visibility settings that Cycles honours and Ercuts does not render: one warning each.

Cycles (Object Properties > Visibility > Ray Visibility, Mask; Light Properties > Cast
Shadow) can hide an object from camera, diffuse, glossy, transmission or shadow rays, make it
a holdout or a shadow catcher, keep a light out of diffuse, glossy or transmission
reflections and switch a light's shadows off. Ercuts renders every object as visible to every
ray and every light as lighting everything and casting shadows, so such a scene comes out
different from Cycles; the bad-input policy asks for a warning with the fallback named, not a
silent difference. A light with a size (area, or point/spot with a radius) shown to the
camera is reported too: Cycles draws it, Ercuts shows only its light. Volume-scatter
visibility is not reported (Ercuts has no volumes).
"""
from __future__ import annotations

#: (property, what it hides) for mesh-like objects; every one is True by default.
OBJECT_RAYS = (("visible_camera", "camera"), ("visible_diffuse", "diffuse"), ("visible_glossy", "glossy"),
               ("visible_transmission", "transmission"), ("visible_shadow", "shadow"))
#: The same for light objects: the kinds of bounce a light illuminates.
LIGHT_RAYS = (("visible_diffuse", "diffuse"), ("visible_glossy", "glossy"),
              ("visible_transmission", "transmission"))


def _light_shown_to_camera(ob) -> bool:
    """The light object ``ob`` has a size and its Ray Visibility > Camera is on (off by default
    for lights): Cycles draws it where the camera sees it."""
    light = ob.data
    sized = light.type == "AREA" or (light.type in {"POINT", "SPOT"} and light.shadow_soft_size > 0)
    return sized and bool(getattr(ob, "visible_camera", False))


def ray_visibility_notes(ob) -> list[str]:
    """Warnings for the Blender object ``ob`` (mesh-like or light) for the visibility settings
    Ercuts ignores, each naming the object and the fallback; empty when it uses none."""
    is_light = ob.type == "LIGHT"
    kind = "Light" if is_light else "Object"
    off = [label for prop, label in (LIGHT_RAYS if is_light else OBJECT_RAYS)
           if not getattr(ob, prop, True)]
    notes = [f"hidden from {', '.join(off)} rays"] if off else []
    if not is_light:
        if getattr(ob, "is_holdout", False):
            notes.append("holdout")
        if getattr(ob, "is_shadow_catcher", False):
            notes.append("shadow catcher")
    elif not getattr(ob.data, "use_shadow", True):
        notes.append("Cast Shadow off")
    out = []
    if notes:
        out.append(f"{kind} '{ob.name}': {'; '.join(notes)} — not supported by Ercuts, rendered as "
                   "visible to every ray" + (" and casting shadows" if is_light else ""))
    if is_light and _light_shown_to_camera(ob):
        out.append(f"Light '{ob.name}': visible to the camera in Cycles (Ray Visibility > Camera); "
                   "Ercuts does not show lights seen directly, only their light")
    return out
