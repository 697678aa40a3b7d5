"""A glTF file made in the test renders like Cycles (issue 14): a small textured scene is built
in bpy, written with Blender's glTF exporter, read back into an empty scene with its glTF
importer (the node patterns users' imported files have: Image Texture → Principled, Separate
Color for metallic/roughness, Normal Map, alpha clip by Math nodes, alpha blend), lit and
rendered by PATH, BDPT and ERCUTS next to Cycles in the same Blender.

Materials of the file: a checker floor with a tangent-space normal map and a roughness
texture (dielectric); a box whose metallic/roughness texture has metal and dielectric stripes;
a leaf cut out by its texture's alpha (MASK: the importer's 1 − (alpha < cutoff)) casting a
shadow; a pane with alpha 0.5 (BLEND). A point light and a dim world.

Neutralised differences (as the area-light visibility in test_cycles_agreement.py): the
imported Principled BSDFs get GGX instead of Multiscatter GGX and Specular IOR Level 0 (no
dielectric specular layer): the core's lobe model differs from Cycles' there (README,
Materials; test_textures_cycles.py::test_principled_lobe_agrees_with_cycles keeps the gap
visible). Metallic lobes, textures, UVs, tangents and alpha are all compared. Before the
sRGB-encoded texture rows, this scene was 3.4 % too bright in red (Linear interpolation of
the 8-bit checker in linear space) and a ray crossing both alpha surfaces raised an overflow
warning. Compared as the Cycles-agreement tests compare full transport: two seeds each,
8×8-block z-scores and the image means (measured: means within 0.8 %, mean z² 0.45-0.84).
"""
from __future__ import annotations

import addon_utils
import bpy
import numpy as np
import pytest

import blender_helpers as h
from addon import compat
import ercuts_core  # noqa: F401  (a missing core must fail these tests)
from test_cycles_agreement import assert_seed_pairs_agree, render_both

pytestmark = pytest.mark.slow

N = 32   # texels per side


def _png(tmp_path, name: str, rgba: np.ndarray, space: str):
    """An image saved as PNG (rows bottom first, as Blender stores pixels)."""
    img = bpy.data.images.new(name, rgba.shape[1], rgba.shape[0], alpha=True)
    img.colorspace_settings.name = space
    img.pixels.foreach_set(np.ascontiguousarray(rgba, np.float32).reshape(-1))
    img.filepath_raw = str(tmp_path / f"{name}.png")
    img.file_format = "PNG"
    img.save()
    return img


def _textures(tmp_path) -> dict:
    y, x = (np.mgrid[0:N, 0:N] + 0.5) / N
    checker = ((np.floor(4 * x) + np.floor(4 * y)) % 2)[..., None]
    one = np.ones((N, N, 1))
    base = np.concatenate([checker * [0.85, 0.8, 0.7] + (1 - checker) * [0.25, 0.35, 0.6], one], 2)
    # tangent-space normal map: ripples along U and V, tilts up to ≈ 25°
    tx, ty = 0.45 * np.sin(2 * np.pi * 2 * x), 0.3 * np.cos(2 * np.pi * 3 * y)
    n = np.stack([tx, ty, np.ones_like(tx)], 2)
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    normal = np.concatenate([n * 0.5 + 0.5, one], 2)
    floor_mr = np.concatenate([0 * one, (0.5 + 0.3 * x)[..., None], 0 * one, one], 2)   # G rough, B metal
    stripe = (np.floor(3 * x) % 2)[..., None]
    box_mr = np.concatenate([0 * one, 0.3 + 0.3 * stripe, stripe, one], 2)
    box_col = np.concatenate([stripe * [0.9, 0.6, 0.3] + (1 - stripe) * [0.7, 0.2, 0.2], one], 2)
    r = np.hypot(x - 0.5, y - 0.5)
    leaf = np.concatenate([np.broadcast_to([0.2, 0.6, 0.15], (N, N, 3)),
                           ((r < 0.45) & ((np.floor(6 * x) + np.floor(6 * y)) % 3 > 0))[..., None]], 2)
    pane = np.concatenate([np.broadcast_to([0.3, 0.5, 0.9], (N, N, 3)), 0.5 * one], 2)
    spec = {"base": (base, "sRGB"), "normal": (normal, "Non-Color"), "floor_mr": (floor_mr, "Non-Color"),
            "box_mr": (box_mr, "Non-Color"), "box_col": (box_col, "sRGB"), "leaf": (leaf, "sRGB"),
            "pane": (pane, "sRGB")}
    return {k: _png(tmp_path, k, px, space) for k, (px, space) in spec.items()}


