"""Bad input through the add-on (real bpy), one test per row of the policy table
(shared docs style-and-testing.md §2.6):

* **error** — the render is refused: ``bpy.ops.render.render`` raises with a message that
  names the object (no camera, empty resolution or border, memory budget exceeded);
* **warning** — a fallback is used, the render finishes and the warning is reported once,
  naming the object (NaN/Inf vertices, missing output node, unsupported nodes, textures,
  no lights at all);
* **silent** — normal in Blender scenes: skipped and counted in the statistics, no warning
  (zero-area triangles, meshes without faces, zero-power lights, zero-area emitters).

Every test renders through ``bpy.ops.render.render`` with the Ercuts engine, so the
engine's error path and ``engine.last_render`` (warnings, core and export statistics) are
what is checked; each would fail if the policy changed (a warning where there should be
none, a missing count, a traceback instead of an error line).
"""
from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

import blender_helpers as bh
from addon import engine

W, H = 16, 12


def lit_scene(material=None):
    """A floor seen from above, lit by a point light: the baseline every case modifies."""
    bh.setup_render(W, H, samples=2, integrator="PATH", max_depth=3)
    floor = bh.plane("Floor", size=4.0, material=material or bh.diffuse("Grey"))
    bh.camera(location=(0, -3, 3), target=(0, 0, 0))
    bh.light("POINT", location=(0, 0, 2), energy=200.0, name="Lamp")
    return floor


def render(tmp_path, name="out.exr"):
    img = bh.render_exr(tmp_path / name)
    assert np.isfinite(img).all()
    return img


def warnings():
    return engine.last_render["warnings"]


def refused(tmp_path) -> str:
    """Render, expect the engine's error, return its one-line message."""
    with pytest.raises(RuntimeError) as info:
        bh.render_exr(tmp_path / "refused.exr")
    message = str(info.value)
    assert "Traceback" not in message and message.count("\n") <= 1, message
    assert not (tmp_path / "refused.exr").exists()
    return message


# --------------------------------------------------------------------------- geometry

def test_nan_and_inf_vertices_warn_naming_the_object(tmp_path):
    lit_scene()
    bh.mesh_object("Broken", [(0, 0, 0.5), (1, 0, 0.5), (math.nan, 1, 0.5), (0, math.inf, 0.5)],
                   [(0, 1, 2), (0, 1, 3)])
    img = render(tmp_path)
    hits = [w for w in warnings() if "Broken" in w]
    assert len(hits) == 1 and "NaN/Inf" in hits[0], warnings()
    assert img[..., :3].mean() > 0


def test_zero_area_triangles_are_silent_and_counted(tmp_path):
    lit_scene()
    bh.mesh_object("Sliver", [(0, 0, 0.5), (1, 0, 0.5), (2, 0, 0.5), (0, 0, 0.5)],
                   [(0, 1, 2), (0, 3, 1)])   # collinear; repeated vertex position
    render(tmp_path)
    assert warnings() == []
    assert engine.last_render["stats"]["degenerate_triangles"] == 2


def test_meshes_without_faces_are_skipped_silently_and_counted(tmp_path):
    lit_scene()
    bh.mesh_object("Points", [(0, 0, 1), (1, 0, 1)], [])
    me = bpy.data.meshes.new("Wire")
    me.from_pydata([(0, 0, 1), (1, 1, 1)], [(0, 1)], [])
    bh.link(bpy.data.objects.new("Wire", me))
    render(tmp_path)
    assert warnings() == []
    assert engine.last_render["export_stats"]["empty_meshes"] == 2
    assert engine.last_render["export_stats"]["triangles"] == 2     # the floor only


def _offset_scene(offset):
    bh.setup_render(W, H, samples=8, integrator="PATH", max_depth=3)
    o = np.array(offset, float)
    bh.plane("Floor", size=4.0, location=tuple(o), material=bh.diffuse("Grey"))
    bh.box("Block", size=(0.6, 0.6, 0.6), location=tuple(o + [0, 0, 0.3]), material=bh.diffuse("Grey2"))
    bh.camera(location=tuple(o + [0, -3, 3]), target=tuple(o))
    bh.light("POINT", location=tuple(o + [0.5, 0.5, 2]), energy=200.0, name="Lamp")


