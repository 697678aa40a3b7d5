"""What a Blender user sees: presets, panels, progress (per-phase lines, progressive
display, cancel), view layers, material override, hidden objects, seeds, the JSON
statistics sidecar and the preview-thumbnail settings."""
from __future__ import annotations

import functools
import importlib
import json
import os
from types import SimpleNamespace

import bpy
import numpy as np
import pytest

import blender_helpers as h
from addon import engine as engine_module
from addon import framebuffer, passes, presets, ui
from addon.engine import ErcutsRenderEngine, phase_of, preview_settings
from ercuts_core.settings import RenderSettings
from test_register import _FakeLayout

W, H = 40, 30


def _scene(samples=4, integrator="PATH", albedo=(0.8, 0.8, 0.8)):
    h.camera(location=(0, 0, 5))
    h.plane("Floor", size=20, material=h.diffuse("Floor", albedo))
    h.light("POINT", location=(0, 0, 3), energy=200)
    return h.setup_render(W, H, samples=samples, integrator=integrator)


# --------------------------------------------------------------------------- presets / panels

def test_presets_apply():
    s = bpy.context.scene
    assert presets.header_label(s.ercuts) == "Final"  # the defaults are the Final preset
    assert bpy.ops.ercuts.sampling_preset(preset="PREVIEW") == {"FINISHED"}
    for key, value in presets.PREVIEW.items():
        assert getattr(s.ercuts, key) == pytest.approx(value), key
    assert presets.matching(s.ercuts) == "PREVIEW"
    assert presets.header_label(s.ercuts) == "Preview"
    s.ercuts.samples = 5
    assert presets.header_label(s.ercuts) == "Presets"
    bpy.ops.ercuts.sampling_preset(preset="FINAL")
    core = s.ercuts.to_core()
    defaults = RenderSettings()
    for key in presets.final():
        assert getattr(core, key) == pytest.approx(getattr(defaults, key)), key
    assert presets.final() == presets._FINAL_FALLBACK  # the fallback tracks the core


def test_preset_menu_lists_both_presets():
    log = []
    layout = _FakeLayout(log)
    presets.ERCUTS_MT_sampling_presets.draw(SimpleNamespace(layout=layout), bpy.context)
    assert log == ["ercuts.sampling_preset"] * 2


def test_passes_panel_draws_every_toggle():
    s = bpy.context.scene
    vl = s.view_layers[0]
    ctx = SimpleNamespace(engine="ERCUTS", scene=s, view_layer=vl)
    log = []
    ui.ERCUTS_VIEWLAYER_PT_passes.draw(SimpleNamespace(layout=_FakeLayout(log)), ctx)
    assert log == [p.toggle for p in passes.PASSES]
    assert ui.ERCUTS_VIEWLAYER_PT_passes.poll(ctx)
    assert not ui.ERCUTS_VIEWLAYER_PT_passes.poll(SimpleNamespace(engine="CYCLES", view_layer=vl))


def test_max_error_percent_is_max_error():
    s = bpy.context.scene
    s.ercuts.max_error_percent = 5.0
    assert s.ercuts.max_error == pytest.approx(0.05)
    assert s.ercuts.to_core().max_error == pytest.approx(0.05)


# --------------------------------------------------------------------------- preview thumbnails

def test_preview_settings_are_cheap():
    fast = preview_settings(RenderSettings(samples=512, max_depth=32))
    assert fast.integrator == "PATH"  # no chains, VPLs or light tree for a thumbnail
    assert fast.samples <= 8 and fast.max_depth <= 4 and 0 < fast.time_limit <= 2.0
    assert preview_settings(RenderSettings(time_limit=0.5)).time_limit == 0.5
    assert preview_settings(RenderSettings(samples=2)).samples == 2
    assert ErcutsRenderEngine.bl_use_preview is True


def test_preview_render_takes_the_cheap_path(tmp_path, monkeypatch):
    """A thumbnail render (``is_preview``; Blender renders none headless, so the engine's
    Python hook stands in): the core gets the preview settings whatever the scene asks for,
    the image is lit, and no passes, statistics file or ``last_render`` record are made."""
    import ercuts_core

    got = []
    core = ercuts_core.render

    def spy(desc, settings, *args, **kwargs):
        got.append(settings)
        return core(desc, settings, *args, **kwargs)

    monkeypatch.setattr(ercuts_core, "render", spy)
    monkeypatch.setattr(ErcutsRenderEngine, "_is_preview", lambda self: True)
    s = _scene(samples=512, integrator="ERCUTS")
    h.uv_sphere("Ball", radius=1.0, location=(0, 0, 1), material=h.diffuse("Ball", (0.8, 0.2, 0.2)))
    s.ercuts.max_depth = 16
    s.ercuts.write_sidecar = True
    s.view_layers[0].use_pass_z = True
    engine_module.last_render.clear()
    img = h.render_exr(tmp_path / "thumb.exr")
    assert len(got) == 1 and got[0].integrator == "PATH"
    assert got[0].samples <= 8 and got[0].max_depth <= 4 and 0 < got[0].time_limit <= 2.0
    assert img.shape == (H, W, 4) and img[..., :3].mean() > 0.01
    assert engine_module.last_render == {}
    assert not list(tmp_path.glob("*.json"))


