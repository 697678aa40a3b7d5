"""Build and save the project's .blend scenes: the S-corridor (paper Fig. 1), a Cornell box and
the benchmark scenes (door_ajar, baffled_lamp, directly_lit, veach_room, mirror_glass_room).

Run with either Blender (the benchmark scenes are converted from ``ercuts_core.scenes`` and
need numpy, so give Debian's Blender the venv's site-packages):

    PYTHONPATH=.venv/lib/python3.11/site-packages:. \
        blender -b --factory-startup --python blend_scenes/build_scenes.py [-- --outdir DIR]
    .venv/bin/python blend_scenes/build_scenes.py [--outdir DIR]

The committed files are saved by Blender 3.4.1 so that they open in 3.4 *and* 5.0
(files written by 4.x/5.x do not open in 3.x). Without ``--outdir``, a Blender ≥ 4.0
therefore writes to ``out/blend_scenes/`` instead of overwriting them.

The geometry, materials and cameras are those of ``ercuts_core.scenes`` (the core's
built-in scenes), converted from the core's Y-up frame to Blender's Z-up frame:
Blender (x, y, z) = core (x, −z, y). The S-corridor and the Cornell box are written out by
hand below (quads); the benchmark scenes are converted triangle by triangle from the core's
description (:func:`build_from_core`), so they cannot drift from it. ``tests/blender/test_blend_scenes.py`` checks that
exporting these files gives the built-in descriptions.
"""
from __future__ import annotations

import argparse
import os
import sys

import bpy
from mathutils import Matrix, Vector

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

for _path in (ROOT, HERE):
    if _path not in sys.path:
        sys.path.insert(0, _path)

from addon import compat  # noqa: E402  (all Blender-version differences; needs only bpy)


# --------------------------------------------------------------------------- helpers

def to_blender(p):
    """Core Y-up point → Blender Z-up point (a rotation: windings are preserved)."""
    x, y, z = p
    return (x, -z, y)


def box_quads(lo, hi, inward=False):
    """The six faces of an axis-aligned box (core frame), counter-clockwise outward."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    faces = [
        [(x0, y0, z0), (x0, y0, z1), (x0, y1, z1), (x0, y1, z0)],
        [(x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)],
        [(x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)],
        [(x0, y1, z0), (x0, y1, z1), (x1, y1, z1), (x1, y1, z0)],
        [(x0, y0, z0), (x0, y1, z0), (x1, y1, z0), (x1, y0, z0)],
        [(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)],
    ]
    return [f[::-1] if inward else f for f in faces]


def quads_object(name, quads, material):
    """A mesh object made of core-frame quads (vertices shared where they coincide)."""
    verts, index, faces = [], {}, []
    for quad in quads:
        face = []
        for p in quad:
            q = tuple(round(c, 6) for c in to_blender(p))
            if q not in index:
                index[q] = len(verts)
                verts.append(q)
            face.append(index[q])
        faces.append(face)
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    me.update()
    me.materials.append(material)
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _material(name, color, shader):
    mat = bpy.data.materials.new(name)
    compat.enable_nodes(mat)
    mat.diffuse_color = (*color, 1.0)
    nt = mat.node_tree
    for node in list(nt.nodes):
        nt.nodes.remove(node)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    out.location = (300, 0)
    node = nt.nodes.new(shader)
    nt.links.new(node.outputs[0], out.inputs["Surface"])
    return mat, node


def diffuse_material(name, color):
    """Diffuse BSDF (Lambert, roughness 0): exactly the core's Lambertian row."""
    mat, node = _material(name, color, "ShaderNodeBsdfDiffuse")
    node.inputs["Color"].default_value = (*color, 1.0)
    return mat


