"""World → Environment Texture (HDRI): export (pixels, colour space, strength, Mapping and
Texture Coordinate, fallbacks) and agreement with Cycles on an HDRI-lit object.

The images are generated in the test (``bpy.data.images.new``): a 64×32 equirectangular
map with a dim sky and a hot spot, so that orientation errors (u/v flips, a wrong azimuth
origin or rotation order) move the light and its shadow.
"""
from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

import blender_helpers as h
from addon.export.images import srgb_to_linear
from test_cycles_agreement import assert_seed_pairs_agree, base_scene, render_both

W_MAP, H_MAP = 64, 32


def hot_spot_pixels(azimuth_deg: float = 30.0, elevation_deg: float = 35.0, sky=(0.25, 0.3, 0.4),
                    hot=(40.0, 32.0, 24.0), half=(4, 3)) -> np.ndarray:
    """(H, W, 4) RGBA, bottom row first: ``sky`` with a ``hot`` patch centred on the direction
    (azimuth from +X toward +Y, elevation), placed with Cycles' equirectangular mapping."""
    px = np.empty((H_MAP, W_MAP, 4), np.float32)
    px[..., :3], px[..., 3] = sky, 1.0
    u = 0.5 - math.radians(azimuth_deg) / (2 * math.pi)
    v = 0.5 + math.radians(elevation_deg) / math.pi
    j, i = int(u % 1.0 * W_MAP), int(v * H_MAP)
    cols = np.arange(j - half[0], j + half[0]) % W_MAP
    px[i - half[1]:i + half[1], cols, :3] = hot
    return px


def hdri_world(pixels: np.ndarray, strength: float = 1.0, rotation_deg=None, float_buffer=True,
               colorspace=None, coords: str | None = None):
    """A world Background ← Environment Texture [← Mapping] [← Texture Coordinate]."""
    w = h.world((0.5, 0.5, 0.5), strength)
    nt = w.node_tree
    bg = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeBackground")
    img = bpy.data.images.new("HDRI", pixels.shape[1], pixels.shape[0], float_buffer=float_buffer)
    if colorspace is not None:
        img.colorspace_settings.name = colorspace
    img.pixels.foreach_set(np.ascontiguousarray(pixels, np.float32).ravel())
    img.pack()
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = img
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    vec = env.inputs["Vector"]
    if rotation_deg is not None:
        mapping = nt.nodes.new("ShaderNodeMapping")
        mapping.inputs["Rotation"].default_value = [math.radians(a) for a in rotation_deg]
        nt.links.new(mapping.outputs["Vector"], vec)
        vec = mapping.inputs["Vector"]
    if coords is not None:
        tc = nt.nodes.new("ShaderNodeTexCoord")
        nt.links.new(tc.outputs[coords], vec)
    return w


def _map(exported):
    wm = exported.description.world_map
    assert wm is not None
    return wm


# --------------------------------------------------------------------------- export

def test_environment_texture_exports_pixels_times_strength():
    px = hot_spot_pixels()
    hdri_world(px, strength=2.5)
    h.camera()
    ex = h.export()
    wm = _map(ex)
    assert wm.radiance.shape == (H_MAP, W_MAP, 3) and wm.radiance.dtype == np.float32
    np.testing.assert_allclose(wm.radiance, px[..., :3] * 2.5, rtol=1e-6)   # bottom row first
    np.testing.assert_allclose(wm.rotation, np.eye(3), atol=1e-7)
    assert ex.warnings == [] and ex.has_emitters
    # The constant fallback is the map's solid-angle mean
    assert 0.25 * 2.5 < ex.description.world_radiance[0] < 40 * 2.5


def test_byte_srgb_image_is_linearised_and_non_color_is_not():
    px = np.full((8, 16, 4), 0.5, np.float32)
    hdri_world(px, float_buffer=False)
    h.camera()
    rad = _map(h.export()).radiance
    expect = float(srgb_to_linear(np.array([0.5]))[0])           # 0.214
    # Byte storage quantises 0.5 to 128/255 before the transfer function
    np.testing.assert_allclose(rad, srgb_to_linear(np.array([128 / 255]))[0], atol=1e-6)
    assert abs(expect - 0.214) < 1e-3
    bpy.ops.wm.read_factory_settings(use_empty=True)
    hdri_world(px, float_buffer=False, colorspace="Non-Color")
    h.camera()
    np.testing.assert_allclose(_map(h.export()).radiance, 128 / 255, atol=1e-6)


def test_mapping_without_input_is_one_texel_like_cycles():
    """Cycles feeds an unlinked Mapping input (0, 0, 0): the texel lookup at (u, v) = (0, 0),
    the mean of the four corner texels (bilinear, wrapping)."""
    px = hot_spot_pixels()
    px[0, 0, :3], px[-1, -1, :3] = (1.0, 2.0, 3.0), (3.0, 2.0, 1.0)
    hdri_world(px, rotation_deg=(0, 0, 90))
    h.camera()
    ex = h.export()
    assert ex.description.world_map is None and len(ex.warnings) == 1
    want = (px[0, 0, :3] + px[0, -1, :3] + px[-1, 0, :3] + px[-1, -1, :3]) / 4
    np.testing.assert_allclose(ex.description.world_radiance, want, rtol=1e-6)


