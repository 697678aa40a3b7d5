"""Exporter side of glass and mirrors (issue 15): Principled Transmission/IOR, Glossy, Glass,
Refraction and their mixes → the ``transmission``/``ior`` row constants and program outputs.

Materials are built with bpy, compiled with the add-on; programs are evaluated with the
core's program evaluator. Runs under bpy 5.x (pytest) and Blender 3.4 (blender -b).
"""
from __future__ import annotations

import json

import bpy
import numpy as np
import pytest

import blender_helpers as h
from addon import compat
from addon.export.images import TextureCollector
from addon.export.shaders import compile_material

V = bpy.app.version


def _material(name, shader, **inputs):
    mat = h.node_material(name, shader, **inputs)
    nt = mat.node_tree
    node = next(n for n in nt.nodes if n.type != "OUTPUT_MATERIAL")   # 4.x+: not by bl_idname
    return mat, nt, node


def _compile(mat):
    compiled = compile_material(mat, TextureCollector())
    program = json.loads(compiled.program) if compiled.program else None
    return compiled, program


def _evaluate(compiled, names):
    """The program's outputs ``names`` at one point, by the core's evaluator."""
    from ercuts_core.shading.geometry import MeshShading
    from ercuts_core.shading.program import compile_program
    from ercuts_core.shading.textures import TextureTable

    prog, notes = compile_program(compiled.program, "T", 0)
    assert prog is not None and notes == [], notes
    tri = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]])
    mesh = MeshShading(tri, None, None, np.zeros(1, int), TextureTable())
    n = np.array([[0.0, 0.0, 1.0]])
    ctx = mesh.context(np.zeros(1, int), np.array([[1 / 3] * 3]), n, n)
    return {k: v[0] for k, v in prog.evaluate(ctx, names).items()}


def _math(nt, op, a, b):
    node = nt.nodes.new("ShaderNodeMath")
    node.operation = op
    node.inputs[0].default_value, node.inputs[1].default_value = a, b
    return node


def _f32(x):
    return float(np.float32(x))


# --------------------------------------------------------------------------- Principled

def test_principled_transmission_and_ior():
    mat, _, _ = _material("Glassy", "ShaderNodeBsdfPrincipled", base_color=(0.9, 0.8, 0.7),
                          roughness=0.0, transmission=1.0, ior=1.45)
    compiled, program = _compile(mat)
    assert compiled.notes == [] and program is None        # constants say everything
    c = compiled.constants
    assert c["transmission"] == 1.0 and c["ior"] == pytest.approx(1.45, abs=1e-6)
    assert c["metallic"] == 0.0 and c["roughness"] == 0.0
    assert c["base_color"] == pytest.approx((0.9, 0.8, 0.7), abs=1e-6)
    # an opaque Principled: transmission 0, no note about it (it used to say "ignored")
    opaque, _, _ = _material("Opaque", "ShaderNodeBsdfPrincipled", transmission=0.0, ior=2.0)
    compiled, program = _compile(opaque)
    assert compiled.notes == [] and compiled.constants["transmission"] == 0.0
    # a partial weight is kept as it is (the core layers (1 − m)·t glass, as Cycles)
    half, _, _ = _material("Half", "ShaderNodeBsdfPrincipled", transmission=0.4, metallic=0.5)
    c = _compile(half)[0].constants
    assert c["transmission"] == pytest.approx(0.4, abs=1e-6) and c["metallic"] == 0.5


def test_principled_coat_still_noted_transmission_not():
    mat, _, _ = _material("Coated", "ShaderNodeBsdfPrincipled", transmission=1.0, coat=0.5)
    compiled, _ = _compile(mat)
    assert len(compiled.notes) == 1 and "coat" in compiled.notes[0]
    assert "transmission" not in compiled.notes[0].lower()


@pytest.mark.skipif(compat.PRINCIPLED_V4, reason="Transmission Roughness exists in 3.x only")
def test_principled_3x_transmission_roughness_is_noted():
    mat, _, node = _material("Frosted", "ShaderNodeBsdfPrincipled", transmission=1.0)
    node.inputs["Transmission Roughness"].default_value = 0.3
    compiled, _ = _compile(mat)
    assert len(compiled.notes) == 1 and "Transmission Roughness" in compiled.notes[0]
    # …but not where nothing transmits
    node.inputs["Transmission"].default_value = 0.0
    assert _compile(mat)[0].notes == []