def emitter_material(name, base, radiance):
    """Principled BSDF: diffuse ``base`` (no specular) plus emission = ``radiance``."""
    mat, node = _material(name, base, "ShaderNodeBsdfPrincipled")
    strength = max(radiance)
    compat.principled_input(node, "base_color").default_value = (*base, 1.0)
    compat.principled_input(node, "roughness").default_value = 1.0
    compat.principled_input(node, "specular").default_value = 0.0
    compat.principled_input(node, "emission_color").default_value = (
        *(c / strength for c in radiance), 1.0)
    compat.principled_input(node, "emission_strength").default_value = strength
    return mat


def glass_material(name, color, roughness, ior):
    """Glass BSDF (GGX): the core's glass row (transmission 1, metallic 0, specular 0.5)."""
    mat, node = _material(name, color, "ShaderNodeBsdfGlass")
    node.distribution = "GGX"
    node.inputs["Color"].default_value = (*color, 1.0)
    node.inputs["Roughness"].default_value = roughness
    node.inputs["IOR"].default_value = ior
    return mat


def glossy_material(name, color, roughness):
    """Glossy BSDF (GGX): the core's metal row (metallic 1, F0 = Color, specular 0.5)."""
    mat, node = _material(name, color, "ShaderNodeBsdfGlossy")
    node.distribution = "GGX"
    node.inputs["Color"].default_value = (*color, 1.0)
    node.inputs["Roughness"].default_value = roughness
    return mat


def core_material(mt, i):
    """The Blender material for row ``i`` of the core's MaterialTable ``mt``: a Principled
    emitter where it emits, a Glass BSDF where it transmits, a Glossy BSDF where it is a
    metal (metallic 1), else a Diffuse BSDF."""
    name, base = mt.names[i], tuple(map(float, mt.base_color[i]))
    if mt.emission[i].max() > 0:
        return emitter_material(name, base, tuple(map(float, mt.emission[i])))
    if mt.transmission[i] > 0:
        return glass_material(name, base, float(mt.roughness[i]), float(mt.ior[i]))
    if mt.metallic[i] == 1.0:
        return glossy_material(name, base, float(mt.roughness[i]))
    return diffuse_material(name, base)


def camera(eye, target, lens, sensor_width=36.0):
    cam = bpy.data.cameras.new("Camera")
    cam.lens = lens
    cam.sensor_width = sensor_width
    cam.sensor_fit = "AUTO"
    cam.clip_start = 0.01
    ob = bpy.data.objects.new("Camera", cam)
    bpy.context.scene.collection.objects.link(ob)
    ob.location = to_blender(eye)
    direction = Vector(to_blender(target)) - Vector(ob.location)
    ob.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()  # up = Blender +Z
    bpy.context.scene.camera = ob
    return ob


def black_world():
    world = bpy.data.worlds.new("World")
    compat.enable_nodes(world)
    world.color = (0.0, 0.0, 0.0)
    bg = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")
    bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bpy.context.scene.world = world


def render_settings(width, height, max_depth=64):
    """Resolution, engine (ERCUTS when registered; scene.ercuts at its defaults), and Cycles
    set up to match (``max_depth`` = the add-on's default max_depth)."""
    s = bpy.context.scene
    s.render.resolution_x, s.render.resolution_y = width, height
    s.render.resolution_percentage = 100
    s.render.film_transparent = False
    s.view_settings.view_transform = "Standard"  # the same look in 3.4 (Filmic) and 5.0 (AgX)
    s.render.image_settings.file_format = "PNG"
    s.render.filepath = "//render/" + os.path.splitext(bpy.path.basename(s.name))[0]
    # Cycles, for comparisons: the same path length (Cycles counts bounces after the first
    # hit, so max_bounces = max_depth − 1; 0 = direct light only), no denoiser, box filter.
    s.cycles.samples = 256
    s.cycles.max_bounces = max_depth - 1
    for key in ("diffuse_bounces", "glossy_bounces", "transmission_bounces", "volume_bounces"):
        setattr(s.cycles, key, max_depth - 1)
    s.cycles.use_denoising = False
    s.cycles.pixel_filter_type = "BOX"
    s.cycles.filter_width = 1.0
    s.cycles.caustics_reflective = s.cycles.caustics_refractive = True
    s.cycles.sample_clamp_indirect = 0.0
    try:  # register the engine from this repository if we can
        import addon

        if not hasattr(bpy.types.Scene, "ercuts"):
            addon.register()
    except Exception as exc:  # noqa: BLE001
        print(f"build_scenes: Ercuts add-on not registered ({exc}); engine stays CYCLES")
    if hasattr(s, "ercuts"):
        # scene.ercuts stays at the add-on's defaults (not stored, so they follow the add-on).
        s.render.engine = "ERCUTS"
        assert s.ercuts.max_depth == max_depth
    else:
        s.render.engine = "CYCLES"


