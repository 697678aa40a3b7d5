"""Every Blender-version branch of the add-on, in one place.

The rest of the add-on calls these helpers instead of testing ``bpy.app.version``
itself, so supporting a new Blender release means editing this file only. Facts and
their sources are in the shared docs, ``blender.md`` (§0, §2.3, §3, §7); the ones
below were verified on Blender 3.4.1 and bpy 5.0.1.

numpy is imported inside the functions that need it, so that the add-on registers
even in a Blender whose Python lacks numpy (the engine then reports the missing
dependency when asked to render).
"""
from __future__ import annotations

import math
import os
import sys

import bpy

VERSION: tuple[int, int, int] = tuple(bpy.app.version)

#: ``RenderPass.rect.foreach_set`` takes a flat array from 4.1 on, (N, channels) before.
RECT_IS_FLAT = VERSION >= (4, 1, 0)
#: ``Mesh.corner_normals`` replaced ``calc_normals_split()`` + ``loops.normal`` in 4.1.
HAS_CORNER_NORMALS = VERSION >= (4, 1, 0)
#: Principled BSDF sockets were renamed in 4.0 (Emission → Emission Color, …).
PRINCIPLED_V4 = VERSION >= (4, 0, 0)
#: ``Material.use_nodes``/``World.use_nodes`` are deprecated (always True) from 5.0 on.
USE_NODES_DEPRECATED = VERSION >= (5, 0, 0)
#: Area lights: L = P/(π·A) from 4.0 on, P/(4·A) before (Cycles commit a21af93e6).
AREA_LIGHT_PI_NORMALISATION = VERSION >= (4, 0, 0)
#: Spot lights: before 4.0 Cycles multiplies the cone's smoothstep by cos θ (θ = angle to
#: the spot axis); from 4.0 on it is the smoothstep alone (measured with Cycles 3.4.1
#: and 5.0.1: off-axis ratio spot/point = cos θ·smoothstep vs smoothstep).
SPOT_COSINE_FALLOFF = VERSION < (4, 0, 0)
#: Cycles' darkening of diffuse light on normal-mapped/bumped surfaces
#: (``bump_shadowing_term``, kernel/closure/bsdf.h; models in ercuts_core/bump_shadowing.py):
#: Chiang et al. 2019 up to 4.4, Estevez et al. 2019 from 4.5 on (Cycles commit 11e282522).
BUMP_SHADOWING = "ESTEVEZ2019" if VERSION >= (4, 5, 0) else "CHIANG2019"
#: Point/spot lights with a radius: from 4.0 on Cycles makes them spheres unless *Soft
#: Falloff* is on (``is_sphere = !use_soft_falloff``, Blender's default is on); 3.x always
#: uses the disk facing the receiver (``kernel/light/light.h`` of Cycles 3.4).
HAS_SPHERE_LIGHTS = VERSION >= (4, 0, 0)


# --------------------------------------------------------------------------- render result

def rect_set(render_pass, pixels) -> None:
    """Write (N, channels) float pixels (row 0 = bottom) into ``render_pass.rect``."""
    import numpy as np

    a = np.ascontiguousarray(pixels, dtype=np.float32).reshape(-1, render_pass.channels)
    if RECT_IS_FLAT:
        render_pass.rect.foreach_set(a.reshape(-1))
    else:
        render_pass.rect.foreach_set(a)


def set_multilayer_exr(image_settings) -> None:
    """Switch ``image_settings`` to multilayer OpenEXR (5.0 needs ``media_type`` first)."""
    if hasattr(image_settings, "media_type"):
        image_settings.media_type = "MULTI_LAYER_IMAGE"
    image_settings.file_format = "OPEN_EXR_MULTILAYER"


def set_single_layer_exr(image_settings) -> None:
    """Switch ``image_settings`` to single-layer OpenEXR (5.0: media type IMAGE first)."""
    if hasattr(image_settings, "media_type"):
        image_settings.media_type = "IMAGE"
    image_settings.file_format = "OPEN_EXR"


