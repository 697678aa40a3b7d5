"""Build and save the project's .blend scenes: the S-corridor (paper Fig. 1), a Cornell box and
the benchmark scenes (door_ajar, baffled_lamp, directly_lit).

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

if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

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
    object (its triangles), Diffuse BSDF or Principled emitter materials, the same camera."""
    import numpy as np

    from ercuts_core import scenes

    reset(name)
    desc = scenes.SCENES[name](160, 120)
    mt = desc.materials
    mats = [emitter_material(n, tuple(map(float, mt.base_color[i])), tuple(map(float, mt.emission[i])))
            if mt.emission[i].max() > 0 else diffuse_material(n, tuple(map(float, mt.base_color[i])))
            for i, n in enumerate(mt.names)]
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


SCENES = {"s_corridor": build_s_corridor, "cornell_box": build_cornell_box,
          **{n: (lambda n=n: build_from_core(n)) for n in ("door_ajar", "baffled_lamp", "directly_lit")}}


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