def reset(name):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.scene.name = name


# --------------------------------------------------------------------------- scenes

def build_s_corridor():
    """The S-shaped corridor of the paper's Fig. 1 (plan 6 m × 6 m, 2.5 m high).

    Three parallel lanes separated by two walls with gaps at opposite ends; a 1 m²
    emissive panel at the end of the first lane, the camera at the far end of the third,
    so light reaches the camera only after several diffuse bounces.
    """
    reset("s_corridor")
    H = 2.5
    wall = diffuse_material("Wall", (0.75, 0.75, 0.75))
    lamp = emitter_material("Lamp", (0.8, 0.8, 0.8), (1500.0, 1400.0, 1200.0))
    quads_object("Shell", box_quads((0, 0, 0), (6, H, 6), inward=True), wall)
    quads_object("Wall1", [[(0, 0, 2), (4.5, 0, 2), (4.5, H, 2), (0, H, 2)]], wall)
    quads_object("Wall2", [[(1.5, 0, 4), (6, 0, 4), (6, H, 4), (1.5, H, 4)]], wall)
    quads_object("LightPanel", [[(0.01, 0.8, 0.5), (0.01, 0.8, 1.5), (0.01, 1.8, 1.5),
                                 (0.01, 1.8, 0.5)]], lamp)
    camera((5.9, 1.25, 5.0), (0.0, 1.25, 5.0), lens=20.0)
    black_world()
    render_settings(160, 120)


def build_cornell_box():
    """Cornell box, 2 m wide, lit by an emissive ceiling panel (core: ``cornell_box()``)."""
    reset("cornell_box")
    white = diffuse_material("White", (0.73, 0.73, 0.73))
    red = diffuse_material("Red", (0.63, 0.065, 0.05))
    green = diffuse_material("Green", (0.14, 0.45, 0.091))
    lamp = emitter_material("Lamp", (0.78, 0.78, 0.78), (17.0, 12.0, 4.0))
    quads_object("Room", [
        [(-1, 0, 1), (1, 0, 1), (1, 0, -1), (-1, 0, -1)],      # floor
        [(-1, 2, -1), (1, 2, -1), (1, 2, 1), (-1, 2, 1)],      # ceiling
        [(-1, 0, -1), (1, 0, -1), (1, 2, -1), (-1, 2, -1)],    # back
    ], white)
    quads_object("LeftWall", [[(-1, 0, 1), (-1, 0, -1), (-1, 2, -1), (-1, 2, 1)]], red)
    quads_object("RightWall", [[(1, 0, -1), (1, 0, 1), (1, 2, 1), (1, 2, -1)]], green)
    quads_object("TallBox", box_quads((-0.7, 0, -0.6), (-0.1, 1.2, 0.0)), white)
    quads_object("ShortBox", box_quads((0.1, 0, -0.1), (0.7, 0.6, 0.5)), white)
    quads_object("Lamp", [[(-0.25, 1.99, -0.2), (0.25, 1.99, -0.2), (0.25, 1.99, 0.2),
                           (-0.25, 1.99, 0.2)]], lamp)
    camera((0, 1, 3.9), (0, 1, 0), lens=30.0)
    black_world()
    render_settings(160, 120)


