"""Glass and mirrors against Cycles, rendered by the same Blender (issue 15, exporter side):
a white perfect mirror (Glossy BSDF, roughness 0) and a white smooth glass sphere (Glass
BSDF, IOR 1.45) on a diffuse floor, where the exporter's mapping is exact (see
``addon/export/shaders.py``); uniform world light (and a point light for the mirror).
PATH, BDPT and ERCUTS each against Cycles, four seeds per engine, compared block by block
(``cycles_stats``: 8×8-pixel block means, z-scores from the renders' own variance, χ² per
channel and Šidák on the largest |z|, family level 10⁻³).

Cycles as in ``test_cycles_agreement.py``, plus Filter Glossy 0: Cycles' default (1.0)
roughens glossy and glass closures after a diffuse bounce, which renders the floor under
the ball 8.8 % darker (measured, PATH and BDPT alike) — the core has no such filter.

The mirror's point light is left out for BDPT and ERCUTS: their light paths also reach the
box via the mirror (a caustic of the point light, 1.8 % of the red), which path tracers cannot
sample — Cycles and PATH. (Until stop 46 ERCUTS path-traced every path through a mirror or
smooth glass and agreed with Cycles there; since, its direct passes render such late paths by
BDPT, ``integrators/ercuts/late_paths.py``, and with the point light its box was 1.6 % redder
than Cycles', block mean z² 14.5.)
ERCUTS runs with bpy 5.x only (its renders are bit-identical in both Blenders; PATH and BDPT
compare Blender 3.4.1's Cycles). Measured numbers (seeds 1–4; "rel" = Ercuts / Cycles − 1 of
the image means in R, G, B) and those of a wrong parameter exported on purpose
(``ERCUTS_INJECT_ERROR=1``) are in each test's docstring. Before (one seed, the image means
within a hand-set 1 %) these were PATH and BDPT within 0.2 %.
"""
from __future__ import annotations

import bpy
import pytest

import blender_helpers as h
import ercuts_core  # noqa: F401  (a missing core must fail these tests)
from cycles_stats import INJECT, compare, render_seeds

pytestmark = pytest.mark.slow
V = bpy.app.version
GLASS = dict(samples=32, cycles_samples=128, max_depth=6)


def _scene():
    h.camera(location=(0, -4, 2.2), target=(0, 0, 0.5))
    h.world((0.6, 0.7, 0.9), 1.0)
    h.box("Box", size=(0.8, 0.8, 0.8), location=(0.9, 0.6, 0.4),
          material=h.diffuse("Box", (0.8, 0.45, 0.2)))


def _node(mat):
    return next(n for n in mat.node_tree.nodes if n.type != "OUTPUT_MATERIAL")


def mirror_scene(point_light: bool):
    _scene()
    mirror = h.node_material("Mirror", "ShaderNodeBsdfGlossy", Color=(1, 1, 1), Roughness=0.0)
    h.plane("Floor", size=3, material=mirror)
    if point_light:
        h.light("POINT", location=(0, -0.5, 2.5), energy=300, shadow_soft_size=0)


def glossy_floor_scene():
    """The mirror scene with a glossy floor (white Glossy BSDF, GGX, roughness 0.1)."""
    _scene()
    floor = h.node_material("GlossyFloor", "ShaderNodeBsdfGlossy", Color=(1, 1, 1), Roughness=0.1)
    _node(floor).distribution = "GGX"
    h.plane("Floor", size=3, material=floor)
    h.light("POINT", location=(0, -0.5, 2.5), energy=300, shadow_soft_size=0)


def glass_sphere_scene():
    _scene()
    h.plane("Floor", size=8, material=h.diffuse("Floor", (0.8, 0.8, 0.8)))
    glass = h.node_material("Glass", "ShaderNodeBsdfGlass", Color=(1, 1, 1), Roughness=0.0, IOR=1.45)
    h.uv_sphere("Ball", radius=0.7, location=(-0.3, 0, 0.7), material=glass)


def _skip_on_3x(integrator):
    if V < (4, 0, 0) and integrator == "ERCUTS":
        pytest.skip("ERCUTS with bpy 5.x only (CI time; the core renders are identical, only "
                    "Cycles differs, which PATH and BDPT compare)")


