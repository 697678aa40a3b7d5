"""Rough glass and glossy lobes against Cycles in the same Blender (issue 15, tests).

Three scenes, each rendered by PATH, BDPT and ERCUTS and by Cycles over four seeds, compared
block by block (``cycles_stats``: 8×8-pixel block means, z-scores from the renders' own
variance, χ² over the blocks per channel and Šidák on the largest |z|, family level 10⁻³):

* a rough glass sphere (Glass BSDF, GGX, roughness 0.3, IOR 1.5) on a floor, lit by a 3 m
  emissive panel above;
* Veach's glossy sweep: five white Glossy plates (GGX) of roughness 0, 0.15, 0.3, 0.55 and 1
  reflecting four sphere lights (point lights of radius 0.02–0.4 m);
* a lamp behind frosted glass: an emissive bulb behind a rough glass pane (roughness 0.6)
  lighting a floor and a block in front of it;

and the transmittance of a rough slab, which pins the two Cycles gaps below.

What is compared, and why the scenes look as they do:

* Cycles' Glass and Glossy are set to 'GGX' (Blender ≥ 4.0 defaults to Multiscatter GGX,
  3.x Glass to Beckmann; the core has single-scattering GGX), white (Cycles' Glossy has no
  Fresnel — the core's metal rises to white at grazing angles, exact for white — and Cycles
  tints a glass's reflection too), Filter Glossy 0, caustics on.
* The lights of the glass scenes are emissive meshes that Cycles does not light-sample
  (``cycles_stats.unsampled_emission``): Cycles evaluates its rough-glass BSDF for
  refraction configurations that no microfacet produces (``bsdf_microfacet_eval``: "TODO:
  check if the refraction configuration is valid"), so its *light samples* at a rough-glass
  vertex add light that its BSDF samples never find. A slab of roughness 0.6 over an emitter
  seen at 45° transmits 0.6308 ± 0.0005 in Cycles 5.0 when the emitter is only hit by BSDF
  rays and 0.6506 ± 0.0005 (+3.1 %) when it is also light-sampled; the core gives
  0.6313 ± 0.0018 (``test_rough_slab_transmittance``). Cycles' estimate depends on its
  sampling strategy, so the comparison uses the strategy that has no such term.
* Rough glass is compared in Blender ≥ 4.0 only: Cycles 3.x's rough glass is another model
  (Fresnel at the shading normal, not the microfacet's; separable Smith G1·G1), and the
  slab's transmittance there is 0.5463 (−13 %). The glossy sweep runs in both Blenders
  (PATH in 3.4.1): there Cycles' separable G darkens the roughness-1 plate by 0.4 %
  (measured at 256 spp), below what these sample counts resolve.
* Light sources with a size are hidden from the camera (Blender's default), no floor under
  the glossy plates: ERCUTS's VPLs are Lambertian at a glossy x2 (README, known
  limitations), which lit a floor under the plates 20–40 % too bright (8×8 blocks at 6–9σ).
"""
from __future__ import annotations

import math

import bpy
import pytest
from mathutils import Vector

import blender_helpers as h
import ercuts_core  # noqa: F401  (a missing core must fail these tests)
from cycles_stats import INJECT, SEEDS, compare, render_seeds, unsampled_emission

V = bpy.app.version
pytestmark = pytest.mark.slow

# ERCUTS does not gather VPL light that reaches a rough-glass shading point from behind its
# surface (ercuts_core/integrators/ercuts/gather.py builds ShadingPoints without
# ``transmissive``, so the lightcuts' receiver cosine is max(0, n·ω) there), while the VPLs'
# normalisation Ê1 counts that light: a rough glass object seen by the camera renders dark.
ERCUTS_ROUGH_GLASS = pytest.mark.xfail(strict=True, reason=(
    "ERCUTS's gather drops VPL light arriving at rough glass from behind the surface "
    "(gather.py: ShadingPoints without transmissive): rough sphere −10 % in the image mean, "
    "8×8 block mean z² 516, the sphere black (bpy 5.0.1, 48×36, 64 spp)"))


#: ERCUTS, a strict xfail in the rough-glass scenes, renders two seeds with shorter phases
#: (CI time): it misses by 20σ and more either way.
ERCUTS_XFAIL = dict(seeds=SEEDS[:2], ercuts_settings=dict(
    rough_samples=8, direct_samples=16, chain_length=50, stochastic_passes=4, e1_samples=128))