# --------------------------------------------------------------------------- compositor

#: 5.0 composites through a node group (``scene.compositing_node_group``, output = Group
#: Output); 3.x through ``scene.node_tree`` with ``use_nodes`` and a Composite node.
COMPOSITOR_NODE_GROUP = VERSION >= (5, 0, 0)


def compositor_tree(scene, create: bool = True):
    """The scene's compositor node tree (made and enabled when ``create``), or None."""
    if COMPOSITOR_NODE_GROUP:
        tree = scene.compositing_node_group
        if tree is None and create:
            tree = bpy.data.node_groups.new("Compositor", "CompositorNodeTree")
            scene.compositing_node_group = tree
        return tree
    if create and not scene.use_nodes:
        scene.use_nodes = True
    return scene.node_tree


def compositor_output_socket(tree):
    """The input socket whose image becomes the composite (made when missing)."""
    if COMPOSITOR_NODE_GROUP:
        if not any(item.item_type == "SOCKET" and item.in_out == "OUTPUT"
                   for item in tree.interface.items_tree):
            new_group_socket(tree, "Image", "OUTPUT", "NodeSocketColor")
        node = next((n for n in tree.nodes if n.bl_idname == "NodeGroupOutput"), None)
        node = node or tree.nodes.new("NodeGroupOutput")
    else:
        node = next((n for n in tree.nodes if n.bl_idname == "CompositorNodeComposite"), None)
        node = node or tree.nodes.new("CompositorNodeComposite")
    return node.inputs[0]


def new_group_socket(tree, name: str, in_out: str, socket_type: str) -> None:
    """Add an input/output socket to a node group's interface (``in_out`` 'INPUT'/'OUTPUT').

    4.0+: ``tree.interface.new_socket``; 3.x: ``tree.inputs/outputs.new(type, name)``.
    """
    if hasattr(tree, "interface"):
        tree.interface.new_socket(name, in_out=in_out, socket_type=socket_type)
    else:
        (tree.inputs if in_out == "INPUT" else tree.outputs).new(socket_type, name)


def oidn_available() -> bool:
    """True when this Blender was built with OpenImageDenoise (the Denoise node works).

    ``bpy.app.build_options`` does not say; Cycles' ``_cycles.with_openimagedenoise``
    does (False in Debian's 3.4.1 build, True in bpy 5.0.1).
    """
    try:
        import _cycles
    except ImportError:
        return False
    return bool(getattr(_cycles, "with_openimagedenoise", False))


# --------------------------------------------------------------------------- meshes

def corner_normals(mesh):
    """(n_loops, 3) float32 shading normal of every face corner.

    Smooth faces get the interpolated (or custom/auto-smooth split) normal, flat faces
    their face normal, matching what Cycles renders.
    """
    import numpy as np

    n = np.empty(len(mesh.loops) * 3, np.float32)
    if HAS_CORNER_NORMALS:
        mesh.corner_normals.foreach_get("vector", n)
    else:
        mesh.calc_normals_split()
        mesh.loops.foreach_get("normal", n)
    return n.reshape(-1, 3)


def uv_layer_corners(layer, n_loops: int):
    """(n_loops, 2) float32 UV of every face corner of a ``MeshUVLoopLayer``.

    3.5+: ``layer.uv[i].vector``; before: ``layer.data[i].uv`` (both read with foreach_get).
    """
    import numpy as np

    out = np.empty(n_loops * 2, np.float32)
    if n_loops:
        if hasattr(layer, "uv"):
            layer.uv.foreach_get("vector", out)
        else:
            layer.data.foreach_get("uv", out)
    return out.reshape(-1, 2)


def active_render_uv_layer(mesh):
    """The UV map Cycles uses by default (``active_render``), or None when the mesh has none."""
    layers = mesh.uv_layers
    for layer in layers:
        if layer.active_render:
            return layer
    return layers.active if len(layers) else None