# --------------------------------------------------------------------------- progress

def test_phase_of_messages():
    assert phase_of("Lightcuts 35% | 1.2M VPL evals") == "Lightcuts"
    assert phase_of("ER chains 3/100") == "ER chains"
    assert phase_of("Light tree") == "Light tree"
    assert phase_of("PATH sample 2/4") == "PATH"
    assert phase_of("Something else | x") == "Something"


def test_background_prints_one_line_per_phase(tmp_path, capsys):
    s = _scene(integrator="ERCUTS")
    bpy.ops.ercuts.sampling_preset(preset="PREVIEW")
    s.ercuts.samples = 2
    assert bpy.app.background
    h.render_exr(tmp_path / "phases.exr")
    lines = [line for line in capsys.readouterr().out.splitlines()
             if line.startswith("Ercuts: ViewLayer | ")]
    phases = [line.split(" | ")[1] for line in lines]
    assert len(phases) == len(set(phases)) >= 3, lines  # one line per phase, several phases
    assert phases[0] == "BDPT" and set(phases) <= set(engine_module.phases())
    fractions = [float(line.split(" | ")[2].rstrip("%")) for line in lines]
    assert fractions == sorted(fractions)


def test_later_iterations_get_one_log_line_each():
    """Phases repeat per progressive iteration; the log names them once, then one line per
    iteration when its first phase starts again."""
    fake = SimpleNamespace(_phases_seen=[])
    line = functools.partial(ErcutsRenderEngine._phase_line, fake)
    order = ["BDPT", "ER chains", "Lightcuts", "BDPT", "ER chains", "Lightcuts", "BDPT", "Lightcuts"]
    assert [line(p) for p in order] == ["BDPT", "ER chains", "Lightcuts", "Iteration 2", None, None,
                                        "Iteration 3", None]


def test_progressive_preview_is_shown(tmp_path, monkeypatch):
    core_render = importlib.import_module("ercuts_core.integrators.base")   # the clock's module
    monkeypatch.setattr(core_render, "PREVIEW_INTERVAL", 0.0)
    shown = []
    show = framebuffer.show_preview

    def spy(engine, render, image, window, layer_name):
        shown.append((image.shape, tuple(window), layer_name))
        return show(engine, render, image, window, layer_name)

    monkeypatch.setattr(framebuffer, "show_preview", spy)
    _scene(samples=3)
    img = h.render_exr(tmp_path / "progressive.exr")
    assert engine_module.last_render["progressive"] is True
    assert len(shown) >= 2
    assert all(entry == ((H, W, 4), (0, 0, W, H), "ViewLayer") for entry in shown)
    assert img[..., :3].max() > 0


def test_cancel_after_first_phase_keeps_partial_image(tmp_path, monkeypatch, interactive):
    """Esc (test_break) during the ER chains: the rough BDPT image is kept, not black."""
    phases = []
    progress = ErcutsRenderEngine._progress

    def spy(self, fraction, message):
        phases.append(phase_of(message))
        return progress(self, fraction, message)

    monkeypatch.setattr(ErcutsRenderEngine, "_progress", spy)
    monkeypatch.setattr(ErcutsRenderEngine, "_should_stop",
                        lambda self: phases[-1] not in ("BDPT", ""))
    s = _scene(integrator="ERCUTS")
    bpy.ops.ercuts.sampling_preset(preset="PREVIEW")
    s.ercuts.samples = 2
    img = h.render_exr(tmp_path / "cancelled.exr")
    assert engine_module.last_render["cancelled"] is True
    assert "Lightcuts" not in phases
    assert img[..., :3].min() > 0  # every floor pixel has the BDPT estimate


# --------------------------------------------------------------------------- view layers

