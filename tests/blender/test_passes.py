"""Render passes: declared for the compositor, written to multilayer EXR, plausible content;
denoising through the compositor with the noisy image kept.

Scene: a camera 5 m above a large diffuse floor (albedo (0.6, 0.3, 0.2)) lit by a point
light, a small two-sided emitter 0.5 m above the floor in view, and a wall outside the
view that bounces light onto the floor (so Indirect is not empty).
"""
from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

import blender_helpers as h
import ercuts_core
from addon import compat, denoise, passes
from addon import engine as engine_module
from ercuts_core.result import RenderResult

W, H = 48, 32
FLOOR = (0.6, 0.3, 0.2)
CAM_HEIGHT = 5.0
TAN_HALF = 18.0 / 50.0  # default sensor 36 mm, lens 50 mm, horizontal fit


def _scene(samples=8, integrator="PATH"):
    h.camera(location=(0, 0, CAM_HEIGHT), target=(0, 0, 0))
    h.plane("Floor", size=20, material=h.diffuse("Floor", FLOOR))
    lamp = h.plane("Lamp", size=0.6, location=(1.0, 0.0, 0.5), material=h.emission(strength=5.0))
    lamp.rotation_euler = (math.pi, 0, 0)  # faces the floor; emitters are two-sided anyway
    wall = h.plane("Wall", size=6, location=(-2.5, 0, 1.5), material=h.diffuse("Wall"))
    wall.rotation_euler = (0, math.pi / 2, 0)
    h.light("POINT", location=(-1.0, 0.0, 3.0), energy=300)
    return h.setup_render(W, H, samples=samples, integrator=integrator)


def _enable_all(view_layer):
    for p in passes.PASSES:
        owner = view_layer if p.blender_toggle else view_layer.ercuts
        setattr(owner, p.toggle, True)


def _floor_depth():
    """(H, W) camera distance of every pixel centre's floor point (ray length, core's depth)."""
    ys, xs = np.mgrid[0:H, 0:W] + 0.5
    tx = TAN_HALF * (2 * xs / W - 1)
    ty = TAN_HALF * (H / W) * (1 - 2 * ys / H)
    return CAM_HEIGHT * np.sqrt(1 + tx ** 2 + ty ** 2)


def _lamp_mask():
    """Pixels that may see the emitter (its projection, widened by a pixel)."""
    mask = np.zeros((H, W), bool)
    px = lambda x, z: W / 2 * (1 + x / (CAM_HEIGHT - z) / TAN_HALF)  # noqa: E731
    py = lambda y, z: H / 2 * (1 - y / (CAM_HEIGHT - z) / (TAN_HALF * H / W))  # noqa: E731
    x0, x1 = int(px(0.7, 0.5)) - 1, int(px(1.3, 0.5)) + 2
    y0, y1 = int(py(0.3, 0.5)) - 1, int(py(-0.3, 0.5)) + 2
    mask[y0:y1, x0:x1] = True
    return mask


def test_passes_in_multilayer_exr_are_plausible(tmp_path):
    s = _scene()
    _enable_all(s.view_layers[0])
    ch = h.render_multilayer(tmp_path / "passes.exr")
    expected = {"Combined": "RGBA", "Depth": "Z", "Normal": "XYZ"}
    expected.update({p.name: p.chan_id for p in passes.PASSES})
    names = {f"ViewLayer.{name}.{c}" for name, chans in expected.items() for c in chans}
    assert set(ch) == names  # every pass exactly once, nothing else
    get = lambda name: h.layer_pass(ch, "ViewLayer", name, expected[name])  # noqa: E731

    floor = ~_lamp_mask()
    depth = get("Depth")[..., 0]
    np.testing.assert_allclose(depth[floor], _floor_depth()[floor], rtol=2e-3)
    assert np.all(depth[~floor] <= _floor_depth()[~floor] * (1 + 2e-3))  # pixel means
    assert depth[_lamp_mask()].min() < 0.95 * CAM_HEIGHT  # the emitter is nearer
    np.testing.assert_allclose(get("Albedo")[floor], np.broadcast_to(FLOOR, (floor.sum(), 3)),
                               atol=1e-5)
    np.testing.assert_allclose(get("Normal")[floor], np.broadcast_to((0, 0, 1), (floor.sum(), 3)),
                               atol=1e-5)

    combined = get("Combined")
    emission, direct, indirect = get("Emission"), get("Direct"), get("Indirect")
    np.testing.assert_allclose(emission + direct + indirect, combined[..., :3],
                               atol=1e-5 * combined.max())
    assert np.all(emission[floor] == 0) and emission[~floor].max() > 1.0
    # The lamp shadows the point light on the floor right of x ≈ 1 m (columns ≥ 37).
    assert direct[:, :34].min() > 0
    assert indirect[floor].mean() > 0 and indirect.min() >= 0
    for diagnostic in ("Cut Size", "VPL Density", "ER Caustic"):  # PATH has none: zeros
        assert not get(diagnostic).any()
    assert engine_module.last_render["warnings"] == []  # expected absences are not warned


