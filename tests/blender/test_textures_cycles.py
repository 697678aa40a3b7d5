"""Textured materials agree with Cycles (issue 14): the exporter's programs, textures and UVs
rendered by the core next to Cycles in the same Blender.

A plane seen straight on by an orthographic camera, textured with a 2×2 sRGB image
(Closest), (a) as an emission (the pixel values are the linear texels: exact colour space
and UV orientation) and (b) as a diffuse under a sun (shading with the textured albedo).
Also a Mix Shader with a textured factor, a normal-mapped rotated plane (world-space
MikkTSpace tangents) and an alpha cutout. Quadrant means are compared. A core that does not
evaluate programs makes them skip, saying so (the probe: uniform quadrants).
"""
from __future__ import annotations

import bpy
import numpy as np
import pytest

import blender_helpers as h
import ercuts_core  # noqa: F401  (a missing core must fail these tests)
from test_cycles_agreement import render_both

pytestmark = pytest.mark.slow

#: 2×2 texels, row 0 = bottom: bottom-left red, bottom-right green, top-left blue, top-right white.
TEXELS = np.array([[[200, 30, 30, 255], [30, 200, 30, 255]],
                   [[30, 30, 200, 255], [255, 255, 255, 255]]], np.float32) / 255.0


def _linear(c):
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _image(name, texels, space="sRGB"):
    img = bpy.data.images.new(name, texels.shape[1], texels.shape[0], alpha=True)
    img.colorspace_settings.name = space
    img.pixels.foreach_set(np.asarray(texels, np.float32).reshape(-1))
    img.update()
    img.pack()  # keep the pixels when the image is re-read during the render
    return img


def _tex(nt, img):
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.interpolation = "Closest"
    return tex


def _scene(shader: str, material=None):
    if material is None:
        material = h.node_material("Tex", shader)
        nt = material.node_tree
        node = next(n for n in nt.nodes if n.bl_idname == shader)
        nt.links.new(_tex(nt, _image("Quadrants", TEXELS)).outputs["Color"], node.inputs["Color"])
    ob = h.plane("Plane", size=2.0, material=material)
    layer = ob.data.uv_layers.new(name="UVMap")
    corners = [(0, 0), (1, 0), (1, 1), (0, 1)]
    for loop in ob.data.loops:
        layer.data[loop.index].uv = corners[loop.vertex_index]
    cam = h.camera(location=(0, 0, 3), target=(0, 0, 0))
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 2.0
    h.world((0, 0, 0))
    return ob