def test_objects_far_from_the_origin_render_like_near_ones(tmp_path):
    """1e5 m away (float32 spacing 8 mm): no shadow acne, no light leaks (image mean within
    the noise of 8 spp × 192 px; acne would darken lit surfaces by tens of per cent)."""
    _offset_scene((0, 0, 0))
    near = render(tmp_path, "near.exr")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    _offset_scene((1e5, -1e5, 1e5))
    far = render(tmp_path, "far.exr")
    assert warnings() == []
    origin = np.array(engine.last_render["export_stats"]["origin"])
    assert np.abs(origin - [1e5, -1e5, 1e5]).max() < 1024, origin     # moved near the camera
    # Same seed, same relative geometry: only rounding differs.
    np.testing.assert_allclose(far[..., :3].mean(), near[..., :3].mean(), rtol=0.01)
    assert (far[..., 3] == 1).all()


def test_negative_scale_renders_like_positive_scale(tmp_path):
    images = []
    for scale in ((1, 1, 1), (-1, 1, 1)):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        floor = lit_scene()
        floor.scale = scale
        images.append(render(tmp_path, f"s{scale[0]}.exr"))
        assert warnings() == []
    np.testing.assert_allclose(images[1][..., :3].mean(), images[0][..., :3].mean(), rtol=0.05)


# --------------------------------------------------------------------------- camera / frame

def test_no_camera_is_an_error(tmp_path):
    lit_scene()
    bpy.context.scene.camera = None
    assert "camera" in refused(tmp_path).lower()


def test_empty_border_is_an_error(tmp_path):
    """Blender itself refuses ("Image too small"); the exported description is refused by
    the core too (what a caller that bypasses Blender's check gets)."""
    from ercuts_core import SceneError, render as core_render
    lit_scene()
    r = bpy.context.scene.render
    r.use_border = True
    r.border_min_x, r.border_max_x = 0.5, 0.5
    r.border_min_y, r.border_max_y = 0.2, 0.8
    assert "too small" in refused(tmp_path)
    with pytest.raises(SceneError, match="border .* is empty"):
        core_render(bh.export().description)


def test_zero_resolution_is_an_error(tmp_path):
    """Blender clamps resolution_x ≥ 4, but 4 px × 1 % rounds to 0 px."""
    from ercuts_core import SceneError, render as core_render
    lit_scene()
    r = bpy.context.scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = 4, 4, 1
    assert "too small" in refused(tmp_path)
    with pytest.raises(SceneError, match="Resolution 0x0 is empty"):
        core_render(bh.export(size=(0, 0)).description)


def test_resolution_over_the_memory_budget_is_refused_with_the_estimate(tmp_path):
    lit_scene()
    s = bpy.context.scene
    s.ercuts.integrator = "ERCUTS"
    s.render.resolution_x, s.render.resolution_y = 7680, 4320
    s.ercuts.memory_budget_mb = 2048
    message = refused(tmp_path)
    assert "MiB" in message and "memory budget of 2048 MiB" in message, message
    estimate = float(message.split("about ")[1].split(" MiB")[0])
    assert estimate > 2048


# --------------------------------------------------------------------------- lights

def test_no_lights_warns_once_and_renders_black(tmp_path):
    lit_scene()
    bpy.data.objects.remove(bpy.data.objects["Lamp"])
    img = render(tmp_path)
    assert len([w for w in warnings() if "no lights" in w]) == 1, warnings()
    assert img[..., :3].max() == 0 and (img[..., 3] == 1).all()


def test_zero_power_light_is_dropped_silently_and_counted(tmp_path):
    lit_scene()
    bh.light("POINT", location=(1, 0, 2), energy=0.0, name="DarkLamp")
    img = render(tmp_path)
    assert warnings() == []
    assert engine.last_render["stats"]["dropped_zero_lights"] == 1
    assert img[..., :3].mean() > 0


