"""Scene builders and render helpers shared by the add-on tests (bpy 3.4 and 5.x)."""
from __future__ import annotations

import math

import bpy
import numpy as np
from mathutils import Vector

from addon import compat
from addon.export import export_scene


# --------------------------------------------------------------------------- objects

def link(obj, collection=None):
    (collection or bpy.context.scene.collection).objects.link(obj)
    return obj


def mesh_object(name, vertices, faces, location=(0, 0, 0), material=None, collection=None):
    """A mesh object from Python lists (small test geometry only)."""
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(v) for v in vertices], [], [tuple(f) for f in faces])
    me.update()
    obj = bpy.data.objects.new(name, me)
    obj.location = location
    if material is not None:
        me.materials.append(material)
    return link(obj, collection)


def plane(name="Plane", size=2.0, location=(0, 0, 0), material=None, collection=None):
    """Square in the XY plane facing +Z."""
    h = size / 2
    return mesh_object(name, [(-h, -h, 0), (h, -h, 0), (h, h, 0), (-h, h, 0)], [(0, 1, 2, 3)],
                       location, material, collection)


def box(name="Box", size=(1, 1, 1), location=(0, 0, 0), material=None, inward=False,
        collection=None):
    """Axis-aligned box with outward (or inward) faces."""
    sx, sy, sz = (s / 2 for s in size)
    v = [(-sx, -sy, -sz), (sx, -sy, -sz), (sx, sy, -sz), (-sx, sy, -sz),
         (-sx, -sy, sz), (sx, -sy, sz), (sx, sy, sz), (-sx, sy, sz)]
    f = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    if inward:
        f = [tuple(reversed(q)) for q in f]
    return mesh_object(name, v, f, location, material, collection)


def uv_sphere(name="Sphere", radius=1.0, segments=32, rings=16, location=(0, 0, 0), smooth=True,
              material=None):
    """UV sphere built with numpy (no bpy.ops, works without a 3D view)."""
    verts = [(0, 0, radius)]
    for i in range(1, rings):
        th = math.pi * i / rings
        for j in range(segments):
            ph = 2 * math.pi * j / segments
            verts.append((radius * math.sin(th) * math.cos(ph), radius * math.sin(th) * math.sin(ph),
                          radius * math.cos(th)))
    verts.append((0, 0, -radius))
    faces = []
    ring = lambda i, j: 1 + (i - 1) * segments + (j % segments)  # noqa: E731
    for j in range(segments):
        faces.append((0, ring(1, j), ring(1, j + 1)))
    for i in range(1, rings - 1):
        for j in range(segments):
            faces.append((ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1)))
    last = len(verts) - 1
    for j in range(segments):
        faces.append((ring(rings - 1, j + 1), ring(rings - 1, j), last))
    obj = mesh_object(name, verts, faces, location, material)
    for p in obj.data.polygons:
        p.use_smooth = smooth
    return obj


def camera(location=(0, 0, 5), target=(0, 0, 0), lens=50.0, name="Camera", **data):
    cam = bpy.data.cameras.new(name)
    cam.lens = lens
    for key, value in data.items():
        setattr(cam, key, value)
    obj = link(bpy.data.objects.new(name, cam))
    obj.location = location
    look_at(obj, target)
    bpy.context.scene.camera = obj
    return obj


def look_at(obj, target, up="Y"):
    direction = Vector(target) - Vector(obj.location)
    obj.rotation_euler = direction.to_track_quat("-Z", up).to_euler()


def light(kind="POINT", location=(0, 0, 2), energy=100.0, color=(1, 1, 1), target=None,
          name=None, **data):
    ld = bpy.data.lights.new(name or kind.title(), kind)
    ld.energy = energy
    ld.color = color
    for key, value in data.items():
        setattr(ld, key, value)
    obj = link(bpy.data.objects.new(name or kind.title(), ld))
    obj.location = location
    if target is not None:
        look_at(obj, target)
    return obj


# --------------------------------------------------------------------------- materials

def node_material(name, shader="ShaderNodeBsdfDiffuse", **inputs):
    """A material whose output is driven by one shader node with the given input values.

    Input keys are socket names; for the Principled BSDF, compat concept names
    ('base_color', 'emission_color', ...) are translated to this Blender's socket names.
    """
    mat = bpy.data.materials.new(name)
    compat.enable_nodes(mat)
    nt = mat.node_tree
    for node in list(nt.nodes):
        nt.nodes.remove(node)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    node = nt.nodes.new(shader)
    for key, value in inputs.items():
        socket_name = key
        if shader == "ShaderNodeBsdfPrincipled" and key in compat._PRINCIPLED:
            socket_name = compat.principled_socket_name(key)
        sock = node.inputs[socket_name]
        if isinstance(value, (tuple, list)) and len(value) == 3 and len(sock.default_value) == 4:
            value = (*value, 1.0)
        sock.default_value = value
    nt.links.new(node.outputs[0], out.inputs["Surface"])
    return mat


