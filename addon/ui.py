"""Properties-editor panels for the Ercuts engine.

Own panels show ``scene.ercuts`` (Render tab) and the material, world and light
settings the exporter reads. Blender's generic panels (Format, Output, Frame Range,
Color Management, camera lens, …) are made visible for the engine the way Cycles
does it (``cycles/ui.py get_panels``): every panel whose ``COMPAT_ENGINES`` contains
'BLENDER_RENDER', minus the ones replaced here, gets 'ERCUTS' added; unregister takes
it out again.
"""
from __future__ import annotations

import bpy

from . import compat

ENGINE_ID = "ERCUTS"

#: Blender panels replaced by our own (the light panels) or meaningless for Ercuts.
_EXCLUDE_PANELS = {
    "DATA_PT_light",
    "DATA_PT_area",
    "DATA_PT_spot",
    "DATA_PT_falloff_curve",
    "NODE_DATA_PT_light",
    "VIEWLAYER_PT_layer_passes",  # replaced by ERCUTS_VIEWLAYER_PT_passes
    "VIEWLAYER_PT_filter",
    "VIEWLAYER_PT_override",  # replaced by ERCUTS_VIEWLAYER_PT_override (3.4 has none)
}
#: EEVEE-only panels that are also right for Ercuts (material slots and previews).
_EXTRA_PANELS = {
    "MATERIAL_PT_preview",
    "EEVEE_MATERIAL_PT_context_material",
    "WORLD_PT_context_world",
}

#: Panels we added ENGINE_ID to, so unregister() can undo exactly that.
_patched_panels: list[type] = []


def get_panels():
    """Blender panel classes to show for Ercuts (Cycles' ``get_panels`` pattern)."""
    panels = []
    for panel in bpy.types.Panel.__subclasses__():
        engines = getattr(panel, "COMPAT_ENGINES", None)
        if engines is None or panel.__name__ in _EXCLUDE_PANELS:
            continue
        if "BLENDER_RENDER" in engines or panel.__name__ in _EXTRA_PANELS:
            panels.append(panel)
    return panels


def _split(layout):
    """``layout`` in Blender's property-split style (labels left, no decorators)."""
    layout.use_property_split = True
    layout.use_property_decorate = False
    return layout


def _settings_layout(layout, context):
    """``layout`` in Blender's property-split style, and ``scene.ercuts``."""
    return _split(layout), context.scene.ercuts


class ErcutsPanel:
    """Mix-in: poll only for the Ercuts engine."""

    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    COMPAT_ENGINES = {ENGINE_ID}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES


class ErcutsClosedPanel(ErcutsPanel):
    """Mix-in: an Ercuts panel that starts collapsed."""

    bl_options = {"DEFAULT_CLOSED"}


# --------------------------------------------------------------------------- render tab

class ERCUTS_RENDER_PT_sampling(ErcutsPanel, bpy.types.Panel):
    """Integrator, samples, seed; the header holds the Preview/Final preset menu."""

    bl_label = "Sampling"
    bl_context = "render"

    def draw_header_preset(self, context):
        from . import presets

        self.layout.menu(presets.ERCUTS_MT_sampling_presets.__name__,
                         text=presets.header_label(context.scene.ercuts))

    def draw(self, context):
        layout, settings = _settings_layout(self.layout, context)
        layout.prop(settings, "integrator")
        col = layout.column(align=True)
        if settings.integrator == "ERCUTS":
            col.prop(settings, "rough_samples")
            if settings.direct_light == "NEE":
                col.prop(settings, "direct_samples")
        else:
            col.prop(settings, "samples")
        col.prop(settings, "seed")
        col.prop(settings, "use_animated_seed")
        col = layout.column(align=True)
        col.prop(settings, "viewport_integrator")
        col.prop(settings, "viewport_samples")


class ERCUTS_RENDER_PT_light_paths(ErcutsPanel, bpy.types.Panel):
    bl_label = "Light Paths"
    bl_context = "render"

    def draw(self, context):
        layout, settings = _settings_layout(self.layout, context)
        col = layout.column(align=True)
        col.prop(settings, "max_depth")
        col.prop(settings, "rr_depth")


class ERCUTS_RENDER_PT_ercuts(ErcutsPanel, bpy.types.Panel):
    """The paper's parameters: lightcut error, chains, cut size, VPL clamp (ERCUTS only)."""

    bl_label = "Ercuts Algorithm"
    bl_context = "render"

    def draw(self, context):
        layout, settings = _settings_layout(self.layout, context)
        layout.active = settings.integrator == "ERCUTS"
        col = layout.column(align=True)
        col.prop(settings, "max_error_percent")
        col.prop(settings, "max_cut_size")
        col.prop(settings, "stochastic_cut_size")
        col.prop(settings, "stochastic_passes")
        col.prop(settings, "stochastic_cut_sharing")
        col.prop(settings, "gather_spacing")
        col = layout.column(align=True)
        col.prop(settings, "chains_per_pixel")
        col.prop(settings, "seed_samples")
        col.prop(settings, "max_chains")
        col.prop(settings, "chain_length")
        col.prop(settings, "min_chain_length")
        layout.prop(settings, "iterations")
        layout.prop(settings, "clamp")
        layout.prop(settings, "clamp_compensation")