def test_emissive_zero_area_faces_are_silent_and_counted(tmp_path):
    lit_scene()
    bh.mesh_object("GlowSliver", [(0, 0, 1), (1, 0, 1), (2, 0, 1)], [(0, 1, 2)],
                   material=bh.emission("Glow", strength=100.0))
    img = render(tmp_path)
    assert warnings() == []
    assert engine.last_render["stats"]["degenerate_triangles"] == 1
    assert np.isfinite(img).all() and engine.last_render["stats"]["nonfinite_samples"] == 0


# --------------------------------------------------------------------------- materials

def test_material_without_node_tree_uses_viewport_colour_silently(tmp_path):
    mat = bpy.data.materials.new("NoNodes")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = False
    mat.diffuse_color = (0.8, 0.1, 0.1, 1.0)
    lit_scene(material=mat)
    img = render(tmp_path)
    if bpy.app.version < (5, 0, 0):   # 5.0: every material has a node tree (default Principled)
        assert warnings() == []
        rgb = img[..., :3].reshape(-1, 3).mean(axis=0)
        assert rgb[0] > 3 * rgb[1], rgb


def test_material_without_output_node_warns_naming_it(tmp_path):
    mat = bh.diffuse("NoOutput")
    for node in list(mat.node_tree.nodes):
        if node.bl_idname == "ShaderNodeOutputMaterial":
            mat.node_tree.nodes.remove(node)
    lit_scene(material=mat)
    render(tmp_path)
    assert len(warnings()) == 1 and "NoOutput" in warnings()[0] and "output" in warnings()[0]


def test_unsupported_node_warns_once_and_falls_back_to_grey(tmp_path):
    mat = bh.node_material("Velvety", "ShaderNodeBsdfToon")
    lit_scene(material=mat)
    bh.plane("Second", size=1.0, location=(0, 0, 0.2), material=mat)   # used twice, warned once
    img = render(tmp_path)
    assert len(warnings()) == 1 and "Velvety" in warnings()[0] and "unsupported" in warnings()[0]
    assert img[..., :3].mean() > 0


def test_missing_image_texture_warns_and_renders_magenta(tmp_path):
    """Like Cycles: a missing image renders magenta; one warning names image and material."""
    mat = bh.node_material("Textured", "ShaderNodeBsdfDiffuse", Color=(0.2, 0.6, 0.2))
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    img = bpy.data.images.new("Missing", 4, 4)
    img.source = "FILE"
    img.filepath = str(tmp_path / "missing.png")
    tex.image = img
    diffuse = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfDiffuse")
    mat.node_tree.links.new(tex.outputs["Color"], diffuse.inputs["Color"])
    lit_scene(material=mat)
    img = render(tmp_path)
    missing = [w for w in warnings() if "'Missing'" in w]
    assert len(missing) == 1 and "'Textured'" in missing[0], warnings()
    rgb = img[..., :3].reshape(-1, 3).mean(axis=0)
    assert rgb[0] > 2 * rgb[1] and rgb[2] > 2 * rgb[1], rgb


# --------------------------------------------------------------------------- libraries

def test_linked_library_objects_render_like_local_ones(tmp_path):
    """An object linked from another .blend is exported like a local one (no warning)."""
    lib_path = str(tmp_path / "library.blend")
    block = bh.box("LibBlock", size=(1, 1, 1), location=(0, 0, 0.5), material=bh.diffuse("LibGrey"))
    bpy.data.libraries.write(lib_path, {block}, fake_user=True)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    lit_scene()
    with bpy.data.libraries.load(lib_path, link=True) as (src, dst):
        dst.objects = ["LibBlock"]
    linked = dst.objects[0]
    assert linked.library is not None
    bh.link(linked)
    render(tmp_path)
    assert warnings() == []
    assert engine.last_render["export_stats"]["triangles"] == 2 + 12