def diffuse(name="Diffuse", color=(0.8, 0.8, 0.8)):
    return node_material(name, "ShaderNodeBsdfDiffuse", Color=color)


def emission(name="Emission", color=(1, 1, 1), strength=1.0):
    return node_material(name, "ShaderNodeEmission", Color=color, Strength=strength)


def world(color=(0, 0, 0), strength=1.0):
    w = bpy.data.worlds.new("World")
    compat.enable_nodes(w)
    bg = next(n for n in w.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")
    bg.inputs["Color"].default_value = (*color, 1.0)
    bg.inputs["Strength"].default_value = strength
    bpy.context.scene.world = w
    return w


# --------------------------------------------------------------------------- export / render

def export(**kwargs):
    """Export the current scene through the viewport depsgraph."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    depsgraph.update()
    return export_scene(depsgraph, **kwargs)


def setup_render(width=64, height=48, engine="ERCUTS", samples=16, integrator="PATH", max_depth=8):
    s = bpy.context.scene
    s.render.engine = engine
    s.render.resolution_x, s.render.resolution_y = width, height
    s.render.resolution_percentage = 100
    s.ercuts.samples = s.ercuts.rough_samples = samples
    s.ercuts.integrator = integrator
    s.ercuts.max_depth = max_depth
    return s


def render_exr(path, scene=None) -> np.ndarray:
    """Render the scene to a 32-bit EXR and read it back: (h, w, 4), **top row first**."""
    s = scene or bpy.context.scene
    compat.set_single_layer_exr(s.render.image_settings)
    s.render.image_settings.color_depth = "32"
    s.render.image_settings.exr_codec = "ZIP"
    s.render.filepath = str(path)
    s.view_settings.view_transform = "Standard"
    s.render.use_file_extension = False
    result = bpy.ops.render.render(write_still=True)
    assert result == {"FINISHED"}
    return load_exr(path)


def load_exr(path) -> np.ndarray:
    img = bpy.data.images.load(str(path), check_existing=False)
    try:
        w, h = img.size
        px = np.empty(w * h * 4, np.float32)
        img.pixels.foreach_get(px)
    finally:
        bpy.data.images.remove(img)
    return px.reshape(h, w, 4)[::-1].copy()  # Blender images are bottom row first


#: Reads every channel of an EXR (all parts) into an .npz: argv = exr path, npz path.
_READ_EXR = """
import sys, numpy as np, OpenEXR
with OpenEXR.File(sys.argv[1], separate_channels=True) as exr:
    np.savez(sys.argv[2], **{n: np.asarray(c.pixels, np.float32)
                             for part in exr.parts for n, c in part.channels.items()})
"""


def read_exr_channels(path) -> dict:
    """Channel name → (h, w) float32 (top row first) of an EXR, read with OpenEXR.

    Inside a Blender binary (e.g. Debian's 3.4.1, which links its own OpenEXR 3.1) the
    wheel's OpenEXR 3.4 crashes the process, so it is read by a separate Python there
    (``python3`` with the inherited PYTHONPATH); with the bpy module, in-process.
    """
    import os
    import shutil
    import subprocess
    import sys
    import tempfile

    if not bpy.app.binary_path:
        python = sys.executable
    else:
        python = shutil.which("python3") or shutil.which("python")
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "channels.npz")
        subprocess.run([python, "-c", _READ_EXR, str(path), out], check=True)
        with np.load(out) as data:
            return {name: data[name] for name in data.files}


def render_multilayer(path, scene=None) -> dict:
    """Render to a 32-bit multilayer EXR and read every channel back
    (:func:`read_exr_channels`; 5.0 writes one EXR part per pass, 3.4 a single part)."""
    s = scene or bpy.context.scene
    compat.set_multilayer_exr(s.render.image_settings)
    s.render.image_settings.color_depth = "32"
    s.render.filepath = str(path)
    s.render.use_file_extension = False
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    return read_exr_channels(path)


def layer_pass(channels: dict, layer: str, name: str, chans: str) -> np.ndarray:
    """(h, w, len(chans)) pass ``name`` of ``layer`` from :func:`render_multilayer` channels."""
    return np.stack([channels[f"{layer}.{name}.{c}"] for c in chans], axis=2)