class ERCUTS_RENDER_PT_mutations(ErcutsPanel, bpy.types.Panel):
    """Which Metropolis mutations the energy-redistribution chains use."""

    bl_label = "Mutations"
    bl_context = "render"
    bl_parent_id = "ERCUTS_RENDER_PT_ercuts"

    def draw(self, context):
        layout, settings = _settings_layout(self.layout, context)
        layout.active = settings.integrator == "ERCUTS"
        col = layout.column(heading="Mutations", align=True)
        col.prop(settings, "lens_perturbation", text="Lens")
        col.prop(settings, "caustic_perturbation", text="Caustic")
        # multichain_perturbation is not drawn: it needs perfectly specular materials.
        col.prop(settings, "bidirectional_mutation", text="Bidirectional")


class ERCUTS_RENDER_PT_ercuts_advanced(ErcutsClosedPanel, bpy.types.Panel):
    """Seeding, gather and normalisation details (ERCUTS only)."""

    bl_label = "Advanced"
    bl_context = "render"
    bl_parent_id = "ERCUTS_RENDER_PT_ercuts"

    def draw(self, context):
        layout, settings = _settings_layout(self.layout, context)
        layout.active = settings.integrator == "ERCUTS"
        layout.prop(settings, "direct_light")
        layout.prop(settings, "seeding")
        layout.prop(settings, "gather")
        layout.prop(settings, "lightcut_error")
        layout.prop(settings, "tree_pairing")
        layout.prop(settings, "iteration_start")
        col = layout.column(align=True)
        col.prop(settings, "shading_samples")
        col.prop(settings, "e1_samples")
        layout.prop(settings, "normalize_to_p")


class ERCUTS_RENDER_PT_film(ErcutsClosedPanel, bpy.types.Panel):
    bl_label = "Film"
    bl_context = "render"

    def draw(self, context):
        layout, settings = _settings_layout(self.layout, context)
        layout.prop(settings, "film_transparent")


class ERCUTS_RENDER_PT_denoising(ErcutsClosedPanel, bpy.types.Panel):
    """OpenImageDenoise through the compositor (:mod:`.denoise`)."""

    bl_label = "Denoising"
    bl_context = "render"

    def draw(self, context):
        from . import denoise

        layout, settings = _settings_layout(self.layout, context)
        layout.prop(settings, "use_denoising")
        layout.operator(denoise.ERCUTS_OT_setup_denoising.bl_idname, icon="NODETREE")
        if not compat.oidn_available():
            layout.label(text="No OpenImageDenoise in this Blender", icon="ERROR")


class ERCUTS_RENDER_PT_performance(ErcutsClosedPanel, bpy.types.Panel):
    bl_label = "Performance"
    bl_context = "render"

    def draw(self, context):
        layout, settings = _settings_layout(self.layout, context)
        layout.prop(settings, "threads")
        layout.prop(settings, "batch_rays")
        layout.prop(settings, "time_limit")
        if "memory_budget_mb" in settings.bl_rna.properties:
            layout.prop(settings, "memory_budget_mb")
        layout.prop(settings, "cluster")


# --------------------------------------------------------------------------- output / view layer

class ERCUTS_OUTPUT_PT_statistics(ErcutsClosedPanel, bpy.types.Panel):
    """The JSON statistics file written next to each frame (:mod:`.sidecar`)."""

    bl_label = "Ercuts Statistics"
    bl_context = "output"

    def draw(self, context):
        layout, settings = _settings_layout(self.layout, context)
        layout.prop(settings, "write_sidecar")


class ErcutsViewLayerPanel(ErcutsPanel):
    """Mix-in: View Layer tab, Ercuts engine, a view layer in the context."""

    bl_context = "view_layer"

    @classmethod
    def poll(cls, context):
        return getattr(context, "view_layer", None) is not None and super().poll(context)


class ERCUTS_VIEWLAYER_PT_passes(ErcutsViewLayerPanel, bpy.types.Panel):
    """Pass toggles of the active view layer (:mod:`.passes`)."""

    bl_label = "Passes"

    def draw(self, context):
        from . import passes

        layout = _split(self.layout)
        view_layer = context.view_layer
        col = layout.column(heading="Include", align=True)
        for p in passes.PASSES:
            owner = view_layer if p.blender_toggle else view_layer.ercuts
            col.prop(owner, p.toggle, text=p.name)