def build_from_core(name):
    """Convert the core's built-in scene ``name`` (160 × 120): one Blender object per core
    object (its triangles), Diffuse, Glass or Glossy BSDF or Principled emitter materials
    (:func:`core_material`), the same camera."""
    import numpy as np

    from ercuts_core import scenes

    reset(name)
    desc = scenes.SCENES[name](160, 120)
    mt = desc.materials
    mats = [core_material(mt, i) for i in range(len(mt.names))]
    mesh = desc.mesh
    for oid, oname in enumerate(desc.object_names):
        tris = mesh.triangles[mesh.object_ids == oid]
        if len(tris) == 0:
            continue
        used, local = np.unique(tris, return_inverse=True)
        verts = [to_blender(p) for p in mesh.positions[used].astype(np.float64).tolist()]
        me = bpy.data.meshes.new(oname)
        me.from_pydata(verts, [], local.reshape(-1, 3).tolist())
        mids = mesh.material_ids[mesh.object_ids == oid]
        slots = sorted(set(mids.tolist()))
        for m in slots:
            me.materials.append(mats[m])
        for poly, m in zip(me.polygons, mids.tolist()):
            poly.material_index = slots.index(m)
        me.update()
        bpy.context.scene.collection.objects.link(bpy.data.objects.new(oname, me))
    c = desc.camera
    cam = camera((0, 0, 0), (0, 0, -1), c.lens, c.sensor_width)
    rot = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])  # core → Blender
    cam.matrix_world = Matrix((rot @ c.world_from_camera).tolist())
    black_world()
    render_settings(160, 120)


# --------------------------------------------------------------------------- textured scenes
# Built directly in Blender's Z-up frame (no core counterpart: the report exports them through
# the add-on). Images are procedural (procedural_textures.py, fixed seeds), 8-bit, packed.

def packed_image(name, pixels, colorspace="sRGB"):
    """A packed 8-bit image from (n, n, 3) or (n, n) values in [0, 1] (row 0 = bottom)."""
    import numpy as np

    px = np.asarray(pixels, np.float64)
    if px.ndim == 2:
        px = np.repeat(px[..., None], 3, axis=2)
    n_y, n_x = px.shape[:2]
    rgba = np.concatenate([px, np.ones((n_y, n_x, 1))], axis=2).astype(np.float32)
    img = bpy.data.images.new(name, n_x, n_y, alpha=False)
    img.colorspace_settings.name = colorspace
    img.pixels.foreach_set(rgba.reshape(-1))
    img.file_format = "PNG"
    img.pack()
    return img


class Nodes:
    """A material's node tree under construction: ``new`` nodes, ``link`` sockets."""

    def __init__(self, name):
        self.mat = bpy.data.materials.new(name)
        compat.enable_nodes(self.mat)
        self.nt = self.mat.node_tree
        for node in list(self.nt.nodes):
            self.nt.nodes.remove(node)
        self.out = self.nt.nodes.new("ShaderNodeOutputMaterial")

    def new(self, kind, **inputs):
        node = self.nt.nodes.new(kind)
        for key, value in inputs.items():
            sock = node.inputs[key]
            if isinstance(value, (tuple, list)) and len(value) == 3 and len(sock.default_value) == 4:
                value = (*value, 1.0)
            sock.default_value = value
        return node

    def link(self, src, dst):
        self.nt.links.new(src, dst)

    def tex(self, img, vector=None, interpolation="Linear"):
        node = self.nt.nodes.new("ShaderNodeTexImage")
        node.image, node.interpolation = img, interpolation
        if vector is not None:
            self.link(vector, node.inputs["Vector"])
        return node

    def mapping(self, scale=(1, 1, 1), rotation_z=0.0):
        uv = self.nt.nodes.new("ShaderNodeTexCoord")
        m = self.new("ShaderNodeMapping")
        m.inputs["Scale"].default_value = scale
        m.inputs["Rotation"].default_value = (0.0, 0.0, rotation_z)
        self.link(uv.outputs["UV"], m.inputs["Vector"])
        return m.outputs["Vector"]

    def principled(self, **concepts):
        node = self.nt.nodes.new("ShaderNodeBsdfPrincipled")
        for concept, value in concepts.items():
            sock = compat.principled_input(node, concept)
            if hasattr(value, "is_output"):
                self.link(value, sock)
            else:
                sock.default_value = (*value, 1.0) if isinstance(value, tuple) else value
        return node

    def surface(self, shader):
        self.link(shader.outputs[0], self.out.inputs["Surface"])
        return self.mat


