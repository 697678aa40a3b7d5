"""Render passes (AOVs): which exist, when they are enabled, and their pixels.

A pass is declared to Blender twice (shared docs ``blender.md`` §1.4, verified on 3.4.1
and 5.0.1): ``update_render_passes`` → ``register_pass`` makes the compositor's Render
Layers node show a socket (and Blender then creates the pass in every render result of
that view layer), and ``add_pass`` before ``begin_result`` adds it in ``render()``
(Blender ignores a second add of a registered pass, so nothing is created twice).

Toggles live per view layer: Depth and Normal use Blender's own ``use_pass_z`` and
``use_pass_normal`` (as Cycles does); the others are ``view_layer.ercuts.use_pass_*``
(:class:`.properties.ErcutsViewLayerSettings`). With denoising on, Normal and Albedo
(the denoiser's guides) are always written, and the noisy Combined is kept as
"Noisy Image".

Pixels come from ``RenderResult.aovs`` (core convention: window size, top row first,
float32): 'depth' (h, w) camera distance in metres, 'normal' (h, w, 3) world-space unit
normal, 'albedo'/'direct'/'indirect'/'emission'/'er_caustic' (h, w, 3) linear RGB,
'cut_size'/'vpl_density' (h, w). A key the core did not produce (e.g. the ERCUTS
diagnostics under BDPT/PATH) leaves the pass at zero and is reported by
:func:`pass_images`.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class PassDef:
    """One render pass.

    Attributes:
        name: Blender pass name (multilayer EXR channel ``<layer>.<name>.<chan>``).
        aov: key in ``RenderResult.aovs`` (None: derived from the image).
        chan_id: one letter per channel ("Z", "XYZ", "RGB", "RGBA", "X").
        kind: ``register_pass`` type: 'VALUE', 'VECTOR' or 'COLOR'.
        toggle: boolean property switching the pass on.
        blender_toggle: ``toggle`` is Blender's ViewLayer property (else ``view_layer.ercuts``).
        ercuts_only: only the ERCUTS integrator produces it.
        description: tooltip of the toggle.
    """

    name: str
    aov: str | None
    chan_id: str
    kind: str
    toggle: str
    blender_toggle: bool = False
    ercuts_only: bool = False
    description: str = ""

    @property
    def channels(self) -> int:
        return len(self.chan_id)


DEPTH = PassDef("Depth", "depth", "Z", "VALUE", "use_pass_z", blender_toggle=True)
NORMAL = PassDef("Normal", "normal", "XYZ", "VECTOR", "use_pass_normal", blender_toggle=True)
ALBEDO = PassDef("Albedo", "albedo", "RGB", "COLOR", "use_pass_albedo",
                 description="Surface colour at the first hit (the denoiser's albedo guide)")
NOISY = PassDef("Noisy Image", None, "RGBA", "COLOR", "use_denoising",
                description="The Combined image before denoising")

#: Every pass with a per-view-layer toggle, in the order of the Passes panel.
PASSES: tuple[PassDef, ...] = (
    DEPTH,
    NORMAL,
    ALBEDO,
    PassDef("Direct", "direct", "RGB", "COLOR", "use_pass_direct",
            description="Light scattered once (at the first hit) toward the camera"),
    PassDef("Indirect", "indirect", "RGB", "COLOR", "use_pass_indirect",
            description="Light scattered more than once; Emission + Direct + Indirect = Combined"),
    PassDef("Emission", "emission", "RGB", "COLOR", "use_pass_emission",
            description="Emitters and the world seen directly by the camera"),
    PassDef("Cut Size", "cut_size", "X", "VALUE", "use_pass_cut_size", ercuts_only=True,
            description="Ercuts diagnostic: lightcut size (light-tree nodes) per pixel"),
    PassDef("VPL Density", "vpl_density", "X", "VALUE", "use_pass_vpl_density", ercuts_only=True,
            description="Ercuts diagnostic: virtual point lights deposited per pixel"),
    PassDef("ER Caustic", "er_caustic", "RGB", "COLOR", "use_pass_er_caustic", ercuts_only=True,
            description="Ercuts diagnostic: caustic light carried by the energy-redistribution chains"),
)

#: Passes the add-on stores in ``view_layer.ercuts`` (the rest are Blender's toggles).
OWN_PASSES = tuple(p for p in PASSES if not p.blender_toggle)


def is_enabled(pass_def: PassDef, view_layer, use_denoising: bool) -> bool:
    """True when ``pass_def`` should be in ``view_layer``'s render result."""
    if use_denoising and pass_def in (NORMAL, ALBEDO):
        return True
    owner = view_layer if pass_def.blender_toggle else getattr(view_layer, "ercuts", None)
    return bool(getattr(owner, pass_def.toggle, False))


def enabled_passes(scene, view_layer) -> list[PassDef]:
    """The extra passes (Combined excluded) of ``view_layer``, Noisy Image last."""
    denoise = bool(getattr(scene.ercuts, "use_denoising", False))
    out = [p for p in PASSES if is_enabled(p, view_layer, denoise)]
    if denoise:
        out.append(NOISY)
    return out


def register_passes(engine, scene, view_layer) -> None:
    """``update_render_passes`` body: declare Combined and every enabled pass."""
    engine.register_pass(scene, view_layer, "Combined", 4, "RGBA", "COLOR")
    for p in enabled_passes(scene, view_layer):
        engine.register_pass(scene, view_layer, p.name, p.channels, p.chan_id, p.kind)


def pass_images(result, enabled: list[PassDef]) -> tuple[dict, list[PassDef]]:
    """Pass name → (h, w, C) float32 image (top row first), and the passes with no data.

    Combined is always first. ``result`` is an ``ercuts_core.RenderResult``.
    """
    import numpy as np  # not at module level: the add-on registers without numpy

    images = {"Combined": np.asarray(result.image, np.float32)}
    missing = []
    aovs = getattr(result, "aovs", None) or {}
    for p in enabled:
        if p is NOISY:
            images[p.name] = images["Combined"]
            continue
        data = aovs.get(p.aov)
        if data is None:
            missing.append(p)
            continue
        data = np.asarray(data, np.float32)
        if data.ndim == 2:
            data = data[..., None]
        images[p.name] = data[..., :p.channels]
    return images, missing


def missing_warning(missing: list[PassDef], integrator: str) -> str | None:
    """A warning for enabled passes the core did not fill (None when all is as expected).

    The ERCUTS diagnostics are expected to be missing under BDPT/PATH; any other
    missing pass is worth telling the user, since it is written as zeros.
    """
    names = [p.name for p in missing if not (p.ercuts_only and integrator != "ERCUTS")]
    if not names:
        return None
    return f"pass(es) {', '.join(names)} not produced by the core for {integrator}; left empty"