@pytest.mark.parametrize("integrator", ["PATH", "BDPT", "ERCUTS"])
def test_white_mirror_floor(tmp_path, integrator):
    """bpy 5.0.1: PATH rel −0.05/−0.02/−0.00 %, block mean z² 0.78, max |z| 2.03; BDPT
    −0.01/−0.00/+0.00 %, 1.06, 2.55; ERCUTS +0.03/+0.01/+0.00 %, 1.05, 2.86 with the point
    light until stop 46, passes without it since (module docstring). Blender 3.4.1:
    PATH 0.74, 2.03; BDPT 1.17, 2.57. Mirror colour 0.99 exported: every engine and Blender
    fails (the noise-free mirrored sky 1 % off: z = ∞); a colour 0.99 in *both* renderers
    fails too (z² 407: the core's metal rises to white at grazing angles, Cycles' Glossy does
    not — the documented gap for non-white Glossy)."""
    _skip_on_3x(integrator)
    mirror_scene(point_light=integrator == "PATH")
    tag = "mirror_lit" if integrator == "PATH" else "mirror"
    e, c = render_seeds(tmp_path, tag, integrator, **GLASS)
    result = compare(f"{tag}/{integrator}", e, c)
    assert result.passed, result.summary()


# ERCUTS normalises each VPL by its image energy Ê1, estimated by tracing the VPL's cosine
# emission one bounce to the camera (vpl.estimate_e1_light_tracing). Where the camera sees a
# sharp glossy lobe that estimate is heavy-tailed — mostly too small, 1/Ê1 too large: the
# VPL image was 24.4× P on this floor (×26 its indirect light, image mean ×3–4; roughness
# 0.05: ×880; 0.2: ×2.3). Now the gather follows the camera through such polished metals
# (Bsdf.is_specular_or_glass: below roughness 0.5 until stop 44, every metal since) and the
# chains and Ê1 leave them out.


@pytest.mark.parametrize("integrator", ["PATH", "BDPT", "ERCUTS"])
def test_white_glossy_floor(tmp_path, integrator):
    """A white GGX floor of roughness 0.1 (the mirror scene, with the point light for all).
    bpy 5.0.1: PATH rel +0.39/+0.21/+0.07 %, z² 1.05, max |z| 2.47; BDPT +0.59/+0.32/+0.12 %,
    1.10, 2.80; ERCUTS +1.95/+1.08/+0.42 %, 0.67, 1.55 (seeds 5–8: +0.2 %, 1.15, 2.25; 9–12:
    +1.3/+0.7/+0.3 %, 0.86, 2.21; before the gather followed polished metals: +322/+193/+86 %,
    3.51 (χ² p 6·10⁻¹⁷), 4.88). Blender
    3.4.1: PATH 0.92, 2.54; BDPT 0.94, 2.61. Roughness 0.13 exported: PATH z² 3.24, max |z|
    6.99 (3.4.1: 2.42, 6.94); BDPT 3.88, 6.60 (3.4.1: 2.98, 6.55) (fail)."""
    _skip_on_3x(integrator)
    glossy_floor_scene()
    e, c = render_seeds(tmp_path, "glossy_floor", integrator, **GLASS)
    result = compare(f"glossy_floor/{integrator}", e, c)
    assert result.passed, result.summary()


#: Measured (stop 38, core renders of this scene exported at 64×48, the 9×14-pixel front of
#: the orange box right of the sphere, grey level): Cycles 0.2932 ± 0.0001 (4 seeds); PATH
#: 1024 spp 0.2935 (direct 0.1649, indirect 0.1286); ERCUTS with one shading point per pixel
#: 0.2880 ± 0.0011 (32 seeds; direct 0.1645 — its indirect 3–5 % low); with four 0.2862 ±
#: 0.0012 (32 seeds). The VPL image's energy was 0.978 ± 0.003 of P over 12 seeds
#: (``vpl_energy_ratio``), with or without the clamp. Stop 39 found most of it: the shaky
#: VPLs' Ê1 (vpl._redraw_shaky) was corrected for Jensen's bias with a relative variance
#: taken from the very samples it corrected — 0.974 ± 0.004 → 0.991 ± 0.004 (8 seeds); the
#: block with four points 0.2895 ± 0.0011 (16 seeds; indirect 0.1247), one point 0.2886 ±
#: 0.0017, one point with 4096 Ê1 samples per VPL 0.2909 ± 0.0018. This test: seeds 1–4
#: max |z| 2.79, 9–12 2.35, 13–16 2.64, 17–20 pass; 5–8 fail (the box's blocks z −5.5 and
#: −4.0): the box's indirect light is still ≈ 3 % low (issue 15). Stop 42 (core, 64×48, the
#: test's settings): ``vpl_energy_ratio`` over seeds 1–24 0.9935 ± 0.0033 (median 0.9954); the
#: box's gathered indirect light 0.0844 ± 0.002 (8 seeds) against PATH's 0.0859, so today's gap
#: is ≈ 1–2 %, and it does not shrink as 1/N with more Ê1 samples (vpl.jackknife_e1's docstring).
GLASS_GAP = ("ERCUTS's indirect light on the box is 1–3 % low (block 0.2895 ± 0.0011 against "
             "0.2932 at stop 39; VPL image 0.9935 ± 0.0033 of P over 24 seeds at stop 42); "
             "seeds 5–8 fail, 1–4 and 9–20 pass (numbers above)")