def textured_box(name, lo, hi, materials, tile=1.0, inward=False, skip=()):
    """An axis-aligned box (Blender frame) with per-face UVs = the face's plane coordinates in
    metres / ``tile``; ``materials``: one material or six (−x, +x, −y, +y, −z, +z); faces
    listed in ``skip`` are left out (open sides)."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    faces = [((x0, y0, z0), (x0, y1, z0), (x0, y1, z1), (x0, y0, z1)),
             ((x1, y0, z0), (x1, y0, z1), (x1, y1, z1), (x1, y1, z0)),
             ((x0, y0, z0), (x0, y0, z1), (x1, y0, z1), (x1, y0, z0)),
             ((x0, y1, z0), (x1, y1, z0), (x1, y1, z1), (x0, y1, z1)),
             ((x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0)),
             ((x0, y0, z1), (x0, y1, z1), (x1, y1, z1), (x1, y0, z1))]
    mats = list(materials) if isinstance(materials, (list, tuple)) else [materials] * 6
    keep = [k for k in range(6) if k not in skip]
    verts, polys = [], []
    for k in keep:
        f = faces[k][::-1] if inward else faces[k]
        polys.append(list(range(len(verts), len(verts) + 4)))
        verts += list(f)
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], polys)
    slots = []
    for k in keep:
        if mats[k] not in slots:
            slots.append(mats[k])
    for m in slots:
        me.materials.append(m)
    layer = me.uv_layers.new(name="UVMap")
    for poly, k in zip(me.polygons, keep):
        poly.material_index = slots.index(mats[k])
        axis = k // 2                                   # the face's normal axis
        u_axis, v_axis = [a for a in range(3) if a != axis]
        for li in poly.loop_indices:
            co = me.vertices[me.loops[li].vertex_index].co
            layer.data[li].uv = (co[u_axis] / tile, co[v_axis] / tile)
    me.update()
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def blender_camera(location, target, lens):
    cam = bpy.data.cameras.new("Camera")
    cam.lens, cam.sensor_width, cam.sensor_fit, cam.clip_start = lens, 36.0, "AUTO", 0.01
    ob = bpy.data.objects.new("Camera", cam)
    bpy.context.scene.collection.objects.link(ob)
    ob.location = location
    ob.rotation_euler = (Vector(target) - Vector(location)).to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.camera = ob
    return ob


def _wood_material(name, tex, scale, rotation_z=0.0, normal=True):
    """Principled wood: colour, roughness (Separate Color of the data image) and a normal map
    from the plank seams, all through one Mapping node."""
    m = Nodes(name)
    vec = m.mapping(scale, rotation_z)
    col = m.tex(tex["wood"], vec)
    data = m.tex(tex["wood_data"], vec)
    sep = m.new("ShaderNodeSeparateColor")
    m.link(data.outputs["Color"], sep.inputs[0])
    bsdf = m.principled(base_color=col.outputs["Color"], roughness=sep.outputs[1])
    if normal:
        nmap = m.new("ShaderNodeNormalMap", Strength=0.8)
        m.link(m.tex(tex["wood_normal"], vec).outputs["Color"], nmap.inputs["Color"])
        m.link(nmap.outputs["Normal"], compat.principled_input(bsdf, "normal"))
    return m.surface(bsdf)


def _plaster_material(name, tex, tint, scale=0.5):
    """Diffuse plaster: texture × tint (Mix, Multiply) and a Bump from the height image."""
    m = Nodes(name)
    vec = m.mapping((scale, scale, 1))
    mix = m.new("ShaderNodeMixRGB", Fac=1.0, Color2=tint)
    mix.blend_type = "MULTIPLY"
    m.link(m.tex(tex["plaster"], vec).outputs["Color"], mix.inputs["Color1"])
    bump = m.new("ShaderNodeBump", Strength=0.25, Distance=0.01)
    m.link(m.tex(tex["plaster_height"], vec).outputs["Color"], bump.inputs["Height"])
    diffuse = m.new("ShaderNodeBsdfDiffuse")
    m.link(mix.outputs["Color"], diffuse.inputs["Color"])
    m.link(bump.outputs["Normal"], diffuse.inputs["Normal"])
    return m.surface(diffuse)


def _fabric_material(name, tex, scale, colour_a, colour_b):
    """Mix Shader of two diffuse yarn colours with the weave image as the factor."""
    m = Nodes(name)
    vec = m.mapping((scale, scale, 1))
    mix = m.new("ShaderNodeMixShader")
    m.link(m.tex(tex["fabric_mix"], vec).outputs["Color"], mix.inputs["Fac"])
    plain = m.new("ShaderNodeBsdfDiffuse", Color=colour_a)
    woven = m.new("ShaderNodeBsdfDiffuse", Color=colour_b)      # its colour: the fabric image
    m.link(m.tex(tex["fabric"], vec).outputs["Color"], woven.inputs["Color"])
    m.link(plain.outputs[0], mix.inputs[1])
    m.link(woven.outputs[0], mix.inputs[2])
    return m.surface(mix)


def _image_diffuse(name, img, scale=1.0):
    m = Nodes(name)
    col = m.tex(img, m.mapping((scale, scale, 1)))
    diffuse = m.new("ShaderNodeBsdfDiffuse")
    m.link(col.outputs["Color"], diffuse.inputs["Color"])
    return m.surface(diffuse)


def _textures(seed, size=256):
    import numpy as np

    import procedural_textures as pt

    rng = np.random.default_rng(seed)
    wood, wood_h, wood_r = pt.wood_planks(size, rng)
    plaster, plaster_h = pt.plaster(size, rng)
    fabric, weave = pt.fabric(size, rng)
    tiles, tiles_h = pt.tiles(size, rng)
    data = np.stack([wood_h, wood_r, np.zeros_like(wood_r)], axis=2)   # G: roughness
    return {"wood": packed_image("Wood", wood), "wood_data": packed_image("WoodData", data, "Non-Color"),
            "wood_normal": packed_image("WoodNormal", pt.normal_map(wood_h, 8.0), "Non-Color"),
            "plaster": packed_image("Plaster", plaster),
            "plaster_height": packed_image("PlasterHeight", plaster_h, "Non-Color"),
            "fabric": packed_image("Fabric", fabric), "fabric_mix": packed_image("Weave", weave, "Non-Color"),
            "rug": packed_image("Rug", pt.rug(size, rng)),
            "tiles": packed_image("Tiles", tiles),
            "tiles_normal": packed_image("TilesNormal", pt.normal_map(tiles_h, 6.0), "Non-Color"),
            "wallpaper": packed_image("Wallpaper", pt.wallpaper(size, rng))}


def _furniture(tex, sofa_at, table_at):
    """Sofa (fabric), coffee table and cabinet (wood), a rug."""
    fab = _fabric_material("Sofa", tex, 4.0, (0.3, 0.12, 0.1), (0.6, 0.55, 0.5))
    sx, sy = sofa_at
    textured_box("SofaSeat", (sx, sy, 0.0), (sx + 2.0, sy + 0.9, 0.45), fab, tile=0.5)
    textured_box("SofaBack", (sx, sy + 0.7, 0.45), (sx + 2.0, sy + 0.9, 0.9), fab, tile=0.5)
    for name, x in (("ArmL", sx), ("ArmR", sx + 1.8)):
        textured_box(name, (x, sy, 0.45), (x + 0.2, sy + 0.7, 0.65), fab, tile=0.5)
    oak = _wood_material("Oak", tex, (2.0, 2.0, 1.0), rotation_z=1.5708, normal=False)
    tx, ty = table_at
    textured_box("TableTop", (tx, ty, 0.4), (tx + 1.1, ty + 0.6, 0.45), oak, tile=1.0)
    for name, (dx, dy) in {"Leg1": (0.05, 0.05), "Leg2": (1.0, 0.05), "Leg3": (0.05, 0.5),
                           "Leg4": (1.0, 0.5)}.items():
        textured_box(name, (tx + dx, ty + dy, 0.0), (tx + dx + 0.05, ty + dy + 0.05, 0.4), oak)
    textured_box("Rug", (tx - 0.6, ty - 0.5, 0.0), (tx + 1.7, ty + 1.1, 0.01),
                 _image_diffuse("Rug", tex["rug"]), tile=2.3)


def build_textured_living_room():
    """A closed 5 m × 4 m × 2.6 m living room lit by a floor uplight whose lamp faces the
    ceiling: the camera sees the lamp's dark shade and a room lit by the bright ceiling."""
    reset("textured_living_room")
    tex = _textures(1)
    floor = _wood_material("Floor", tex, (1.0, 1.0, 1.0))
    wall = _plaster_material("Plaster", tex, (0.95, 0.9, 0.8))
    ceiling = diffuse_material("Ceiling", (0.85, 0.85, 0.85))
    textured_box("Room", (0, 0, 0), (5, 4, 2.6), [wall, wall, wall, wall, floor, ceiling], tile=1.5, inward=True)
    _furniture(tex, sofa_at=(1.2, 2.9), table_at=(1.6, 1.5))
    oak = bpy.data.materials["Oak"]
    textured_box("Cabinet", (4.4, 0.4, 0.0), (4.95, 2.0, 1.1), oak, tile=1.0)
    metal = Nodes("Steel")
    metal = metal.surface(metal.principled(base_color=(0.6, 0.6, 0.62), metallic=1.0, roughness=0.35))
    textured_box("LampPole", (0.48, 3.48, 0.0), (0.52, 3.52, 1.9), metal)
    shade = diffuse_material("Shade", (0.15, 0.12, 0.1))
    textured_box("LampShade", (0.22, 3.22, 1.9), (0.78, 3.78, 2.1), shade)
    lamp = emitter_material("Lamp", (0.8, 0.8, 0.8), (200.0, 180.0, 150.0))
    textured_box("LampTop", (0.25, 3.25, 2.101), (0.75, 3.75, 2.101), lamp, skip=(0, 1, 2, 3, 4))
    blender_camera((4.6, 0.3, 1.45), (1.5, 3.0, 0.9), lens=20.0)
    black_world()
    render_settings(160, 120)