def corner_tangents(mesh, uv_name: str):
    """(n_loops, 4) float32 MikkTSpace tangent xyz + bitangent sign (``calc_tangents``,
    same API on 3.4 and 5.0). Raises RuntimeError (e.g. faces with more than 4 corners)."""
    import numpy as np

    mesh.calc_tangents(uvmap=uv_name)
    try:
        n = len(mesh.loops)
        t = np.empty(n * 3, np.float32)
        sign = np.empty(n, np.float32)
        if n:
            mesh.loops.foreach_get("tangent", t)
            mesh.loops.foreach_get("bitangent_sign", sign)
    finally:
        mesh.free_tangents()
    return np.concatenate([t.reshape(-1, 3), sign[:, None]], axis=1)


# --------------------------------------------------------------------------- node trees

def uses_nodes(idblock) -> bool:
    """True when a material/world/light renders through its node tree.

    On 5.0 ``use_nodes`` is deprecated for materials and worlds (always True, reading
    it warns), so only the presence of a tree counts there.
    """
    if getattr(idblock, "node_tree", None) is None:
        return False
    if USE_NODES_DEPRECATED and isinstance(idblock, (bpy.types.Material, bpy.types.World)):
        return True
    return bool(idblock.use_nodes)


def enable_nodes(idblock) -> None:
    """Make a new material/world/light use a node tree (no-op where that is the default)."""
    if USE_NODES_DEPRECATED and isinstance(idblock, (bpy.types.Material, bpy.types.World)):
        return
    idblock.use_nodes = True


#: Principled BSDF input names per concept: (4.x/5.x name, 3.x name).
_PRINCIPLED = {
    "base_color": ("Base Color", "Base Color"),
    "roughness": ("Roughness", "Roughness"),
    "metallic": ("Metallic", "Metallic"),
    "specular": ("Specular IOR Level", "Specular"),
    "ior": ("IOR", "IOR"),
    "emission_color": ("Emission Color", "Emission"),
    "emission_strength": ("Emission Strength", "Emission Strength"),
    "alpha": ("Alpha", "Alpha"),
    "transmission": ("Transmission Weight", "Transmission"),
    #: 3.x only (4.0 dropped it: the glass lobe uses Roughness); "" = no such socket
    "transmission_roughness": ("", "Transmission Roughness"),
    "coat": ("Coat Weight", "Clearcoat"),
    "sheen": ("Sheen Weight", "Sheen"),
    "subsurface": ("Subsurface Weight", "Subsurface"),
    "normal": ("Normal", "Normal"),
}


def principled_input(node, concept: str):
    """The Principled BSDF input socket for ``concept`` (see ``_PRINCIPLED``), or None."""
    new, old = _PRINCIPLED[concept]
    name = new if PRINCIPLED_V4 else old
    return node.inputs.get(name) if name else None


def principled_socket_name(concept: str) -> str:
    """This Blender's Principled BSDF input name for ``concept`` (for building scenes)."""
    new, old = _PRINCIPLED[concept]
    return new if PRINCIPLED_V4 else old


def principled_specular(specular: float, ior: float) -> float:
    """The core's ``specular`` (F0 = 0.08·specular) from Principled inputs.

    3.x: F0 = 0.08·Specular directly. 4.0+: F0 = ((ior−1)/(ior+1))²·2·IOR Level, so
    IOR 1.5 and level 0.5 give the same F0 = 0.04 as 3.x's default 0.5.
    """
    if not PRINCIPLED_V4:
        return float(specular)
    f0 = ((ior - 1.0) / (ior + 1.0)) ** 2 * 2.0 * specular
    return float(f0 / 0.08)


# --------------------------------------------------------------------------- lights

def light_exposure_scale(light) -> float:
    """2**exposure (4.0+; 1 on 3.x, which has no light exposure)."""
    return 2.0 ** float(getattr(light, "exposure", 0.0))


def light_temperature_rgb(light) -> tuple[float, float, float]:
    """Blackbody tint when ``use_temperature`` is on (4.5+), else white."""
    if getattr(light, "use_temperature", False):
        return tuple(float(c) for c in light.temperature_color)
    return (1.0, 1.0, 1.0)


