"""Exporter side of the Translucent BSDF (issue 15): the node and its mixes → the
``translucency`` row constant and program output (mapping in ``addon/export/shaders.py``).

Runs under bpy 5.x (pytest) and Blender 3.4 (blender -b).
"""
from __future__ import annotations

import numpy as np
import pytest

import blender_helpers as h
from test_glass_export import _compile, _evaluate, _material, _math


def _translucent(nt, color=(0.8, 0.5, 0.3, 1.0)):
    node = nt.nodes.new("ShaderNodeBsdfTranslucent")
    node.inputs["Color"].default_value = color
    return node


def _mix(fac, a_type="ShaderNodeBsdfDiffuse", color=(0.8, 0.5, 0.3, 1.0)):
    """Mix(A, Translucent, fac), A a Diffuse (or Glass) BSDF of ``color``."""
    mat, nt, mix = _material("MixT", "ShaderNodeMixShader", Fac=fac)
    a = nt.nodes.new(a_type)
    a.inputs["Color"].default_value = color
    nt.links.new(a.outputs[0], mix.inputs[1])
    nt.links.new(_translucent(nt, color).outputs[0], mix.inputs[2])
    return mat, nt, mix


def test_translucent_bsdf_is_the_translucent_lobe():
    mat, _, node = _material("Velvet", "ShaderNodeBsdfTranslucent", Color=(0.8, 0.5, 0.3, 1.0))
    compiled, program = _compile(mat)
    assert compiled.notes == [] and program is None          # no "unsupported" note any more
    c = compiled.constants
    assert c["translucency"] == 1.0 and c["transmission"] == 0.0
    assert c["base_color"] == pytest.approx((0.8, 0.5, 0.3))
    assert c["roughness"] == 1.0 and c["metallic"] == 0.0 and c["specular"] == 0.0


def test_translucent_normal_input_makes_a_program():
    mat, nt, node = _material("Bumpy", "ShaderNodeBsdfTranslucent")
    bump = nt.nodes.new("ShaderNodeBump")
    nt.links.new(bump.outputs["Normal"], node.inputs["Normal"])
    compiled, program = _compile(mat)
    out = program["outputs"]
    assert out["translucency"] == 1.0 and out["normal"] is not None


@pytest.mark.parametrize("fac", [0.0, 0.3, 1.0])
def test_mix_with_diffuse_blends_translucency(fac):
    mat, _, _ = _mix(fac)
    compiled, program = _compile(mat)
    assert compiled.notes == [] and program is None
    c = compiled.constants
    assert c["translucency"] == pytest.approx(fac) and c["base_color"] == pytest.approx((0.8, 0.5, 0.3))


def test_mix_with_glass_shares_add():
    """Mix(Glass, Translucent, 0.4): transmission 0.6 and translucency 0.4 (the core's shares
    add: no opaque part left)."""
    mat, _, _ = _mix(0.4, "ShaderNodeBsdfGlass")
    c = _compile(mat)[0].constants
    assert c["transmission"] == pytest.approx(0.6) and c["translucency"] == pytest.approx(0.4)


def test_textured_factor_is_a_program_output():
    mat, nt, mix = _mix(0.5)
    nt.links.new(_math(nt, "MULTIPLY", 0.5, 0.5).outputs[0], mix.inputs["Fac"])
    compiled, program = _compile(mat)
    assert isinstance(program["outputs"]["translucency"], dict)
    assert "transmission" not in program["outputs"]
    got = _evaluate(compiled, ["translucency", "base_color"])
    assert got["translucency"] == pytest.approx(0.25)
    assert compiled.constants["translucency"] == pytest.approx(0.25)


def test_add_shader_and_emission_mix():
    mat, nt, add = _material("AddT", "ShaderNodeAddShader")
    d = nt.nodes.new("ShaderNodeBsdfDiffuse")
    d.inputs["Color"].default_value = (0.3, 0.3, 0.3, 1.0)
    nt.links.new(d.outputs[0], add.inputs[0])
    nt.links.new(_translucent(nt, (0.3, 0.3, 0.3, 1.0)).outputs[0], add.inputs[1])
    c = _compile(mat)[0].constants
    assert c["translucency"] == pytest.approx(0.5) and c["base_color"] == pytest.approx((0.6,) * 3)
    glow = nt.nodes.new("ShaderNodeEmission")          # a side without a BSDF keeps the other's
    nt.links.new(glow.outputs[0], add.inputs[0])
    c = _compile(mat)[0].constants
    assert c["translucency"] == 1.0


def test_opaque_programs_have_no_translucency_output():
    mat, nt, node = _material("Tex", "ShaderNodeBsdfDiffuse")
    nt.links.new(_math(nt, "MULTIPLY", 0.5, 0.5).outputs[0], node.inputs["Color"])
    _, program = _compile(mat)
    assert "translucency" not in program["outputs"]


def test_exported_material_table_has_translucency():
    h.camera()
    h.plane("A", material=h.node_material("Velvet", "ShaderNodeBsdfTranslucent"))
    h.plane("B", material=h.diffuse(), location=(0, 0, 1))
    exported = h.export()
    assert not any("Velvet" in w for w in exported.warnings), exported.warnings
    t = exported.description.materials
    row = {n: i for i, n in enumerate(t.names)}
    assert t.translucency.dtype == np.float32
    assert t.translucency[row["Velvet"]] == 1.0 and t.translucency[row["Diffuse"]] == 0.0