def _principled(name, base_img, mr_img=None, normal_img=None, alpha=None):
    """Principled BSDF fed as glTF materials are: alpha None | 'MASK' (Math Round) | 'BLEND'."""
    mat = h.node_material(name, "ShaderNodeBsdfPrincipled")
    nt = mat.node_tree
    bsdf = next(n for n in nt.nodes if n.type == "BSDF_PRINCIPLED")

    def tex(img):
        node = nt.nodes.new("ShaderNodeTexImage")
        node.image = img
        return node

    col = tex(base_img)
    nt.links.new(col.outputs["Color"], bsdf.inputs["Base Color"])
    if mr_img is not None:
        sep = nt.nodes.new("ShaderNodeSeparateColor")
        nt.links.new(tex(mr_img).outputs["Color"], sep.inputs[0])
        nt.links.new(sep.outputs[1], bsdf.inputs["Roughness"])
        nt.links.new(sep.outputs[2], bsdf.inputs["Metallic"])
    if normal_img is not None:
        nmap = nt.nodes.new("ShaderNodeNormalMap")
        nt.links.new(tex(normal_img).outputs["Color"], nmap.inputs["Color"])
        nt.links.new(nmap.outputs["Normal"], bsdf.inputs["Normal"])
    if alpha == "MASK":
        clip = nt.nodes.new("ShaderNodeMath")
        clip.operation = "ROUND"
        nt.links.new(col.outputs["Alpha"], clip.inputs[0])
        nt.links.new(clip.outputs[0], bsdf.inputs["Alpha"])
    elif alpha == "BLEND":
        nt.links.new(col.outputs["Alpha"], bsdf.inputs["Alpha"])
    return mat


def _uv(ob, scale=1.0):
    """Per-corner UVs of a quad mesh: corner k of each face → the unit square's corner k."""
    layer = ob.data.uv_layers.new(name="UVMap")
    corners = [(0, 0), (1, 0), (1, 1), (0, 1)]
    for poly in ob.data.polygons:
        for k, li in enumerate(poly.loop_indices):
            layer.data[li].uv = [scale * c for c in corners[k % 4]]
    return ob


def _export_textured_scene(tmp_path) -> str:
    tex = _textures(tmp_path)
    floor = _principled("Floor", tex["base"], tex["floor_mr"], tex["normal"])
    _uv(h.plane("Floor", size=8, material=floor), 3.0)
    _uv(h.box("Box", size=(1, 1, 1), location=(0.6, 0.5, 0.5),
              material=_principled("Box", tex["box_col"], tex["box_mr"])))
    leaf = _uv(h.plane("Leaf", size=1.4, location=(-0.9, -0.3, 1.2), material=_principled("Leaf", tex["leaf"],
                                                                                        alpha="MASK")))
    leaf.rotation_euler = (np.radians(60), 0, np.radians(15))
    pane = _uv(h.plane("Pane", size=1.0, location=(0.9, -1.2, 0.6), material=_principled("Pane", tex["pane"],
                                                                                        alpha="BLEND")))
    pane.rotation_euler = (np.radians(80), 0, np.radians(-20))
    path = str(tmp_path / "scene.glb")
    assert bpy.ops.export_scene.gltf(filepath=path) == {"FINISHED"}
    return path