def area_light_radiance_scale(light, area: float) -> float:
    """Factor turning an area light's colour·power·2^exposure into radiance [W/(sr·m²)].

    ≥ 4.0: 1/(π·A), or 1/π when ``normalize`` is off (size no longer divides power);
    3.x: 1/(4·A) (the pre-4.0 Cycles conversion).
    """
    if AREA_LIGHT_PI_NORMALISATION:
        if not getattr(light, "normalize", True):
            return 1.0 / math.pi
        return 1.0 / (math.pi * area)
    return 1.0 / (4.0 * area)


def point_light_is_sphere(light) -> bool:
    """The shape Cycles gives a point/spot light of radius > 0: a sphere (True) when Soft
    Falloff is off (≥ 4.0), else the disk facing the receiver (every 3.x)."""
    return HAS_SPHERE_LIGHTS and not getattr(light, "use_soft_falloff", True)


def point_light_intensity_scale(light) -> float:
    """Factor turning a point/spot light's colour·power·2^exposure into intensity I [W/sr]
    (the core's radiance over the light's disk or sphere is I/(π·r²)).

    Cycles ``scene/light.cpp``: radiance = P·invarea/π with invarea = 1/(4πr²) (4 for r = 0)
    when ``normalize`` is on (always on 3.x), 1 when it is off (≥ 4.x): I = P/(4π); without
    normalisation I = P/π at r = 0 and I = L·πr² = P·r² otherwise.
    """
    if getattr(light, "normalize", True):
        return 1.0 / (4.0 * math.pi)
    r = float(light.shadow_soft_size)
    return 1.0 / math.pi if r <= 0 else r * r


def sun_irradiance_scale(light) -> float:
    """Factor turning a sun's colour·strength·2^exposure into irradiance E [W/m²]: 1, or
    π·sin²(angle/2) when ``normalize`` is off (Cycles: the strength is then the radiance of the
    sun disk instead of the irradiance it gives)."""
    half = 0.5 * float(light.angle)
    if getattr(light, "normalize", True) or half <= 0:
        return 1.0
    return math.pi * math.sin(half) ** 2


def world_override(view_layer):
    """``view_layer.world_override`` (5.0) or None (3.x has none)."""
    return getattr(view_layer, "world_override", None)


# --------------------------------------------------------------------------- embreex

def _process_exports_embree() -> bool:
    """True when this Blender exports Embree's C API globally (e.g. Debian's 3.4.1 links
    the system ``libembree3.so.3``)."""
    import ctypes

    try:
        return hasattr(ctypes.CDLL(None), "rtcNewDevice")
    except OSError:
        return False


def preload_embreex() -> None:
    """Import embreex so that it talks to *its own* Embree 4.

    Embree 3 and 4 share C symbol names (``rtcNewDevice``, ``rtcIntersect1``, …). In a
    Blender that links Embree 3 globally, embreex's calls would bind to Embree 3 and
    crash on the first ray query. Loading embreex's extension modules with
    ``RTLD_DEEPBIND`` makes them resolve against their bundled Embree 4 first. numpy is
    imported *before* switching the flag: numpy's bundled libgfortran must keep using
    Blender's allocator (jemalloc), otherwise it frees foreign memory at exit.
    No-op when embreex is already imported, when the process has no Embree symbols
    (bpy module, most official builds), or when numpy/embreex are missing.
    """
    if "embreex.rtcore_scene" in sys.modules or not hasattr(os, "RTLD_DEEPBIND"):
        return
    if not _process_exports_embree():
        return
    try:
        import numpy  # noqa: F401  (must not be loaded with RTLD_DEEPBIND)
    except ImportError:
        return
    flags = sys.getdlopenflags()
    sys.setdlopenflags(flags | os.RTLD_DEEPBIND)
    try:
        import embreex.mesh_construction  # noqa: F401
        import embreex.rtcore  # noqa: F401
        import embreex.rtcore_scene  # noqa: F401
    except ImportError:
        pass
    finally:
        sys.setdlopenflags(flags)