def test_principled_textured_transmission_and_ior_are_program_outputs():
    mat, nt, bsdf = _material("TexGlass", "ShaderNodeBsdfPrincipled")
    nt.links.new(_math(nt, "MULTIPLY", 0.5, 0.5).outputs[0],
                 bsdf.inputs[compat.principled_socket_name("transmission")])
    nt.links.new(_math(nt, "ADD", 1.0, 0.33).outputs[0], bsdf.inputs["IOR"])
    compiled, program = _compile(mat)
    assert compiled.notes == [] and program is not None
    out = program["outputs"]
    assert isinstance(out["transmission"], dict) and isinstance(out["ior"], dict)
    assert program["nodes"][out["transmission"]["node"]]["params"]["operation"] == "MULTIPLY"
    got = _evaluate(compiled, ["transmission", "ior"])
    assert got["transmission"] == pytest.approx(0.25) and got["ior"] == pytest.approx(1.33, abs=1e-6)


def test_opaque_programs_have_no_glass_outputs():
    """A textured opaque material's program is as before: no transmission/ior outputs (the
    row constants, transmission 0, say it); a linked IOR on 3.x is not even read."""
    mat, nt, bsdf = _material("Rough", "ShaderNodeBsdfPrincipled")
    nt.links.new(_math(nt, "MULTIPLY", 0.5, 0.5).outputs[0], bsdf.inputs["Roughness"])
    compiled, program = _compile(mat)
    assert program is not None and "transmission" not in program["outputs"]
    assert "ior" not in program["outputs"] and compiled.constants["transmission"] == 0.0


# --------------------------------------------------------------------------- Glass, Refraction

def test_glass_bsdf_colour_roughness_ior():
    mat, _, node = _material("Glass", "ShaderNodeBsdfGlass", Color=(0.9, 0.7, 0.5),
                             Roughness=0.2, IOR=1.33)
    node.distribution = "GGX"
    compiled, program = _compile(mat)
    assert compiled.notes == [] and program is None
    c = compiled.constants
    assert c["base_color"] == pytest.approx((0.9, 0.7, 0.5), abs=1e-6)
    assert c["roughness"] == pytest.approx(0.2, abs=1e-6) and c["ior"] == pytest.approx(1.33, abs=1e-6)
    assert c["transmission"] == 1.0 and c["metallic"] == 0.0 and c["specular"] == 0.5
    node.distribution = "BECKMANN"   # the core has GGX only
    compiled, _ = _compile(mat)
    assert len(compiled.notes) == 1 and "Beckmann" in compiled.notes[0]
    assert compiled.constants["roughness"] == pytest.approx(0.2, abs=1e-6)
    node.inputs["Roughness"].default_value = 0.0   # smooth: the distribution does not matter
    assert _compile(mat)[0].notes == []


def test_glass_textured_colour_keeps_transmission_constant():
    mat, nt, node = _material("Tinted", "ShaderNodeBsdfGlass", IOR=1.6)
    rgb = nt.nodes.new("ShaderNodeCombineXYZ")
    rgb.inputs[0].default_value, rgb.inputs[1].default_value = 0.2, 0.4
    nt.links.new(rgb.outputs[0], node.inputs["Color"])
    compiled, program = _compile(mat)
    out = program["outputs"]
    assert out["transmission"] == 1.0 and out["ior"] == pytest.approx(1.6, abs=1e-6)
    assert out["metallic"] == 0.0
    got = _evaluate(compiled, ["base_color", "transmission"])
    assert got["base_color"] == pytest.approx([0.2, 0.4, 0.0]) and got["transmission"] == 1.0


def test_glass_ior_below_one_is_noted_and_clamped():
    mat, _, _ = _material("Bubble", "ShaderNodeBsdfGlass", IOR=0.75)
    compiled, _ = _compile(mat)
    assert len(compiled.notes) == 1 and "IOR 0.75" in compiled.notes[0]
    assert compiled.constants["ior"] == 1.0


def test_refraction_bsdf_is_glass_with_a_note():
    mat, _, node = _material("Refr", "ShaderNodeBsdfRefraction", Color=(0.5, 1.0, 1.0), IOR=1.2)
    node.distribution = "GGX"
    compiled, program = _compile(mat)
    assert program is None
    assert len(compiled.notes) == 1 and "Refraction BSDF" in compiled.notes[0]
    assert "Glass" in compiled.notes[0] and "reflection" in compiled.notes[0]
    c = compiled.constants
    assert c["transmission"] == 1.0 and c["ior"] == pytest.approx(1.2, abs=1e-6)
    assert c["base_color"] == pytest.approx((0.5, 1.0, 1.0)) and c["metallic"] == 0.0