def build_textured_bedroom():
    """A 4 m × 3.5 m × 2.5 m tiled room with wallpaper, lit only by the sun through a window
    (a bright patch on the floor; everything else indirect) and a dim sky seen through it."""
    reset("textured_bedroom")
    tex = _textures(2)
    m = Nodes("TileFloor")
    vec = m.mapping((2.0, 2.0, 1.0))
    nmap = m.new("ShaderNodeNormalMap", Strength=1.0)
    m.link(m.tex(tex["tiles_normal"], vec).outputs["Color"], nmap.inputs["Color"])
    bsdf = m.principled(base_color=m.tex(tex["tiles"], vec).outputs["Color"], roughness=0.3)
    m.link(nmap.outputs["Normal"], compat.principled_input(bsdf, "normal"))
    floor = m.surface(bsdf)
    paper = _image_diffuse("Wallpaper", tex["wallpaper"], 1.0)
    plaster = _plaster_material("Plaster", tex, (1.0, 1.0, 1.0))
    ceiling = diffuse_material("Ceiling", (0.8, 0.8, 0.8))
    # room without the +y wall; that wall is built around a 1.2 m × 1.2 m window
    textured_box("Room", (0, 0, 0), (4, 3.5, 2.5), [paper, paper, paper, paper, floor, ceiling],
                 tile=1.25, inward=True, skip=(3,))
    y0, y1 = 3.5, 3.6
    for name, lo, hi in (("WallL", (0, y0, 0), (1.4, y1, 2.5)), ("WallR", (2.6, y0, 0), (4, y1, 2.5)),
                         ("WallLow", (1.4, y0, 0), (2.6, y1, 0.9)), ("WallHigh", (1.4, y0, 2.1), (2.6, y1, 2.5))):
        textured_box(name, lo, hi, plaster, tile=1.25)
    bed = _fabric_material("Bedspread", tex, 3.0, (0.15, 0.25, 0.4), (0.75, 0.75, 0.7))
    textured_box("Bed", (0.3, 0.4, 0.0), (1.9, 2.5, 0.55), bed, tile=0.6)
    oak = _wood_material("Oak", tex, (2.0, 2.0, 1.0), rotation_z=1.5708, normal=False)
    textured_box("Headboard", (0.3, 0.2, 0.0), (1.9, 0.4, 1.1), oak)
    textured_box("Wardrobe", (3.3, 0.3, 0.0), (3.95, 1.8, 2.0), oak)
    textured_box("Rug", (2.0, 1.2, 0.0), (3.1, 2.8, 0.01), _image_diffuse("Rug", tex["rug"]), tile=1.6)
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy, sun.angle, sun.color = 4.0, 0.0, (1.0, 0.95, 0.85)
    ob = bpy.data.objects.new("Sun", sun)
    bpy.context.scene.collection.objects.link(ob)
    ob.rotation_euler = (Vector((0.3, -1.0, -0.9))).to_track_quat("-Z", "Y").to_euler()
    blender_camera((3.1, 0.15, 1.6), (1.6, 3.5, 0.9), lens=18.0)
    world = bpy.data.worlds.new("World")
    compat.enable_nodes(world)
    bg = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")
    bg.inputs["Color"].default_value = (0.35, 0.45, 0.65, 1.0)
    bg.inputs["Strength"].default_value = 1.0
    bpy.context.scene.world = world
    render_settings(160, 120)


