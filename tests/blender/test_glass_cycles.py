"""Glass and mirrors against Cycles, rendered by the same Blender (issue 15, exporter side):
a white perfect mirror (Glossy BSDF, roughness 0) and a white smooth glass sphere (Glass
BSDF, IOR 1.45) on a diffuse floor, where the exporter's mapping is exact (see
``addon/export/shaders.py``); uniform world light (and a point light for PATH). Cycles as in
``test_cycles_agreement.py``, plus Filter Glossy 0: Cycles' default (1.0) roughens glossy
and glass closures after a diffuse bounce, which renders the floor under the ball 8.8 %
darker (measured, PATH and BDPT alike) — the core has no such filter.
"""
from __future__ import annotations

import bpy
import numpy as np
import pytest

import blender_helpers as h
import ercuts_core  # noqa: F401  (a missing core must fail these tests)
import test_cycles_agreement as agreement

W, H = agreement.W, agreement.H


def _render_both(tmp_path, integrator, tag, samples=128, cycles_samples=512, max_depth=8):
    s = bpy.context.scene
    s.render.resolution_x, s.render.resolution_y = W, H
    s.render.resolution_percentage = 100
    s.ercuts.samples, s.ercuts.integrator, s.ercuts.max_depth = samples, integrator, max_depth
    s.ercuts.rough_samples = samples
    s.ercuts.seed = 0
    s.render.engine = "ERCUTS"
    ercuts = h.render_exr(tmp_path / f"{tag}_ercuts.exr")
    agreement._cycles(s, max_depth, cycles_samples, 0)
    s.cycles.blur_glossy = 0.0
    s.render.engine = "CYCLES"
    cycles = h.render_exr(tmp_path / f"{tag}_cycles.exr")
    return ercuts, cycles


def _assert_agree(e, c, rtol):
    agreement.assert_means_agree(e, c, rtol=rtol)
    bottom = np.s_[H * 2 // 3:, :]   # rows first: the floor in front of / under the object
    agreement.assert_means_agree(e[bottom], c[bottom], rtol=2 * rtol)


def _scene():
    h.camera(location=(0, -4, 2.2), target=(0, 0, 0.5))
    h.world((0.6, 0.7, 0.9), 1.0)
    h.box("Box", size=(0.8, 0.8, 0.8), location=(0.9, 0.6, 0.4),
          material=h.diffuse("Box", (0.8, 0.45, 0.2)))


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["PATH", "BDPT"])
def test_white_mirror_floor(tmp_path, integrator):
    _scene()
    mirror = h.node_material("Mirror", "ShaderNodeBsdfGlossy", Color=(1, 1, 1), Roughness=0.0)
    h.plane("Floor", size=3, material=mirror)
    if integrator == "PATH":
        # BDPT's light paths also reach the box via the mirror (a caustic of the point
        # light, 1.8 % of the red), which path tracers (PATH, Cycles) cannot sample
        h.light("POINT", location=(0, -0.5, 2.5), energy=300, shadow_soft_size=0)
    e, c = _render_both(tmp_path, integrator, "mirror")
    _assert_agree(e, c, rtol=0.01)


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["PATH", "BDPT"])
def test_white_glass_sphere(tmp_path, integrator):
    _scene()
    h.plane("Floor", size=8, material=h.diffuse("Floor", (0.8, 0.8, 0.8)))
    glass = h.node_material("Glass", "ShaderNodeBsdfGlass", Color=(1, 1, 1), Roughness=0.0, IOR=1.45)
    h.uv_sphere("Ball", radius=0.7, location=(-0.3, 0, 0.7), material=glass)
    e, c = _render_both(tmp_path, integrator, "glass")
    _assert_agree(e, c, rtol=0.01)