def _extra(integrator):
    return ERCUTS_XFAIL if integrator == "ERCUTS" else {}


def _skip_rough_glass_on_3x():
    if V < (4, 0, 0):
        pytest.skip("Cycles 3.x's rough glass is another model (Fresnel at the shading normal, "
                    "Smith G1·G1): slab transmittance 0.5463 vs 0.6313 at 45° (module docstring)")


def _node(mat):
    return next(n for n in mat.node_tree.nodes if n.type != "OUTPUT_MATERIAL")


def _glass(name: str, roughness: float, ior: float = 1.5):
    mat = h.node_material(name, "ShaderNodeBsdfGlass", Color=(1, 1, 1), Roughness=roughness, IOR=ior)
    _node(mat).distribution = "GGX"
    return mat


def _glossy(name: str, roughness: float):
    mat = h.node_material(name, "ShaderNodeBsdfGlossy", Color=(1, 1, 1), Roughness=roughness)
    _node(mat).distribution = "GGX"
    return mat


def _set_input(mat, socket: str, value):
    """Inject: set ``socket`` of the material's shader to ``value``; returns the undo."""
    node = _node(mat)
    old = node.inputs[socket].default_value
    old = tuple(old) if hasattr(old, "__len__") else old      # a colour is a live view
    node.inputs[socket].default_value = value
    return lambda: setattr(node.inputs[socket], "default_value", old)


# --------------------------------------------------------------------------- rough glass sphere

def rough_sphere_scene():
    """Rough glass sphere on a grey floor, an orange box behind it, a 3 m emissive panel."""
    h.camera(location=(0, -3.2, 1.6), target=(0, 0, 0.45))
    h.plane("Floor", size=8, material=h.diffuse("Floor", (0.8, 0.8, 0.8)))
    h.box("Back", size=(0.6, 0.3, 1.2), location=(0.25, 1.0, 0.6),
          material=h.diffuse("Back", (0.8, 0.3, 0.1)))
    h.uv_sphere("Ball", radius=0.5, location=(0, 0, 0.5), material=_glass("RoughGlass", 0.3))
    panel = h.plane("Panel", size=3.0, location=(-0.6, -0.4, 2.6),
                    material=unsampled_emission("Panel", strength=2.0))
    panel.rotation_euler = (math.pi, 0, 0)       # facing down (emission is two-sided anyway)


SPHERE = dict(samples=32, cycles_samples=128, max_depth=5)


@pytest.mark.parametrize("integrator", ["PATH", "BDPT", pytest.param("ERCUTS", marks=ERCUTS_ROUGH_GLASS)])
def test_rough_glass_sphere_agrees_with_cycles(tmp_path, integrator):
    _skip_rough_glass_on_3x()
    rough_sphere_scene()
    e, c = render_seeds(tmp_path, "rough_sphere", integrator, **_extra(integrator), **SPHERE)
    result = compare(f"rough_sphere/{integrator}", e, c)
    assert result.passed, result.summary()


@pytest.mark.skipif(not INJECT, reason="error injection: run with ERCUTS_INJECT_ERROR=1")
@pytest.mark.parametrize("integrator", ["PATH", "BDPT"])
def test_rough_glass_sphere_detects_a_wrong_ior(tmp_path, integrator):
    _skip_rough_glass_on_3x()
    rough_sphere_scene()
    mat = bpy.data.materials["RoughGlass"]
    e, c = render_seeds(tmp_path, "rough_sphere", integrator,
                        inject=lambda: _set_input(mat, "IOR", 1.4), **SPHERE)
    assert not compare(f"rough_sphere/{integrator}, IOR 1.4 exported", e, c).passed


# --------------------------------------------------------------------------- glossy sweep (Veach)

SWEEP_ROUGHNESS = (0.0, 0.15, 0.3, 0.55, 1.0)
SWEEP_RADII = (0.02, 0.08, 0.2, 0.4)