def test_enabled_view_layers_rendered_disabled_skipped(tmp_path, monkeypatch):
    written = []
    write = framebuffer.write_image

    def spy(engine, render, image, window, layer_name, pass_name="Combined"):
        written.append(layer_name)
        return write(engine, render, image, window, layer_name, pass_name)

    monkeypatch.setattr(framebuffer, "write_image", spy)
    s = _scene(samples=1)
    s.view_layers.new("Second").ercuts.use_pass_albedo = True
    s.view_layers.new("Off").use = False
    ch = h.render_multilayer(tmp_path / "layers.exr")
    assert written == ["ViewLayer", "Second"]
    layers = {name.split(".")[0] for name in ch}
    assert layers == {"ViewLayer", "Second"}
    assert "Second.Albedo.R" in ch and "ViewLayer.Albedo.R" not in ch  # toggles per layer
    for layer in ("ViewLayer", "Second"):
        assert h.layer_pass(ch, layer, "Combined", "RGB").max() > 0


def test_material_override(tmp_path):
    s = _scene(samples=1, albedo=(0.1, 0.7, 0.1))
    vl = s.view_layers[0]
    vl.ercuts.use_pass_albedo = True
    vl.material_override = h.diffuse("Override", (0.9, 0.2, 0.3))
    ch = h.render_multilayer(tmp_path / "override.exr")
    albedo = h.layer_pass(ch, "ViewLayer", "Albedo", "RGB")
    np.testing.assert_allclose(albedo.reshape(-1, 3), np.broadcast_to((0.9, 0.2, 0.3), (W * H, 3)),
                               atol=1e-5)


def test_hidden_objects_not_rendered(tmp_path):
    s = _scene(samples=1)
    blocker = h.box("Blocker", size=(10, 10, 0.2), location=(0, 0, 1),
                    material=h.diffuse("Red", (1, 0, 0)))
    blocker.hide_render = True
    s.view_layers[0].use_pass_z = True
    ch = h.render_multilayer(tmp_path / "hidden.exr")
    assert h.layer_pass(ch, "ViewLayer", "Depth", "Z").min() > 4.9  # the floor, not the box


# --------------------------------------------------------------------------- seeds

def _render_frame(tmp_path, frame):
    bpy.context.scene.frame_set(frame)
    return h.render_exr(tmp_path / f"seed_{frame}.exr")[..., :3]


def test_animated_seed_changes_noise_fixed_seed_does_not(tmp_path):
    s = _scene(samples=1)
    s.ercuts.seed = 7
    a, b = _render_frame(tmp_path, 1), _render_frame(tmp_path, 2)
    np.testing.assert_array_equal(a, b)
    assert engine_module.last_render["settings"]["seed"] == 7
    s.ercuts.use_animated_seed = True
    c, d = _render_frame(tmp_path, 1), _render_frame(tmp_path, 2)
    assert engine_module.last_render["settings"]["seed"] == 9
    assert np.abs(c - d).max() > 0
    assert np.mean(c) == pytest.approx(np.mean(d), rel=0.05)  # same scene, other noise


# --------------------------------------------------------------------------- sidecar

def test_sidecar_beside_animation_frame(tmp_path):
    """A batch frame (animation naming, as ``-f``/``-a`` use): out/shot_0012.ercuts.json."""
    from addon import compat

    s = _scene(samples=2)
    s.view_layers.new("Second")
    s.ercuts.write_sidecar = True
    s.ercuts.seed = 3
    s.frame_start = s.frame_end = 12
    s.render.filepath = str(tmp_path / "out" / "shot_####")
    s.render.use_file_extension = True
    compat.set_single_layer_exr(s.render.image_settings)
    assert bpy.ops.render.render(animation=True) == {"FINISHED"}
    path = tmp_path / "out" / "shot_0012.ercuts.json"
    assert engine_module.last_render["sidecar"] == str(path)
    data = json.loads(path.read_text())
    assert data["frame"] == 12 and data["image"] == str(tmp_path / "out" / "shot_0012.exr")
    assert set(data["layers"]) == {"ViewLayer", "Second"}
    layer = data["layers"]["ViewLayer"]
    assert layer["seed"] == 3 and layer["settings"]["samples"] == 2
    assert layer["settings"]["integrator"] == "PATH" and layer["cancelled"] is False
    assert layer["timings"] and all(v >= 0 for v in layer["timings"].values())
    assert layer["total_seconds"] >= layer["export_seconds"] >= 0
    assert layer["view_layer"] == "ViewLayer" and layer["warnings"] == []
    # Atomic writes leave no temporary files behind.
    assert sorted(os.listdir(tmp_path / "out")) == ["shot_0012.ercuts.json", "shot_0012.exr"]