def test_without_toggles_only_combined(tmp_path):
    _scene(samples=1)
    ch = h.render_multilayer(tmp_path / "combined.exr")
    assert set(ch) == {f"ViewLayer.Combined.{c}" for c in "RGBA"}


def _render_layers_outputs(scene):
    for view_layer in scene.view_layers:
        view_layer.update_render_passes()
    tree = compat.compositor_tree(scene)
    node = next((n for n in tree.nodes if n.bl_idname == "CompositorNodeRLayers"), None)
    node = node or tree.nodes.new("CompositorNodeRLayers")
    return {o.name for o in node.outputs if o.enabled}


def test_passes_declared_to_compositor():
    """update_render_passes → register_pass: the Render Layers node shows the toggled passes."""
    s = _scene()
    vl = s.view_layers[0]
    assert _render_layers_outputs(s) >= {"Image"}
    assert not _render_layers_outputs(s) & {"Albedo", "Cut Size", "Depth"}
    vl.ercuts.use_pass_albedo = True
    vl.ercuts.use_pass_cut_size = True
    vl.use_pass_z = True
    assert _render_layers_outputs(s) >= {"Albedo", "Cut Size", "Depth"}
    vl.ercuts.use_pass_albedo = False
    assert "Albedo" not in _render_layers_outputs(s)


def _no_aov_render(desc, settings=None, progress=None):
    from ercuts_core.camera import render_window

    w = render_window(desc.camera)
    image = np.full((w.height, w.width, 4), 0.5, np.float32)
    return RenderResult(image=image, window=w.rect,
                        full_size=(desc.camera.width, desc.camera.height))


def test_missing_aov_is_zero_and_warned(tmp_path, monkeypatch):
    monkeypatch.setattr(ercuts_core, "render", _no_aov_render)
    s = _scene()
    s.view_layers[0].ercuts.use_pass_albedo = True
    s.view_layers[0].ercuts.use_pass_cut_size = True
    ch = h.render_multilayer(tmp_path / "missing.exr")
    assert not h.layer_pass(ch, "ViewLayer", "Albedo", "RGB").any()
    np.testing.assert_allclose(h.layer_pass(ch, "ViewLayer", "Combined", "RGB"), 0.5)
    warnings = engine_module.last_render["warnings"]
    assert any("Albedo" in w for w in warnings)
    assert not any("Cut Size" in w for w in warnings)  # PATH never has it
    assert engine_module.last_render["missing_passes"] == ["Albedo", "Cut Size"]


def test_ercuts_diagnostic_passes(tmp_path):
    s = _scene(samples=2, integrator="ERCUTS")
    bpy.ops.ercuts.sampling_preset(preset="PREVIEW")
    s.ercuts.samples = s.ercuts.rough_samples = 2
    # VPLs on the lamp, which the camera sees (with direct light by light sampling the VPLs
    # are indirect only, at x2 on the wall, out of view: a density of 0 everywhere).
    s.ercuts.direct_light = "VPL"
    vl = s.view_layers[0]
    for toggle in ("use_pass_cut_size", "use_pass_vpl_density", "use_pass_er_caustic"):
        setattr(vl.ercuts, toggle, True)
    ch = h.render_multilayer(tmp_path / "diag.exr")
    cut = h.layer_pass(ch, "ViewLayer", "Cut Size", "X")[..., 0]
    density = h.layer_pass(ch, "ViewLayer", "VPL Density", "X")[..., 0]
    caustic = h.layer_pass(ch, "ViewLayer", "ER Caustic", "RGB")
    assert engine_module.last_render["missing_passes"] == []
    assert cut[~_lamp_mask()].min() >= 1  # every floor pixel evaluated a cut
    assert density.min() >= 0 and density.sum() > 0
    assert np.isfinite(caustic).all() and caustic.min() >= 0