def glossy_sweep_scene():
    """Veach's multiple-importance test scene: glossy plates of increasing roughness (front to
    back), each turned to reflect a row of four sphere lights of increasing radius toward
    the camera; a dark back wall, black world."""
    cam = Vector((0, -2.6, 1.25))
    h.camera(location=cam, target=(0, 0.25, 0.62), lens=35)
    lights = Vector((0, -0.8, 2.6))
    colours = [(1, 0.4, 0.3), (1, 0.9, 0.3), (0.4, 1, 0.4), (0.4, 0.6, 1)]
    for i, (radius, colour) in enumerate(zip(SWEEP_RADII, colours)):
        ob = h.light("POINT", location=(-0.75 + 0.5 * i, lights.y, lights.z), energy=30,
                     color=colour, shadow_soft_size=radius, name=f"Sphere{i}")
        ob.visible_camera = False
    n = len(SWEEP_ROUGHNESS)
    for i, roughness in enumerate(SWEEP_ROUGHNESS):
        t = i / (n - 1)
        c = Vector((0, -0.35 + 0.75 * t, 0.15 + 0.85 * t))
        normal = ((cam - c).normalized() + (lights - c).normalized()).normalized()
        plate = h.plane(f"Plate{i}", size=1.0, location=c, material=_glossy(f"Glossy{i}", roughness))
        plate.scale = (2.2, 0.32, 1.0)
        plate.rotation_euler = normal.to_track_quat("Z", "Y").to_euler()
    wall = h.plane("Wall", size=6, location=(0, 2.6, 1.5), material=h.diffuse("Wall", (0.2, 0.2, 0.2)))
    wall.rotation_euler = (math.pi / 2, 0, 0)


SWEEP = dict(samples=32, cycles_samples=64, max_depth=2)


@pytest.mark.parametrize("integrator", ["PATH", "BDPT", "ERCUTS"])
def test_glossy_sweep_agrees_with_cycles(tmp_path, integrator):
    if V < (4, 0, 0) and integrator != "PATH":
        pytest.skip("Blender 3.x: PATH only (CI time; the core renders are identical)")
    glossy_sweep_scene()
    e, c = render_seeds(tmp_path, "glossy_sweep", integrator, **SWEEP)
    result = compare(f"glossy_sweep/{integrator}", e, c)
    assert result.passed, result.summary()


@pytest.mark.skipif(not INJECT, reason="error injection: run with ERCUTS_INJECT_ERROR=1")
@pytest.mark.parametrize("integrator", ["PATH", "BDPT", "ERCUTS"])
def test_glossy_sweep_detects_a_wrong_roughness(tmp_path, integrator):
    if V < (4, 0, 0) and integrator != "PATH":
        pytest.skip("Blender 3.x: PATH only")
    glossy_sweep_scene()
    mat = bpy.data.materials["Glossy3"]
    e, c = render_seeds(tmp_path, "glossy_sweep", integrator,
                        inject=lambda: _set_input(mat, "Roughness", 0.45), **SWEEP)
    assert not compare(f"glossy_sweep/{integrator}, plate 0.55 exported as 0.45", e, c).passed


# --------------------------------------------------------------------------- lamp behind frosted glass

def frosted_lamp_scene():
    """A bulb behind a frosted pane (rough glass slab, roughness 0.6) lights a floor, a wall
    and a blue block in front of the pane through it; seen at an angle."""
    h.camera(location=(1.6, -3.0, 1.5), target=(0.0, 0.3, 0.45), lens=35)
    h.plane("Floor", size=6, material=h.diffuse("Floor", (0.8, 0.8, 0.8)))
    wall = h.plane("Wall", size=6, location=(0, 2.0, 1.5), material=h.diffuse("Wall", (0.6, 0.6, 0.5)))
    wall.rotation_euler = (math.pi / 2, 0, 0)
    h.box("Pane", size=(1.4, 0.05, 1.1), location=(0, 0.5, 0.6), material=_glass("Frosted", 0.6))
    h.uv_sphere("Bulb", radius=0.15, location=(0, 0.85, 0.7),
                material=unsampled_emission("Bulb", (1.0, 0.9, 0.75), 40.0))
    h.box("Block", size=(0.3, 0.3, 0.3), location=(-0.3, -0.2, 0.15),
          material=h.diffuse("Block", (0.2, 0.4, 0.8)))


FROSTED = dict(samples=32, cycles_samples=128, max_depth=5)
#: BDPT: half the samples (three times PATH's cost per sample, less noise through the pane)
FROSTED_BDPT_SAMPLES = 16


@pytest.mark.parametrize("integrator", ["PATH", "BDPT", pytest.param("ERCUTS", marks=ERCUTS_ROUGH_GLASS)])
def test_lamp_behind_frosted_glass_agrees_with_cycles(tmp_path, integrator):
    _skip_rough_glass_on_3x()
    frosted_lamp_scene()
    settings = dict(FROSTED, samples=FROSTED_BDPT_SAMPLES) if integrator == "BDPT" else FROSTED
    e, c = render_seeds(tmp_path, "frosted_lamp", integrator, **_extra(integrator), **settings)
    result = compare(f"frosted_lamp/{integrator}", e, c)
    assert result.passed, result.summary()


