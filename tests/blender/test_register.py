"""Registration, engine flags, panels, and the scene.ercuts ↔ RenderSettings mirror."""
from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import bpy
import pytest

import addon
from addon import compat, properties, ui
from addon.engine import ErcutsRenderEngine


def _engines():
    """bl_idnames of the registered engines (setting render.engine validates against them)."""
    s = bpy.context.scene
    try:
        s.render.engine = "ERCUTS"
        return {"ERCUTS"}
    except TypeError:
        return set()


def test_register_unregister_twice():
    for _ in range(2):
        addon.unregister()
        assert not hasattr(bpy.types.Scene, "ercuts")
        assert "ERCUTS" not in _engines()
        assert "ERCUTS" not in bpy.types.RENDER_PT_format.COMPAT_ENGINES
        assert not hasattr(bpy.types, "ERCUTS_RENDER_PT_sampling")
        addon.register()
        assert "ERCUTS" in _engines()
        assert bpy.context.scene.ercuts.samples == 4096
        assert "ERCUTS" in bpy.types.RENDER_PT_format.COMPAT_ENGINES
    bpy.context.scene.render.engine = "ERCUTS"
    assert bpy.context.scene.render.engine == "ERCUTS"


def test_bl_info_and_engine_flags():
    assert addon.bl_info["name"] == "Ercuts" and addon.bl_info["category"] == "Render"
    assert ErcutsRenderEngine.bl_idname == "ERCUTS" and ErcutsRenderEngine.bl_label == "Ercuts"
    assert ErcutsRenderEngine.bl_use_preview is True
    assert ErcutsRenderEngine.bl_use_shading_nodes_custom is False
    assert ErcutsRenderEngine.bl_use_eevee_viewport is True
    assert getattr(ErcutsRenderEngine, "bl_use_postprocess", True) is not False


def test_properties_mirror_render_settings():
    from ercuts_core import settings as core_settings
    from ercuts_core.settings import RenderSettings

    rna = properties.ErcutsRenderSettings.bl_rna.properties
    names = [f.name for f in dataclasses.fields(RenderSettings)]
    assert list(properties.PROPERTY_NAMES) == names
    own = {p.identifier for p in rna} - {"rna_type", "name"}
    assert own == set(names) | set(properties.ADDON_ONLY_NAMES)
    defaults = RenderSettings()
    assert properties._CORE_DEFAULTS == defaults.to_dict()  # defaults come from the core
    for name in names:
        prop = rna[name]
        assert prop.description, name
        expected = getattr(defaults, name)
        if prop.type == "FLOAT":
            assert prop.default == pytest.approx(expected), name
        else:
            assert prop.default == expected, name
    enums = {"integrator": "INTEGRATORS", "gather": "GATHERS", "seeding": "SEEDINGS"}
    for name, table in enums.items():
        if name in names:
            items = tuple(item.identifier for item in rna[name].enum_items)
            assert set(items) == set(getattr(core_settings, table)), name
    assert bpy.context.scene.ercuts.to_core() == RenderSettings()


def test_properties_round_trip_and_threads():
    s = bpy.context.scene
    s.ercuts.integrator = "PATH"
    s.ercuts.samples = 7
    s.ercuts.max_depth = 3
    s.ercuts.time_limit = 1.5
    s.ercuts.film_transparent = True
    assert s.render.film_transparent is True  # one setting, shared with Film > Transparent
    core = s.ercuts.to_core()
    assert (core.integrator, core.samples, core.max_depth, core.time_limit, core.film_transparent) == \
        ("PATH", 7, 3, 1.5, True)
    s.render.threads_mode = "FIXED"
    s.render.threads = 3
    assert s.ercuts.to_core().threads == 3  # honours -t / fixed threads when ercuts.threads = 0
    s.ercuts.threads = 1
    assert s.ercuts.to_core().threads == 1