def test_denoising_setup_and_noisy_pass(tmp_path):
    s = _scene(samples=2)
    warnings = denoise.setup_compositor(s)
    assert (denoise.NO_OIDN_WARNING in warnings) == (not compat.oidn_available())
    assert not [w for w in warnings if w != denoise.NO_OIDN_WARNING]
    tree = compat.compositor_tree(s, create=False)
    node = tree.nodes[denoise.DENOISE_NODE_NAME]
    linked = {link.to_socket.name: link.from_socket.name for link in tree.links
              if link.to_node == node}
    assert linked == {"Image": "Image", "Normal": "Normal", "Albedo": "Albedo"}
    assert any(link.from_node == node for link in tree.links)
    assert denoise.setup_compositor(s) == warnings  # idempotent
    assert sum(n.bl_idname == "CompositorNodeDenoise" for n in tree.nodes) == 1

    ch = h.render_multilayer(tmp_path / "noisy.exr")
    noisy = h.layer_pass(ch, "ViewLayer", "Noisy Image", "RGBA")
    np.testing.assert_array_equal(noisy, h.layer_pass(ch, "ViewLayer", "Combined", "RGBA"))
    assert {"ViewLayer.Normal.X", "ViewLayer.Albedo.R"} <= set(ch)  # guides without toggles
    assert (denoise.NO_OIDN_WARNING in engine_module.last_render["warnings"]) == \
        (not compat.oidn_available())


def _high_pass_energy(img):
    """Mean squared difference between ``img`` (h, w, 3) and its 3×3 box blur (interior)."""
    blur = sum(img[1 + dy:img.shape[0] - 1 + dy, 1 + dx:img.shape[1] - 1 + dx]
               for dy in (-1, 0, 1) for dx in (-1, 0, 1)) / 9
    return float(np.mean((img[1:-1, 1:-1] - blur) ** 2))


def test_composite_is_denoised_where_oidn_exists(tmp_path):
    s = _scene(samples=1)
    noisy = h.render_exr(tmp_path / "noisy.exr")[..., :3]
    denoise.setup_compositor(s)
    composite = h.render_exr(tmp_path / "denoised.exr")[..., :3]
    if compat.oidn_available():
        assert _high_pass_energy(composite) < 0.5 * _high_pass_energy(noisy)
        assert composite.mean() == pytest.approx(noisy.mean(), rel=0.1)
    else:  # the Denoise node passes the image through
        np.testing.assert_allclose(composite, noisy, atol=1e-6)


def test_passes_follow_border_crop(tmp_path):
    """Border render with crop: every pass covers the border window at its frame position."""
    s = _scene(samples=1)
    s.view_layers[0].use_pass_z = True
    s.view_layers[0].ercuts.use_pass_albedo = True
    s.render.use_border = s.render.use_crop_to_border = True
    s.render.border_min_x, s.render.border_max_x = 0.0, 0.5  # the left half: floor only
    s.render.border_min_y, s.render.border_max_y = 0.25, 0.75
    ch = h.render_multilayer(tmp_path / "border.exr")
    x1, yb0, yb1 = int(0.5 * W), int(0.25 * H), int(0.75 * H)
    depth = h.layer_pass(ch, "ViewLayer", "Depth", "Z")[..., 0]
    assert depth.shape == (yb1 - yb0, x1)
    # One sample per pixel lands anywhere in the pixel: allow half a pixel's depth change
    # in x and in y.
    fd = _floor_depth()
    half_pixel = 0.5 * (np.abs(np.diff(fd, axis=0)).max() + np.abs(np.diff(fd, axis=1)).max())
    np.testing.assert_allclose(depth, fd[H - yb1:H - yb0, :x1], atol=half_pixel + 1e-4)
    albedo = h.layer_pass(ch, "ViewLayer", "Albedo", "RGB")
    np.testing.assert_allclose(albedo.reshape(-1, 3), np.broadcast_to(FLOOR, (depth.size, 3)),
                               atol=1e-5)