def _import(path: str) -> list:
    """Read the file into an empty scene; returns the imported materials."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon_utils.enable("io_scene_gltf2", default_set=True)
    assert bpy.ops.import_scene.gltf(filepath=path) == {"FINISHED"}
    return [m for m in bpy.data.materials if m.users]


@pytest.fixture
def gltf_scene(tmp_path):
    """The imported scene, lit, with a camera; skipped where the importer cannot run."""
    if addon_utils.enable("io_scene_gltf2", default_set=True) is None:
        pytest.skip("no glTF add-on in this Blender")
    path = _export_textured_scene(tmp_path)
    try:
        mats = _import(path)
    except (RuntimeError, AttributeError) as exc:
        if "bool" not in str(exc):
            raise
        pytest.skip("Debian's Blender 3.4 glTF importer uses np.bool, which numpy ≥ 1.24 removed "
                    f"(installed: {np.__version__}; tests/blender/test_shaders.py skips the same)")
    for mat in mats:
        for node in mat.node_tree.nodes:
            if node.type == "BSDF_PRINCIPLED":   # the neutralised differences (module docstring)
                node.distribution = "GGX"
                node.inputs[compat.principled_socket_name("specular")].default_value = 0.0
    h.camera(location=(0, -4, 3), target=(0, 0, 0.4))
    h.light("POINT", location=(-0.3, -0.8, 2.4), energy=400, color=(1, 0.92, 0.85), shadow_soft_size=0)
    h.world((0.05, 0.06, 0.08))
    return {m.name: m for m in mats}


def test_imported_materials_are_the_gltf_node_patterns(gltf_scene):
    """The premise: the importer rebuilt what glTF stores, and the exporter compiles it all
    without a warning (alpha clip as Math nodes, metallic/roughness through Separate Color)."""
    types = {name: {n.type for n in m.node_tree.nodes} for name, m in gltf_scene.items()}
    assert {"TEX_IMAGE", "NORMAL_MAP", "SEPARATE_COLOR"} <= types["Floor"]
    assert {"TEX_IMAGE", "SEPARATE_COLOR"} <= types["Box"]
    assert "MATH" in types["Leaf"]
    exported = h.export()
    assert exported.warnings == []
    desc = exported.description
    assert desc.mesh.uvs is not None and desc.mesh.tangents is not None
    assert len(desc.textures.names) == 7


# ERCUTS's bottom-right 8×8 block was ≈ 5 % darker than Cycles' (max |z| 4.32, 4.85 with
# several light samples per direct pass): an xfail until stop 44, its cause unknown. Three
# causes found (README, stop 44), measured on core renders (64×48, 8 seeds, light passes
# against PATH with 8192 samples, blocks against Cycles with 8192): (1) the VPLs stood on the
# *shading* normal, tilted by up to 25° on this normal-mapped floor (er_sampling._VPLStore;
# tests/test_er_sampling.py::test_vpls_stand_on_the_geometric_normal); (2) floor VPLs whose
# emission mostly escapes this open scene had a heavy-tailed light-traced Ê1: the VPL image
# 1.107× P, now 1.007× with pixel samples (vpl._camera_side; tests/test_e1.py); (3) the box's
# metal stripes (roughness 0.6) held VPLs emitting like diffuse patches: the floor beside the
# box 64 % short of its indirect light, in front 27–43 % over; every metal is followed now
# (tests/test_follow_specular.py::test_metals_of_any_roughness_are_followed_and_hold_no_vpl).
# Worst 8×8 block over four seed pairs: 4.26/5.16/3.77/4.33σ → 3.17/1.69/1.36/2.32σ. This
# test (seeds 1–2, Cycles 512 samples): max |z| 3.00, mean z² 0.36, means −0.31/−0.07/−0.01 %.


@pytest.mark.parametrize("integrator, spp", [
    ("PATH", 64), ("BDPT", 32), ("ERCUTS", 16)])
def test_gltf_round_trip_agrees_with_cycles(tmp_path, gltf_scene, integrator, spp):
    runs = [render_both(tmp_path, max_depth=4, samples=spp, cycles_samples=512, integrator=integrator,
                        seed=seed, tag=f"gltf_{integrator}") for seed in (1, 2)]
    assert_seed_pairs_agree(runs, rtol=0.02, tag=f"gltf {integrator}")