@pytest.mark.skipif(not INJECT, reason="error injection: run with ERCUTS_INJECT_ERROR=1")
@pytest.mark.parametrize("integrator", ["PATH", "BDPT"])
def test_lamp_behind_frosted_glass_detects_a_wrong_roughness(tmp_path, integrator):
    _skip_rough_glass_on_3x()
    frosted_lamp_scene()
    mat = bpy.data.materials["Frosted"]
    settings = dict(FROSTED, samples=FROSTED_BDPT_SAMPLES) if integrator == "BDPT" else FROSTED
    e, c = render_seeds(tmp_path, "frosted_lamp", integrator,
                        inject=lambda: _set_input(mat, "Roughness", 0.5), **settings)
    assert not compare(f"frosted_lamp/{integrator}, roughness 0.5 exported", e, c).passed


# --------------------------------------------------------------------------- rough slab transmittance

def rough_slab_scene(light_sampled: bool):
    """An orthographic camera looks down through a rough glass slab (roughness 0.6, IOR 1.5,
    5 cm thick, tilted 45°) at a uniform emitter filling the lower hemisphere; black world:
    every pixel is the slab's directional transmittance (internal reflections included)."""
    cam = h.camera(location=(0, 0, 5), target=(0, 0, 0))
    cam.data.type, cam.data.ortho_scale = "ORTHO", 0.5
    slab = h.box("Slab", size=(4, 4, 0.05), material=_glass("Slab", 0.6))
    slab.rotation_euler = (math.radians(45), 0, 0)
    emitter = h.emission("Below", (1, 1, 1), 1.0) if light_sampled else unsampled_emission("Below")
    h.plane("Below", size=200, location=(0, 0, -1), material=emitter)


SLAB = dict(samples=128, cycles_samples=512, max_depth=8, size=(16, 16), seeds=SEEDS[:2],
            cycles_seeds=SEEDS[:2])
_SLAB_3X = ("Cycles 3.x's rough glass is another model (Fresnel at the shading normal, Smith "
            "G1·G1): transmittance 0.5463 (unsampled) / 0.5632 (light-sampled) vs the core's 0.6313")
_SLAB_OVERCOUNT = ("Cycles' light samples at a rough-glass vertex evaluate refraction configurations "
                   "no microfacet produces (bsdf_microfacet_eval, 'TODO: check if the refraction "
                   "configuration is valid'): transmittance 0.6506 light-sampled vs 0.6308 found by "
                   "BSDF sampling only (+3.1 %); the core 0.6313")


@pytest.mark.parametrize("light_sampled", [
    pytest.param(False, marks=pytest.mark.xfail(V < (4, 0, 0), strict=True, reason=_SLAB_3X)),
    pytest.param(True, marks=pytest.mark.xfail(strict=True, reason=_SLAB_OVERCOUNT if V >= (4, 0, 0) else _SLAB_3X)),
], ids=["bsdf_sampled", "light_sampled"])
def test_rough_slab_transmittance(tmp_path, light_sampled):
    """The slab's transmittance: PATH against Cycles, which finds the emitter by BSDF sampling
    only (``bsdf_sampled``) or also light-samples it (``light_sampled``, a Cycles gap: its
    estimate changes with the sampling strategy)."""
    rough_slab_scene(light_sampled)
    tag = f"slab_{'light' if light_sampled else 'bsdf'}"
    e, c = render_seeds(tmp_path, tag, "PATH", **SLAB)
    result = compare(f"{tag}/PATH", e, c, block=4)
    assert result.passed, result.summary()


@pytest.mark.skipif(not INJECT, reason="error injection: run with ERCUTS_INJECT_ERROR=1")
def test_rough_slab_detects_a_wrong_roughness(tmp_path):
    _skip_rough_glass_on_3x()
    rough_slab_scene(light_sampled=False)
    mat = bpy.data.materials["Slab"]
    e, c = render_seeds(tmp_path, "slab_bsdf", "PATH", inject=lambda: _set_input(mat, "Roughness", 0.55),
                        **SLAB)
    assert not compare("slab_bsdf/PATH, roughness 0.55 exported", e, c, block=4).passed