@pytest.mark.skipif(V >= (4, 0, 0), reason="the 'Sharp' distribution exists in 3.x only")
@pytest.mark.parametrize("shader", ["ShaderNodeBsdfGlossy", "ShaderNodeBsdfGlass",
                                    "ShaderNodeBsdfRefraction"])
def test_3x_sharp_distribution_is_roughness_zero(shader):
    mat, _, node = _material("Sharp", shader, Roughness=0.6)
    node.distribution = "SHARP"
    c = _compile(mat)[0].constants
    assert c["roughness"] == 0.0


# --------------------------------------------------------------------------- Glossy

def test_glossy_roughness_zero_is_a_mirror():
    mat, _, node = _material("Mirror", "ShaderNodeBsdfGlossy", Color=(0.9, 0.6, 0.3), Roughness=0.0)
    compiled, program = _compile(mat)
    assert compiled.notes == [] and program is None
    c = compiled.constants
    assert c["metallic"] == 1.0 and c["roughness"] == 0.0 and c["transmission"] == 0.0
    assert c["base_color"] == pytest.approx((0.9, 0.6, 0.3), abs=1e-6)


@pytest.mark.parametrize("distribution", ["GGX", "MULTI_GGX", "BECKMANN", "ASHIKHMIN_SHIRLEY"])
def test_glossy_distributions_map_to_ggx(distribution):
    mat, _, node = _material("Shiny", "ShaderNodeBsdfGlossy", Roughness=0.3)
    node.distribution = distribution
    compiled, _ = _compile(mat)
    assert compiled.constants["roughness"] == pytest.approx(0.3, abs=1e-6)
    assert compiled.constants["metallic"] == 1.0
    if distribution in {"GGX", "MULTI_GGX"}:
        assert compiled.notes == []
    else:
        assert len(compiled.notes) == 1 and "rendered as GGX" in compiled.notes[0]


def test_anisotropic_glossy_is_isotropic_with_a_note():
    if V >= (4, 0, 0):
        mat, _, node = _material("Brushed", "ShaderNodeBsdfGlossy", Roughness=0.4, Anisotropy=0.5)
    else:   # 3.x: its own node, anisotropy 0.5 by default
        mat, _, node = _material("Brushed", "ShaderNodeBsdfAnisotropic", Roughness=0.4)
        assert node.type == "BSDF_ANISOTROPIC"
    compiled, _ = _compile(mat)
    assert len(compiled.notes) == 1 and "anisotropy" in compiled.notes[0]
    c = compiled.constants
    assert c["metallic"] == 1.0 and c["roughness"] == pytest.approx(0.4, abs=1e-6)


def test_textured_glossy_roughness_is_a_program_output():
    mat, nt, node = _material("Scratched", "ShaderNodeBsdfGlossy")
    node.distribution = "GGX"
    nt.links.new(_math(nt, "MULTIPLY", 0.5, 0.4).outputs[0], node.inputs["Roughness"])
    compiled, program = _compile(mat)
    assert compiled.notes == [] and program["outputs"]["metallic"] == 1.0
    assert _evaluate(compiled, ["roughness"])["roughness"] == pytest.approx(0.2)


# --------------------------------------------------------------------------- Mix / Add

def _mix_glass_diffuse(fac):
    mat, nt, mix = _material("GlassMix", "ShaderNodeMixShader", Fac=fac)
    diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (1, 0, 0, 1)
    glass = nt.nodes.new("ShaderNodeBsdfGlass")
    glass.inputs["IOR"].default_value = 1.45
    glass.inputs["Color"].default_value = (1, 1, 1, 1)
    nt.links.new(diffuse.outputs[0], mix.inputs[1])
    nt.links.new(glass.outputs[0], mix.inputs[2])
    return mat, nt, mix


def test_mix_of_glass_and_diffuse_blends_transmission():
    mat, _, _ = _mix_glass_diffuse(0.3)
    compiled, program = _compile(mat)
    assert compiled.notes == [] and program is None
    c = compiled.constants
    assert c["transmission"] == pytest.approx(0.3)
    assert c["ior"] == pytest.approx(1.45, abs=1e-6)      # the glass's, not blended with 1.5
    assert c["base_color"] == pytest.approx((1.0, 0.3, 0.3))
    assert c["roughness"] == pytest.approx(0.7) and c["metallic"] == 0.0