def test_panels_poll_for_engine():
    s = bpy.context.scene
    mat = bpy.data.materials.new("M")
    w = bpy.data.worlds.new("W")
    li = bpy.data.lights.new("L", "AREA")
    ctx = lambda engine: SimpleNamespace(engine=engine, scene=s, material=mat, world=w,  # noqa: E731
                                         light=li, view_layer=s.view_layers[0])
    for cls in ui.classes:
        assert cls.poll(ctx("ERCUTS")), cls.__name__
        assert not cls.poll(ctx("CYCLES")), cls.__name__
        assert getattr(bpy.types, cls.__name__) is cls
    blender_panels = ["RENDER_PT_format", "RENDER_PT_output", "RENDER_PT_color_management",
                      "RENDER_PT_frame_range", "DATA_PT_lens", "DATA_PT_camera",
                      "MATERIAL_PT_preview", "EEVEE_MATERIAL_PT_context_material"]
    for name in blender_panels:
        panel = getattr(bpy.types, name)
        assert "ERCUTS" in panel.COMPAT_ENGINES, name
    # The light panels we replace are not shown twice.
    assert "ERCUTS" not in bpy.types.DATA_PT_light.COMPAT_ENGINES
    assert bpy.types.RENDER_PT_format.poll(ctx("ERCUTS"))


def test_compat_version_switches():
    v = bpy.app.version
    assert compat.RECT_IS_FLAT == (v >= (4, 1, 0))
    assert compat.HAS_CORNER_NORMALS == hasattr(bpy.types.Mesh, "corner_normals") or \
        "corner_normals" in bpy.types.Mesh.bl_rna.properties
    mat = bpy.data.materials.new("P")
    compat.enable_nodes(mat)
    node = mat.node_tree.nodes.new("ShaderNodeBsdfPrincipled")
    for concept, (new, old) in compat._PRINCIPLED.items():
        here = new if compat.PRINCIPLED_V4 else old
        # a concept with no socket in this version ("" name: 3.x Transmission Roughness) is None
        assert (compat.principled_input(node, concept) is not None) == bool(here), concept
    assert compat.principled_specular(0.5, 1.5) == pytest.approx(0.5)
    li = bpy.data.lights.new("A", "AREA")
    scale = compat.area_light_radiance_scale(li, 2.0)
    import math
    assert scale == pytest.approx(1 / (math.pi * 2.0) if v >= (4, 0, 0) else 1 / (4 * 2.0))


class _FakeLayout:
    """Stands in for UILayout (no UI in background mode): checks every drawn property exists."""

    def __init__(self, log):
        self.log = log

    def prop(self, data, name, **kwargs):
        assert name in data.bl_rna.properties, f"{type(data).__name__} has no property {name!r}"
        self.log.append(name)

    def template_node_view(self, ntree, node, socket):
        assert socket.node == node
        self.log.append("node_view")

    def label(self, **kwargs):
        self.log.append("label")

    def operator(self, idname, **kwargs):
        module, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, module), name), idname
        self.log.append(idname)
        return SimpleNamespace()

    def separator(self, **kwargs):
        pass

    def column(self, **kwargs):
        return self

    row = box = split = column


@pytest.mark.parametrize("light_type", ["POINT", "SPOT", "SUN", "AREA"])
def test_panels_draw(light_type):
    from addon import compat

    s = bpy.context.scene
    mat = bpy.data.materials.new("M")
    compat.enable_nodes(mat)
    w = bpy.data.worlds.new("W")
    compat.enable_nodes(w)
    li = bpy.data.lights.new("L", light_type)
    ctx = SimpleNamespace(engine="ERCUTS", scene=s, material=mat, world=w, light=li,
                          view_layer=s.view_layers[0])
    for cls in ui.classes:
        log = []
        cls.draw(SimpleNamespace(layout=_FakeLayout(log)), ctx)  # draw() only uses self.layout
        assert log, cls.__name__