def test_sidecar_of_still_with_ercuts_statistics(tmp_path):
    """A still (write_still: the path as given): ercuts.exr → ercuts.ercuts.json."""
    s = _scene(integrator="ERCUTS")
    bpy.ops.ercuts.sampling_preset(preset="PREVIEW")
    s.ercuts.samples = 2
    s.ercuts.write_sidecar = True
    h.render_exr(tmp_path / "ercuts.exr")
    data = json.loads((tmp_path / "ercuts.ercuts.json").read_text())
    layer = data["layers"]["ViewLayer"]
    assert layer["settings"]["integrator"] == "ERCUTS"
    assert layer["vpl"] and layer["cuts"]  # VPL and cut statistics of the core's report


def test_cancelled_render_keeps_the_earlier_sidecar(tmp_path, monkeypatch, interactive):
    """Esc during a frame: Blender writes no image, and the frame's statistics file from
    the earlier good render is not replaced by the cancelled one's."""
    s = _scene(samples=2)
    s.ercuts.write_sidecar = True
    h.render_exr(tmp_path / "frame.exr")
    path = tmp_path / "frame.ercuts.json"
    good = path.read_bytes()
    assert json.loads(good)["layers"]["ViewLayer"]["cancelled"] is False
    monkeypatch.setattr(ErcutsRenderEngine, "_should_stop", lambda self: True)
    s.ercuts.samples = 50
    h.render_exr(tmp_path / "frame.exr")
    assert engine_module.last_render["cancelled"] is True and "sidecar" not in engine_module.last_render
    assert path.read_bytes() == good


def test_no_sidecar_by_default(tmp_path):
    _scene(samples=1)
    h.render_exr(tmp_path / "plain.exr")
    assert "sidecar" not in engine_module.last_render
    assert os.listdir(tmp_path) == ["plain.exr"]


# --------------------------------------------------------------------------- instancing

def _cube_instancer(points, z=1.0, size=0.4):
    """A mesh of ``points`` whose geometry-nodes modifier puts a cube on every vertex."""
    from addon import compat

    ng = bpy.data.node_groups.new("Scatter", "GeometryNodeTree")
    compat.new_group_socket(ng, "Geometry", "INPUT", "NodeSocketGeometry")
    compat.new_group_socket(ng, "Geometry", "OUTPUT", "NodeSocketGeometry")
    group_in = ng.nodes.new("NodeGroupInput")
    group_out = ng.nodes.new("NodeGroupOutput")
    cube = ng.nodes.new("GeometryNodeMeshCube")
    cube.inputs["Size"].default_value = (size, size, size)
    on_points = ng.nodes.new("GeometryNodeInstanceOnPoints")
    ng.links.new(group_in.outputs[0], on_points.inputs["Points"])
    ng.links.new(cube.outputs["Mesh"], on_points.inputs["Instance"])
    ng.links.new(on_points.outputs["Instances"], group_out.inputs[0])
    obj = h.mesh_object("Scatter", points, [], location=(0, 0, z))
    obj.modifiers.new("Scatter", "NODES").node_group = ng
    return obj


def test_geometry_nodes_instances_rendered(tmp_path):
    s = _scene(samples=1)
    s.view_layers[0].use_pass_z = True
    _cube_instancer([(-1, 0, 0), (1, 0, 0)], z=1.0, size=0.4)
    ch = h.render_multilayer(tmp_path / "instances.exr")
    depth = h.layer_pass(ch, "ViewLayer", "Depth", "Z")[..., 0]
    tan_half = 18.0 / 50.0
    for x in (-1.0, 1.0):  # cube tops at z = 1.2, i.e. 3.8 m below the camera
        col = int(W / 2 * (1 + x / 3.8 / tan_half))
        assert depth[H // 2, col] == pytest.approx(3.8 * np.hypot(1, x / 3.8), rel=0.01)
    assert depth[H // 2, W // 2] == pytest.approx(5.0, rel=0.01)  # floor between them


def test_transparent_film_alpha_is_coverage(tmp_path):
    h.camera(location=(0, 0, 5))
    h.plane("Small", size=1.0, material=h.diffuse("Grey"))  # covers the centre only
    h.light("POINT", location=(0, 0, 3), energy=200)
    h.world(color=(0.2, 0.3, 0.4), strength=1.0)
    s = h.setup_render(W, H, samples=2)
    s.ercuts.film_transparent = True
    img = h.render_exr(tmp_path / "transparent.exr")
    assert img[H // 2, W // 2, 3] == pytest.approx(1.0)  # the plane
    assert img[0, 0, 3] == pytest.approx(0.0)  # the world
    s.ercuts.film_transparent = False
    img = h.render_exr(tmp_path / "opaque.exr")
    assert img[0, 0, 3] == pytest.approx(1.0)