def _quadrants(img):
    """Means of the four quadrants (top row first image): [[BL, BR], [TL, TR]] RGB."""
    hgt, wid = img.shape[:2]
    q = np.zeros((2, 2, 3))
    for i, rows in enumerate((slice(hgt // 2, hgt), slice(0, hgt // 2))):   # bottom, top
        for j, cols in enumerate((slice(0, wid // 2), slice(wid // 2, wid))):
            q[i, j] = img[rows, cols, :3].reshape(-1, 3).mean(axis=0)
    return q


#: Normal-map and bump cases: a delta sun, a diffuse plane, max_depth 1 and one texel per
#: quadrant make every pixel deterministic (zero estimator variance) in both renderers; the
#: measured differences are float32 rounding, ≤ 2.6e-5 relative (bpy 5.0.1 and Blender
#: 3.4.1). 1e-3 keeps a 40× margin and is 3.6× below the smallest model difference the tests
#: must see: Cycles 3.4's bump shadowing (Chiang 2019) darkens one quadrant by 0.36 %, 5.0's
#: (Estevez 2019) every quadrant by 1.2 % (ercuts_core/bump_shadowing.py).
NORMAL_RTOL, NORMAL_ATOL = 1e-3, 1e-4


def _skip_unless_textured(q):
    if np.ptp(q.reshape(-1, 3), axis=0).max() < 1e-3:
        pytest.skip("the core does not evaluate shading programs yet (uniform image)")


def test_textured_emission_matches_texels_and_cycles(tmp_path):
    _scene("ShaderNodeEmission")
    ercuts, cycles = render_both(tmp_path, max_depth=1, samples=4, cycles_samples=4,
                                 integrator="PATH", tag="tex_emission")
    qe, qc = _quadrants(ercuts), _quadrants(cycles)
    want = _linear(TEXELS[..., :3])
    print("ercuts", np.round(qe, 4).tolist(), "cycles", np.round(qc, 4).tolist())
    assert np.allclose(qc, want, rtol=0.02, atol=2e-3)      # the test's own premise
    _skip_unless_textured(qe)
    assert np.allclose(qe, want, rtol=0.02, atol=2e-3)


def test_linear_interpolation_of_srgb_texels_agrees_with_cycles(tmp_path):
    """The 2×2 sRGB image magnified with Linear interpolation (EXTEND): Cycles interpolates
    8-bit sRGB texels *encoded* and decodes after (compress_as_srgb); between the white and
    the blue texel that is up to 29 % darker than interpolating linear values. Means of 8×8
    blocks (8×6 pixels): the pixel-jitter noise of a block is ≤ 0.28 % at 64 spp (measured
    seed to seed: 0.56 % at 16 spp); interpolating linear values is off by up to 197 % in
    the dark channels of the middle blocks."""
    _scene("ShaderNodeEmission")
    tex = next(n for n in bpy.data.materials["Tex"].node_tree.nodes if n.type == "TEX_IMAGE")
    tex.interpolation, tex.extension = "Linear", "EXTEND"
    ercuts, cycles = render_both(tmp_path, max_depth=1, samples=64, cycles_samples=64,
                                 integrator="PATH", tag="tex_linear")
    be, bc = _blocks(ercuts, 8), _blocks(cycles, 8)
    print("max relative block difference", np.abs(be / bc - 1).max())
    assert np.allclose(be, bc, rtol=0.01, atol=1e-3)


@pytest.mark.parametrize("integrator", ["PATH", "BDPT", "ERCUTS"])
def test_textured_diffuse_under_sun_agrees_with_cycles(tmp_path, integrator):
    _scene("ShaderNodeBsdfDiffuse")
    h.light("SUN", location=(0, 0, 5), energy=3.0)
    ercuts, cycles = render_both(tmp_path, max_depth=1, samples=16, cycles_samples=16,
                                 integrator=integrator, tag=f"tex_diffuse_{integrator}")
    qe, qc = _quadrants(ercuts), _quadrants(cycles)
    print("ercuts", np.round(qe, 4).tolist(), "cycles", np.round(qc, 4).tolist())
    want = _linear(TEXELS[..., :3]) * 3.0 / np.pi               # albedo · E / π
    assert np.allclose(qc, want, rtol=0.03, atol=2e-3)          # the test's own premise
    _skip_unless_textured(qe)
    assert np.allclose(qe, qc, rtol=0.03, atol=2e-3)


@pytest.mark.parametrize("integrator", ["PATH", "BDPT", "ERCUTS"])
def test_mix_shader_with_textured_factor_agrees_with_cycles(tmp_path, integrator):
    """Mix(f = the texture's luminance, red diffuse, white diffuse) under a sun."""
    mat = h.node_material("Mixed", "ShaderNodeMixShader")
    nt = mat.node_tree
    mix = next(n for n in nt.nodes if n.type == "MIX_SHADER")
    red, white = nt.nodes.new("ShaderNodeBsdfDiffuse"), nt.nodes.new("ShaderNodeBsdfDiffuse")
    red.inputs["Color"].default_value = (0.8, 0.05, 0.05, 1)
    white.inputs["Color"].default_value = (0.9, 0.9, 0.9, 1)
    nt.links.new(_tex(nt, _image("Factor", TEXELS, "Non-Color")).outputs["Color"], mix.inputs[0])
    nt.links.new(red.outputs[0], mix.inputs[1])
    nt.links.new(white.outputs[0], mix.inputs[2])
    _scene("", material=mat)
    h.light("SUN", location=(0, 0, 5), energy=3.0)
    ercuts, cycles = render_both(tmp_path, max_depth=1, samples=16, cycles_samples=16,
                                 integrator=integrator, tag=f"tex_mix_{integrator}")
    qe, qc = _quadrants(ercuts), _quadrants(cycles)
    print("ercuts", np.round(qe, 4).tolist(), "cycles", np.round(qc, 4).tolist())
    f = TEXELS[..., :3] @ np.array([0.2126729, 0.7151522, 0.0721750])   # colour → float
    want = ((1 - f)[..., None] * [0.8, 0.05, 0.05] + f[..., None] * [0.9, 0.9, 0.9]) * 3.0 / np.pi
    assert np.allclose(qc, want, rtol=0.03, atol=2e-3)          # the test's own premise
    assert np.allclose(qe, qc, rtol=0.03, atol=2e-3)


@pytest.mark.parametrize("integrator,mirror", [("PATH", False), ("BDPT", False), ("ERCUTS", False),
                                                ("PATH", True)])
def test_normal_mapped_rotated_plane_agrees_with_cycles(tmp_path, integrator, mirror):
    """A constant tangent-space normal map tilting the normal towards +U, on a plane rotated
    about Z (world-space tangents) and lit by a sun from the side: cos θ follows the tilt."""
    mat = h.node_material("Bumpy", "ShaderNodeBsdfDiffuse", Color=(0.8, 0.8, 0.8))
    nt = mat.node_tree
    diffuse = next(n for n in nt.nodes if n.type == "BSDF_DIFFUSE")
    nmap = nt.nodes.new("ShaderNodeNormalMap")
    texel = np.zeros((2, 2, 4), np.float32)
    texel[...] = (0.8, 0.5, 0.9, 1.0)          # tangent-space normal (0.6, 0, 0.8) before normalising
    texel[1, :, :3] = (0.2, 0.5, 0.9)          # top half tilted the other way
    if mirror:                                 # tilts along V: the bitangent sign matters
        texel[0, :, :3] = (0.5, 0.8, 0.9)
        texel[1, :, :3] = (0.5, 0.2, 0.9)
    nt.links.new(_tex(nt, _image("N", texel, "Non-Color")).outputs["Color"], nmap.inputs["Color"])
    nt.links.new(nmap.outputs["Normal"], diffuse.inputs["Normal"])
    ob = _scene("", material=mat)
    ob.rotation_euler = (0, 0, np.pi)          # U now runs along world −X
    if mirror:                                 # negative scale: the bitangent sign flips
        ob.scale = (1.0, -1.0, 1.0)
    sun = h.light("SUN", location=(0, 0, 5), energy=3.0)
    sun.rotation_euler = (np.radians(40), 0, 0) if mirror else (0, np.radians(-40), 0)
    ercuts, cycles = render_both(tmp_path, max_depth=1, samples=16, cycles_samples=16,
                                 integrator=integrator, tag=f"tex_nmap_{integrator}_{mirror}")
    qe, qc = _quadrants(ercuts), _quadrants(cycles)
    print("ercuts", np.round(qe, 4).tolist(), "cycles", np.round(qc, 4).tolist())
    assert abs(qc[0, 0, 0] - qc[1, 0, 0]) > 0.1 * qc.max()     # the tilt is visible in Cycles
    assert np.allclose(qe, qc, rtol=NORMAL_RTOL, atol=NORMAL_ATOL)


@pytest.mark.parametrize("integrator", ["PATH", "BDPT", "ERCUTS"])
def test_alpha_cutout_agrees_with_cycles(tmp_path, integrator):
    """A plane cut out by its texture's alpha (Mix of Transparent and diffuse by Alpha) over a
    white floor, lit by a sun: the camera sees the floor through the holes, and the shadow."""
    mat = h.node_material("Leaf", "ShaderNodeMixShader")
    nt = mat.node_tree
    mix = next(n for n in nt.nodes if n.type == "MIX_SHADER")
    green = nt.nodes.new("ShaderNodeBsdfDiffuse")
    green.inputs["Color"].default_value = (0.1, 0.6, 0.1, 1)
    transparent = nt.nodes.new("ShaderNodeBsdfTransparent")
    texel = np.ones((2, 2, 4), np.float32)
    texel[0, 0, 3] = texel[1, 1, 3] = 0.0      # checkerboard holes
    nt.links.new(_tex(nt, _image("Cutout", texel)).outputs["Alpha"], mix.inputs[0])
    nt.links.new(transparent.outputs[0], mix.inputs[1])
    nt.links.new(green.outputs[0], mix.inputs[2])
    _scene("", material=mat)
    h.plane("Floor", size=20.0, location=(0, 0, -0.5), material=h.diffuse("Floor", (0.8, 0.8, 0.8)))
    sun = h.light("SUN", location=(0, 0, 5), energy=3.0)
    sun.rotation_euler = (np.radians(20), 0, 0)
    ercuts, cycles = render_both(tmp_path, max_depth=2, samples=32, cycles_samples=64,
                                 integrator=integrator, tag=f"tex_cutout_{integrator}")
    qe, qc = _quadrants(ercuts), _quadrants(cycles)
    print("ercuts", np.round(qe, 4).tolist(), "cycles", np.round(qc, 4).tolist())
    assert np.allclose(qe, qc, rtol=0.05, atol=5e-3)


_VIEW_REFLECTION_CLAMP = pytest.mark.xfail(
    bpy.app.version < (3, 6, 0), strict=True,
    reason="Cycles 3.0-3.5 bends every closure's normal so that the view's mirror reflection stays "
           "0.01 above the surface (ensure_valid_reflection); here the bump tilts the normal 45°, "
           "the head-on view's reflection grazes, and Cycles renders 0.14 % brighter; the core "
           "does not bend normals")


@pytest.mark.parametrize("distance", [0.5, pytest.param(2.0, marks=_VIEW_REFLECTION_CLAMP)])
def test_bump_from_uv_height_agrees_with_cycles(tmp_path, distance):
    """Bump with Height = U (a linear ramp: finite differences are exact whatever the offset),
    on a plane rotated about Z, lit by a sun from the side (Distance 2: a 45° tilt)."""
    mat = h.node_material("Bumped", "ShaderNodeBsdfDiffuse", Color=(0.8, 0.8, 0.8))
    nt = mat.node_tree
    diffuse = next(n for n in nt.nodes if n.type == "BSDF_DIFFUSE")
    coord, sep, bump = (nt.nodes.new(t) for t in ("ShaderNodeTexCoord", "ShaderNodeSeparateXYZ",
                                                  "ShaderNodeBump"))
    bump.inputs["Distance"].default_value = distance
    nt.links.new(coord.outputs["UV"], sep.inputs["Vector"])
    nt.links.new(sep.outputs["X"], bump.inputs["Height"])
    nt.links.new(bump.outputs["Normal"], diffuse.inputs["Normal"])
    ob = _scene("", material=mat)
    ob.rotation_euler = (0, 0, np.pi / 2)
    sun = h.light("SUN", location=(0, 0, 5), energy=3.0)
    sun.rotation_euler = (np.radians(30), 0, 0)
    ercuts, cycles = render_both(tmp_path, max_depth=1, samples=16, cycles_samples=16,
                                 integrator="PATH", tag=f"tex_bump_{distance}")
    qe, qc = _quadrants(ercuts), _quadrants(cycles)
    print("ercuts", np.round(qe, 4).tolist(), "cycles", np.round(qc, 4).tolist())
    flat = 0.8 * 3.0 / np.pi * np.cos(np.radians(30))
    assert abs(qc.mean() / flat - 1) > 0.05                    # the bump is visible in Cycles
    assert np.allclose(qe, qc, rtol=NORMAL_RTOL, atol=NORMAL_ATOL)


def _checker(n=8, a=(0.9, 0.9, 0.9), b=(0.1, 0.3, 0.8)):
    texels = np.ones((n, n, 4), np.float32)
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    texels[..., :3] = np.where(((ii + jj) % 2 == 0)[..., None], a, b)
    return texels


@pytest.mark.parametrize("integrator", ["PATH", "BDPT", "ERCUTS"])
def test_textured_room_with_indirect_light_agrees_with_cycles(tmp_path, integrator):
    """The base scene of the light tests with a checker-textured floor (box-projected UVs from
    Blender's own UV map) and an sRGB-textured box, lit by a point light, 4 bounces."""
    from test_cycles_agreement import assert_means_agree

    h.camera(location=(0, -4, 3), target=(0, 0, 0.3))
    floor_mat = h.node_material("Floor", "ShaderNodeBsdfDiffuse")
    nt = floor_mat.node_tree
    diffuse = next(n for n in nt.nodes if n.type == "BSDF_DIFFUSE")
    mapping = nt.nodes.new("ShaderNodeMapping")
    mapping.inputs["Scale"].default_value = (3.0, 3.0, 1.0)
    uv = nt.nodes.new("ShaderNodeUVMap")
    tex = _tex(nt, _image("Checker", _checker(), "sRGB"))
    nt.links.new(uv.outputs["UV"], mapping.inputs["Vector"])
    nt.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    nt.links.new(tex.outputs["Color"], diffuse.inputs["Color"])
    floor = h.plane("Floor", size=8, material=floor_mat)
    layer = floor.data.uv_layers.new(name="UVMap")
    for loop in floor.data.loops:
        layer.data[loop.index].uv = [(0, 0), (1, 0), (1, 1), (0, 1)][loop.vertex_index]
    # a Diffuse BSDF: 3.x's Principled diffuse is Burley's (retro-reflective), not the core's
    box_mat = h.node_material("Box", "ShaderNodeBsdfDiffuse")
    nt = box_mat.node_tree
    bsdf = next(n for n in nt.nodes if n.type == "BSDF_DIFFUSE")
    coord = nt.nodes.new("ShaderNodeTexCoord")
    tex = _tex(nt, _image("BoxTex", _checker(4, (0.8, 0.45, 0.2), (0.2, 0.7, 0.3)), "sRGB"))
    nt.links.new(coord.outputs["Generated"], tex.inputs["Vector"])
    nt.links.new(tex.outputs["Color"], bsdf.inputs["Color"])
    h.box("Box", size=(1, 1, 1), location=(0.3, 0.3, 0.5), material=box_mat)
    h.light("POINT", location=(0, -0.5, 2), energy=300, color=(1, 0.9, 0.8), shadow_soft_size=0)
    e, c = render_both(tmp_path, integrator=integrator, tag=f"tex_room_{integrator}")
    assert_means_agree(e, c, rtol=0.04)


def test_object_space_normal_map_on_a_rotated_plane_agrees_with_cycles(tmp_path):
    mat = h.node_material("ObjN", "ShaderNodeBsdfDiffuse", Color=(0.8, 0.8, 0.8))
    nt = mat.node_tree
    diffuse = next(n for n in nt.nodes if n.type == "BSDF_DIFFUSE")
    nmap = nt.nodes.new("ShaderNodeNormalMap")
    nmap.space = "OBJECT"
    texel = np.ones((2, 2, 4), np.float32)
    texel[0, :, :3] = (0.8, 0.5, 0.9)
    texel[1, :, :3] = (0.2, 0.5, 0.9)
    nt.links.new(_tex(nt, _image("ON", texel, "Non-Color")).outputs["Color"], nmap.inputs["Color"])
    nt.links.new(nmap.outputs["Normal"], diffuse.inputs["Normal"])
    ob = _scene("", material=mat)
    ob.rotation_euler = (0, 0, np.pi)
    sun = h.light("SUN", location=(0, 0, 5), energy=3.0)
    sun.rotation_euler = (0, np.radians(-40), 0)
    ercuts, cycles = render_both(tmp_path, max_depth=1, samples=16, cycles_samples=16,
                                 integrator="PATH", tag="tex_objn")
    qe, qc = _quadrants(ercuts), _quadrants(cycles)
    print("ercuts", np.round(qe, 4).tolist(), "cycles", np.round(qc, 4).tolist())
    assert abs(qc[0, 0, 0] - qc[1, 0, 0]) > 0.1 * qc.max()
    assert np.allclose(qe, qc, rtol=NORMAL_RTOL, atol=NORMAL_ATOL)


def _blocks(img, n=4):
    hgt, wid = img.shape[:2]
    return img[:hgt // n * n, :wid // n * n, :3].reshape(n, hgt // n, n, wid // n, 3).mean(axis=(1, 3))


@pytest.mark.parametrize("coords", ["Generated", "Object", "Normal"])
def test_object_space_coordinates_on_a_transformed_box_agree_with_cycles(tmp_path, coords):
    """Texture Coordinate Generated / Object / Normal on a rotated, scaled, moved box: the
    exporter maps the core's world position/normal into the object's space per object."""
    mat = h.node_material("Coords", "ShaderNodeBsdfDiffuse")
    nt = mat.node_tree
    diffuse = next(n for n in nt.nodes if n.type == "BSDF_DIFFUSE")
    coord = nt.nodes.new("ShaderNodeTexCoord")
    tex = _tex(nt, _image("Checker", _checker(4), "sRGB"))
    # faces must not lie on texel edges (which texel wins there is float rounding):
    # Generated is 0 or 1 on the faces (EXTEND keeps both sides in one texel), Object
    # coordinates are ±(0.8, 0.55, 0.35) (×4 texels: 3.2, 2.2, 1.4)
    tex.extension = "EXTEND" if coords == "Generated" else "REPEAT"
    if coords == "Normal":   # the normal's components as colour: (n + 1) / 2
        mapping = nt.nodes.new("ShaderNodeVectorMath")
        mapping.operation = "MULTIPLY_ADD"
        mapping.inputs[1].default_value = (0.5, 0.5, 0.5)
        mapping.inputs[2].default_value = (0.5, 0.5, 0.5)
        nt.links.new(coord.outputs["Normal"], mapping.inputs[0])
        nt.links.new(mapping.outputs["Vector"], diffuse.inputs["Color"])
    else:
        nt.links.new(coord.outputs[coords], tex.inputs["Vector"])
        nt.links.new(tex.outputs["Color"], diffuse.inputs["Color"])
    box = h.box("Box", size=(1.6, 1.1, 0.7), location=(0.3, -0.2, 0.5), material=mat)
    box.rotation_euler = (np.radians(20), np.radians(10), np.radians(35))
    box.scale = (1.2, 0.9, 1.1)
    h.camera(location=(2.5, -3.5, 3.0), target=(0.3, -0.2, 0.5))
    h.world((0.6, 0.6, 0.6))
    e, c = render_both(tmp_path, max_depth=1, samples=32, cycles_samples=64, integrator="PATH",
                       tag=f"tex_coords_{coords}")
    be, bc = _blocks(e), _blocks(c)
    print("max block difference", np.abs(be - bc).max(), "block mean", bc.mean())
    assert np.allclose(be, bc, rtol=0.06, atol=0.01)


_LOBE_GAP = pytest.mark.xfail(strict=True, reason=(
    "documented gap (README, Materials): the core's Principled is Lambert + one single-scattering "
    "GGX lobe with a constant dielectric F0; Cycles 4+ adds Multiscatter GGX energy and a "
    "Fresnel-weighted dielectric layer (measured here: -11 % rough metal, +3.2 % dielectric at "
    "roughness 0.2)"))


@pytest.mark.parametrize("metallic, roughness, distribution", [
    (1.0, 0.3, "GGX"), (1.0, 0.6, "GGX"), (0.5, 0.5, "GGX"),
    pytest.param(1.0, 0.6, "MULTI_GGX", marks=_LOBE_GAP),
    pytest.param(0.0, 0.2, "GGX", marks=_LOBE_GAP),
])
def test_principled_lobe_agrees_with_cycles(tmp_path, metallic, roughness, distribution):
    """A constant Principled floor under a sun seen at 37° (max_depth 1: every pixel is the
    BSDF times the sun's irradiance, no estimator noise but the pixel jitter). Metals with
    Cycles' single-scattering GGX agree to 0.01 % (measured); the xfails are the gap."""
    if bpy.app.version < (4, 0, 0):
        pytest.skip("Blender 3.x's Principled is Burley diffuse + Schlick (Principled v1)")
    mat = h.node_material("P", "ShaderNodeBsdfPrincipled", base_color=(0.6, 0.5, 0.4),
                          Roughness=roughness, Metallic=metallic)
    next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED").distribution = distribution
    h.plane("Floor", size=20, material=mat)
    h.camera(location=(0, -4, 3), target=(0, 0, 0))
    sun = h.light("SUN", location=(0, 0, 5), energy=3.0)
    sun.rotation_euler = (np.radians(-30), 0, 0)
    h.world((0, 0, 0))
    e, c = render_both(tmp_path, max_depth=1, samples=64, cycles_samples=256, integrator="PATH",
                       tag=f"lobe_{metallic}_{roughness}_{distribution}")
    me, mc = e[..., :3].mean(), c[..., :3].mean()
    print(f"principled metallic {metallic} roughness {roughness} {distribution}: rel {me / mc - 1:+.4f}")
    assert me == pytest.approx(mc, rel=0.005)