def test_mix_with_textured_factor_blends_transmission_in_the_program():
    mat, nt, mix = _mix_glass_diffuse(0.5)
    nt.links.new(_math(nt, "MULTIPLY", 0.5, 0.5).outputs[0], mix.inputs["Fac"])
    compiled, program = _compile(mat)
    out = program["outputs"]
    assert isinstance(out["transmission"], dict) and out["ior"] == pytest.approx(1.45, abs=1e-6)
    got = _evaluate(compiled, ["transmission", "ior", "base_color"])
    assert got["transmission"] == pytest.approx(0.25) and got["ior"] == pytest.approx(1.45, abs=1e-6)
    assert got["base_color"] == pytest.approx([1.0, 0.25, 0.25])


def test_mix_of_two_glasses_blends_ior_and_glass_with_emission_keeps_it():
    mat, nt, mix = _material("TwoGlass", "ShaderNodeMixShader", Fac=0.25)
    a, b = nt.nodes.new("ShaderNodeBsdfGlass"), nt.nodes.new("ShaderNodeBsdfGlass")
    a.inputs["IOR"].default_value, b.inputs["IOR"].default_value = 1.2, 1.6
    nt.links.new(a.outputs[0], mix.inputs[1])
    nt.links.new(b.outputs[0], mix.inputs[2])
    c = _compile(mat)[0].constants
    assert c["transmission"] == 1.0 and c["ior"] == pytest.approx(0.75 * 1.2 + 0.25 * 1.6, abs=1e-6)
    # a side without a BSDF does not blend the BSDF parameters
    glow = nt.nodes.new("ShaderNodeEmission")
    nt.links.new(glow.outputs[0], mix.inputs[2])
    c = _compile(mat)[0].constants
    assert c["transmission"] == 1.0 and c["ior"] == pytest.approx(1.2, abs=1e-6)


def test_add_shader_glass_with_emission_and_with_diffuse():
    mat, nt, add = _material("AddGlass", "ShaderNodeAddShader")
    glass = nt.nodes.new("ShaderNodeBsdfGlass")
    glass.inputs["IOR"].default_value = 1.4
    glow = nt.nodes.new("ShaderNodeEmission")
    nt.links.new(glass.outputs[0], add.inputs[0])
    nt.links.new(glow.outputs[0], add.inputs[1])
    c = _compile(mat)[0].constants
    assert c["transmission"] == 1.0 and c["ior"] == pytest.approx(1.4, abs=1e-6)
    diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
    nt.links.new(diffuse.outputs[0], add.inputs[1])
    c = _compile(mat)[0].constants
    assert c["transmission"] == pytest.approx(0.5) and c["ior"] == pytest.approx(1.4, abs=1e-6)


def test_mix_with_transparent_keeps_glass_parameters():
    mat, nt, mix = _material("GlassCut", "ShaderNodeMixShader", Fac=0.5)
    glass = nt.nodes.new("ShaderNodeBsdfGlass")
    glass.inputs["IOR"].default_value = 1.5
    clear = nt.nodes.new("ShaderNodeBsdfTransparent")
    nt.links.new(glass.outputs[0], mix.inputs[1])
    nt.links.new(clear.outputs[0], mix.inputs[2])
    compiled, program = _compile(mat)
    assert program["outputs"]["alpha"] == 0.5 and program["outputs"]["transmission"] == 1.0
    assert compiled.constants["transmission"] == 1.0


# --------------------------------------------------------------------------- export

def test_exported_material_table_has_transmission_and_ior():
    h.camera()
    glass = h.node_material("Window", "ShaderNodeBsdfGlass", IOR=1.52)
    mirror = h.node_material("Mirror", "ShaderNodeBsdfGlossy", Roughness=0.0)
    h.plane("A", material=glass)
    h.plane("B", material=mirror, location=(0, 0, 1))
    h.plane("C", material=h.diffuse(), location=(0, 0, 2))
    exported = h.export()
    t = exported.description.materials
    assert exported.warnings == [] or not any("Window" in w or "Mirror" in w for w in exported.warnings)
    row = {n: i for i, n in enumerate(t.names)}
    assert t.transmission.dtype == np.float32 and t.ior.dtype == np.float32
    assert t.transmission[row["Window"]] == 1.0 and t.ior[row["Window"]] == _f32(1.52)
    assert t.metallic[row["Mirror"]] == 1.0 and t.roughness[row["Mirror"]] == 0.0
    assert t.transmission[row["Mirror"]] == 0.0 and t.transmission[row["Diffuse"]] == 0.0