#: The textured interiors (no built-in core counterpart).
TEXTURED_SCENES = ("textured_living_room", "textured_bedroom")

SCENES = {"s_corridor": build_s_corridor, "cornell_box": build_cornell_box,
          **{n: (lambda n=n: build_from_core(n)) for n in ("door_ajar", "baffled_lamp", "directly_lit",
                                                            "veach_room", "mirror_glass_room")},
          "textured_living_room": build_textured_living_room, "textured_bedroom": build_textured_bedroom}


def save(path):
    bpy.ops.wm.save_as_mainfile(filepath=path, compress=True, relative_remap=True)
    if os.path.exists(path + "1"):  # Blender's backup of the file it overwrote
        os.remove(path + "1")
    print(f"build_scenes: saved {path} ({os.path.getsize(path) / 1024:.0f} KiB)")


def main(argv=None):
    if argv is None:
        argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else (
            sys.argv[1:] if not bpy.app.background or sys.argv[0].endswith(".py") else [])
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--outdir", help="where to save the .blend files")
    parser.add_argument("scenes", nargs="*", default=list(SCENES), help="scene names")
    args = parser.parse_args(argv)
    outdir = args.outdir
    if outdir is None:
        if bpy.app.version < (4, 0, 0):
            outdir = HERE
        else:
            outdir = os.path.join(ROOT, "out", "blend_scenes")
            print(f"build_scenes: Blender {bpy.app.version_string} files do not open in 3.4; "
                  f"writing to {outdir} (use --outdir to override)")
    os.makedirs(outdir, exist_ok=True)
    for name in args.scenes:
        SCENES[name]()
        save(os.path.join(os.path.abspath(outdir), name + ".blend"))


if __name__ == "__main__":
    main()