@pytest.mark.parametrize("coords", ["Generated", "Object"])
def test_mapping_rotation_is_world_to_map(coords):
    hdri_world(hot_spot_pixels(), rotation_deg=(0, 0, 90), coords=coords)
    h.camera()
    ex = h.export()
    R = _map(ex).rotation
    # Mapping (Point) rotates the direction by R_z(90°): world +X looks up map +Y
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-6)
    np.testing.assert_allclose(R @ [0, 0, 1], [0, 0, 1], atol=1e-6)
    assert ex.warnings == []


def test_object_coordinates_apply_the_inverse_object_rotation():
    w = hdri_world(hot_spot_pixels(), rotation_deg=(0, 0, 90), coords="Object")
    empty = bpy.data.objects.new("Frame", None)
    bpy.context.scene.collection.objects.link(empty)
    empty.rotation_euler = (0, 0, math.radians(30))
    empty.scale = (2, 2, 2)
    tc = next(n for n in w.node_tree.nodes if n.bl_idname == "ShaderNodeTexCoord")
    tc.object = empty
    h.camera()
    ex = h.export()
    # Object coordinates rotate by −30°, the Mapping by +90°: +60° in all
    np.testing.assert_allclose(_map(ex).rotation @ [1, 0, 0],
                               [math.cos(math.radians(60)), math.sin(math.radians(60)), 0], atol=1e-6)
    assert ex.warnings == []


def test_euler_order_is_blenders():
    hdri_world(hot_spot_pixels(), rotation_deg=(30, 40, 50), coords="Generated")
    h.camera()
    from mathutils import Euler
    want = np.array(Euler([math.radians(a) for a in (30, 40, 50)], "XYZ").to_matrix())
    np.testing.assert_allclose(_map(h.export()).rotation, want, atol=1e-6)


def test_missing_image_is_magenta_with_one_warning():
    w = hdri_world(hot_spot_pixels(), strength=2.0)
    env = next(n for n in w.node_tree.nodes if n.bl_idname == "ShaderNodeTexEnvironment")
    env.image = None
    h.camera()
    ex = h.export()
    assert ex.description.world_map is None
    np.testing.assert_allclose(ex.description.world_radiance, (2.0, 0.0, 2.0))
    assert len(ex.warnings) == 1 and "missing" in ex.warnings[0] and "World" in ex.warnings[0]


def test_image_file_that_does_not_exist_is_magenta(tmp_path):
    w = hdri_world(hot_spot_pixels())
    env = next(n for n in w.node_tree.nodes if n.bl_idname == "ShaderNodeTexEnvironment")
    img = bpy.data.images.new("Gone", 4, 4)
    img.source = "FILE"
    img.filepath = str(tmp_path / "no_such_file.hdr")
    env.image = img
    h.camera()
    ex = h.export()
    assert ex.description.world_map is None
    np.testing.assert_allclose(ex.description.world_radiance, (1.0, 0.0, 1.0))
    assert len(ex.warnings) == 1 and "'Gone'" in ex.warnings[0]


def test_mirror_ball_and_sky_texture_fall_back_to_the_background_colour():
    w = hdri_world(hot_spot_pixels())
    env = next(n for n in w.node_tree.nodes if n.bl_idname == "ShaderNodeTexEnvironment")
    env.projection = "MIRROR_BALL"
    h.camera()
    ex = h.export()
    assert ex.description.world_map is None and len(ex.warnings) == 1
    np.testing.assert_allclose(ex.description.world_radiance, (0.5, 0.5, 0.5))


# --------------------------------------------------------------------------- Cycles

@pytest.mark.slow
@pytest.mark.parametrize("rotation, coords", [(None, None), ((0, 0, 120), "Generated"),
                                              ((20, 0, 60), "Object")])
def test_hdri_lit_object_agrees_with_cycles(tmp_path, rotation, coords):
    """Floor and box lit by the map alone (hot spot 30° azimuth, 35° up; with a Mapping
    rotation of 120° about Z the light comes from the other side; Object coordinates of an
    empty turned −70° about Z): BDPT vs Cycles, image means within 3 % and 8×8 block means
    within the noise (two seeds each)."""
    base_scene()
    w = hdri_world(hot_spot_pixels(), strength=1.0, rotation_deg=rotation, coords=coords)
    if coords == "Object":
        empty = bpy.data.objects.new("Frame", None)
        bpy.context.scene.collection.objects.link(empty)
        empty.rotation_euler = (0, 0, math.radians(-70))
        next(n for n in w.node_tree.nodes if n.bl_idname == "ShaderNodeTexCoord").object = empty
    runs = [render_both(tmp_path, max_depth=4, samples=64, cycles_samples=512, seed=seed,
                        tag=f"hdri_{coords}") for seed in (1, 2)]
    assert_seed_pairs_agree(runs, rtol=0.03, tag=f"hdri rotation={rotation}")