@pytest.mark.parametrize("integrator", ["PATH", "BDPT", pytest.param(
    "ERCUTS", marks=pytest.mark.xfail(reason=GLASS_GAP, strict=False))])
def test_white_glass_sphere(tmp_path, integrator):
    """bpy 5.0.1: PATH rel −0.10/−0.11/−0.11 %, z² 0.80, max |z| 1.97; BDPT −0.08 %, 0.76,
    2.01; ERCUTS −0.05/−0.10/−0.13 %, 0.77, 2.41 (its correlated noise inflates the block
    variance 2.4×). Blender 3.4.1: PATH 0.84, 2.51; BDPT 0.75, 2.01. IOR 1.33 exported: PATH
    z² 7.23, max |z| 10.7 (3.4.1: 7.35); BDPT 7.27, 10.9 (3.4.1: 7.25); ERCUTS 4.28, 8.04
    (fail). The resolution: IOR 1.40 (−0.2 % in the mean) fails BDPT (z² 2.35) and ERCUTS
    (2.67) but not PATH (1.75, χ² p 10⁻³ against the 1.7·10⁻⁴ level)."""
    _skip_on_3x(integrator)
    glass_sphere_scene()
    e, c = render_seeds(tmp_path, "glass", integrator, **GLASS)
    result = compare(f"glass/{integrator}", e, c)
    assert result.passed, result.summary()


def _set(socket, value):
    """Inject: set ``socket`` to ``value``; returns the undo (a copy of the old value: a colour
    socket's default_value is a live view)."""
    old = socket.default_value
    old = tuple(old) if hasattr(old, "__len__") else old
    socket.default_value = value
    return lambda: setattr(socket, "default_value", old)


@pytest.mark.skipif(not INJECT, reason="error injection: run with ERCUTS_INJECT_ERROR=1")
@pytest.mark.parametrize("integrator", ["PATH", "BDPT", "ERCUTS"])
def test_white_mirror_floor_detects_a_grey_mirror(tmp_path, integrator):
    _skip_on_3x(integrator)
    mirror_scene(point_light=integrator == "PATH")
    tag = "mirror_lit" if integrator == "PATH" else "mirror"
    colour = _node(bpy.data.materials["Mirror"]).inputs["Color"]
    e, c = render_seeds(tmp_path, tag, integrator, inject=lambda: _set(colour, (0.99, 0.99, 0.99, 1)),
                        **GLASS)
    assert not compare(f"{tag}/{integrator}, mirror colour 0.99 exported", e, c).passed


@pytest.mark.skipif(not INJECT, reason="error injection: run with ERCUTS_INJECT_ERROR=1")
@pytest.mark.parametrize("integrator", ["PATH", "BDPT"])
def test_white_glossy_floor_detects_a_wrong_roughness(tmp_path, integrator):
    _skip_on_3x(integrator)
    glossy_floor_scene()
    roughness = _node(bpy.data.materials["GlossyFloor"]).inputs["Roughness"]
    e, c = render_seeds(tmp_path, "glossy_floor", integrator, inject=lambda: _set(roughness, 0.13), **GLASS)
    assert not compare(f"glossy_floor/{integrator}, roughness 0.13 exported", e, c).passed


@pytest.mark.skipif(not INJECT, reason="error injection: run with ERCUTS_INJECT_ERROR=1")
@pytest.mark.parametrize("integrator", ["PATH", "BDPT", "ERCUTS"])
def test_white_glass_sphere_detects_a_wrong_ior(tmp_path, integrator):
    _skip_on_3x(integrator)
    glass_sphere_scene()
    ior = _node(bpy.data.materials["Glass"]).inputs["IOR"]
    e, c = render_seeds(tmp_path, "glass", integrator, inject=lambda: _set(ior, 1.33), **GLASS)
    assert not compare(f"glass/{integrator}, IOR 1.33 exported", e, c).passed