class ERCUTS_VIEWLAYER_PT_override(ErcutsViewLayerPanel, bpy.types.Panel):
    """Material (and on 5.0 world) override of the view layer, which the exporter honours."""

    bl_label = "Override"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = _split(self.layout)
        view_layer = context.view_layer
        layout.prop(view_layer, "material_override")
        if "world_override" in view_layer.bl_rna.properties:
            layout.prop(view_layer, "world_override")


# --------------------------------------------------------------------------- material / world

def _draw_node_view(layout, id_block, output_type: str, input_name: str) -> None:
    """Cycles' ``panel_node_draw``: the node tree as nested sockets, or a 'Use Nodes' button."""
    if not compat.uses_nodes(id_block):
        layout.prop(id_block, "use_nodes", icon="NODETREE")
        return
    ntree = id_block.node_tree
    node = ntree.get_output_node("CYCLES") or ntree.get_output_node("ALL")
    if node is None:
        layout.label(text="No output node")
        return
    socket = node.inputs.get(input_name)
    if socket is None:
        layout.label(text=f"No {input_name} input")
        return
    layout.template_node_view(ntree, node, socket)


def _draw_surface(layout, idblock, output: str, color_prop: str, color_text: str | None) -> None:
    """The Surface panel of a material or world: its node tree's ``output`` node, or
    (without nodes) the use-nodes toggle and the plain colour ``color_prop``."""
    if compat.uses_nodes(idblock):
        _draw_node_view(layout, idblock, output, "Surface")
        return
    layout.use_property_split = True
    if not compat.USE_NODES_DEPRECATED:
        layout.prop(idblock, "use_nodes", icon="NODETREE")
    layout.prop(idblock, color_prop, **({"text": color_text} if color_text else {}))


class ERCUTS_MATERIAL_PT_surface(ErcutsPanel, bpy.types.Panel):
    bl_label = "Surface"
    bl_context = "material"

    @classmethod
    def poll(cls, context):
        return context.material is not None and super().poll(context)

    def draw(self, context):
        _draw_surface(self.layout, context.material, "OUTPUT_MATERIAL", "diffuse_color", "Color")


class ERCUTS_WORLD_PT_surface(ErcutsPanel, bpy.types.Panel):
    bl_label = "Surface"
    bl_context = "world"

    @classmethod
    def poll(cls, context):
        return context.world is not None and super().poll(context)

    def draw(self, context):
        _draw_surface(self.layout, context.world, "OUTPUT_WORLD", "color", None)


# --------------------------------------------------------------------------- light

class ERCUTS_LIGHT_PT_light(ErcutsPanel, bpy.types.Panel):
    bl_label = "Light"
    bl_context = "data"

    @classmethod
    def poll(cls, context):
        return context.light is not None and super().poll(context)

    def draw(self, context):
        light = context.light
        layout = self.layout
        layout.row().prop(light, "type", expand=True)
        layout.use_property_split = True
        layout.use_property_decorate = False
        col = layout.column()
        col.prop(light, "color")
        col.prop(light, "energy")
        for extra in ("exposure", "normalize"):
            if hasattr(light, extra):
                col.prop(light, extra)
        if light.type in {"POINT", "SPOT"}:
            col.prop(light, "shadow_soft_size", text="Radius")
            if hasattr(light, "use_soft_falloff"):
                col.prop(light, "use_soft_falloff")
        elif light.type == "SUN":
            col.prop(light, "angle")
        elif light.type == "AREA":
            col.prop(light, "shape")
            sub = col.column(align=True)
            if light.shape in {"SQUARE", "DISK"}:
                sub.prop(light, "size")
            else:
                sub.prop(light, "size", text="Size X")
                sub.prop(light, "size_y", text="Y")
            if hasattr(light, "spread"):
                col.prop(light, "spread")
        if light.type == "SPOT":
            col.separator()
            col.prop(light, "spot_size", text="Spot Size")
            col.prop(light, "spot_blend", text="Blend")
            col.prop(light, "show_cone")


classes = (
    ERCUTS_RENDER_PT_sampling,
    ERCUTS_RENDER_PT_light_paths,
    ERCUTS_RENDER_PT_ercuts,
    ERCUTS_RENDER_PT_mutations,
    ERCUTS_RENDER_PT_ercuts_advanced,
    ERCUTS_RENDER_PT_film,
    ERCUTS_RENDER_PT_denoising,
    ERCUTS_RENDER_PT_performance,
    ERCUTS_OUTPUT_PT_statistics,
    ERCUTS_VIEWLAYER_PT_passes,
    ERCUTS_VIEWLAYER_PT_override,
    ERCUTS_MATERIAL_PT_surface,
    ERCUTS_WORLD_PT_surface,
    ERCUTS_LIGHT_PT_light,
)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    for panel in get_panels():
        if ENGINE_ID not in panel.COMPAT_ENGINES:
            panel.COMPAT_ENGINES.add(ENGINE_ID)
            _patched_panels.append(panel)


def unregister():
    for panel in _patched_panels:
        panel.COMPAT_ENGINES.discard(ENGINE_ID)
    _patched_panels.clear()
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
