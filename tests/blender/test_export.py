"""Exporter: depsgraph → SceneDescription (geometry, materials, lights, world, camera)."""
from __future__ import annotations

import math

import bpy
import numpy as np
import pytest
from mathutils import Matrix

import blender_helpers as h
from addon import compat
from addon.export import ExportError

V = bpy.app.version


def _face_normals(desc):
    p = desc.mesh.positions.astype(np.float64)
    t = desc.mesh.triangles
    n = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


# --------------------------------------------------------------------------- geometry

def test_plane_world_transform():
    h.camera()
    ob = h.plane(size=2.0, location=(1, 2, 3))
    ob.rotation_euler = (0, 0, math.pi / 2)
    ob.scale = (2, 1, 1)
    desc = h.export().description
    assert desc.mesh.n_triangles == 2
    want = np.array(ob.matrix_world) @ np.array([[-1, -1, 0, 1], [1, -1, 0, 1], [1, 1, 0, 1], [-1, 1, 0, 1]]).T
    got = desc.mesh.positions
    for corner in want[:3].T:
        assert np.min(np.linalg.norm(got - corner, axis=1)) < 1e-6
    assert desc.mesh.normals is None and desc.mesh.smooth is None  # flat only
    assert np.allclose(_face_normals(desc), [0, 0, 1], atol=1e-6)
    assert desc.object_names == ("Plane",)
    assert np.all(desc.mesh.object_ids == 0)


def test_collection_instances():
    h.camera()
    src = bpy.data.collections.new("Src")  # not linked to the scene: visible only through instances
    h.box("Cube", collection=src)
    for i, x in enumerate((-3.0, 3.0)):
        empty = h.link(bpy.data.objects.new(f"Inst{i}", None))
        empty.instance_type = "COLLECTION"
        empty.instance_collection = src
        empty.location = (x, 0, 0)
    exported = h.export()
    desc = exported.description
    assert desc.mesh.n_triangles == 24
    assert exported.stats["instances"] == 2 and exported.stats["meshes"] == 1
    assert set(desc.object_names) == {"Inst0/Cube", "Inst1/Cube"}
    xs = desc.mesh.positions[:, 0]
    assert xs.min() == pytest.approx(-3.5) and xs.max() == pytest.approx(3.5)
    # Each instance keeps its own copy of the matrix (not the last one seen).
    for oid in (0, 1):
        tri = desc.mesh.triangles[desc.mesh.object_ids == oid]
        cx = desc.mesh.positions[tri.reshape(-1), 0].mean()
        assert abs(abs(cx) - 3.0) < 1e-6
    assert np.unique(desc.mesh.object_ids).size == 2


def test_array_and_subdivision_modifiers():
    h.camera()
    cube = h.box("Cube")
    arr = cube.modifiers.new("Array", "ARRAY")
    arr.count = 3
    arr.relative_offset_displace = (2.0, 0, 0)
    desc = h.export().description
    assert desc.mesh.n_triangles == 36
    assert desc.mesh.positions[:, 0].max() == pytest.approx(4.5)
    sub = cube.modifiers.new("Sub", "SUBSURF")
    sub.levels = sub.render_levels = 1
    desc = h.export().description
    assert desc.mesh.n_triangles == 36 * 4


def test_hidden_objects_are_skipped():
    h.camera()
    h.plane("Visible")
    h.plane("Hidden", location=(0, 0, 1)).hide_render = True
    desc = h.export().description
    assert desc.object_names == ("Visible",)


@pytest.mark.parametrize("scale", [(1, 1, 1), (-1, 1, 1), (1, -2, 1), (-1, -1, -1)])
@pytest.mark.parametrize("smooth", [False, True])
def test_negative_scale_keeps_winding(scale, smooth):
    h.camera()
    ob = h.uv_sphere(segments=12, rings=6, smooth=smooth)
    ob.scale = scale
    desc = h.export().description
    n = _face_normals(desc)
    p = desc.mesh.positions[desc.mesh.triangles].mean(axis=1)
    # Outward winding of the sphere survives any mirroring transform.
    assert np.all(np.sum(n * p, axis=1) > 0)
    if smooth:
        shading = desc.mesh.normals[desc.mesh.triangles].mean(axis=1)
        assert np.all(np.sum(shading * n, axis=1) > 0.5)


def test_smooth_normals_per_corner():
    h.camera()
    ob = h.uv_sphere(radius=2.0, segments=24, rings=12, smooth=True)
    ob.location = (1, 0, 0)
    desc = h.export().description
    m = desc.mesh
    assert m.normals is not None and m.smooth is not None and m.smooth.all()
    radial = m.positions - np.array([1.0, 0, 0])
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    assert np.allclose(m.normals, radial, atol=0.05)
    # Exactly Blender's smooth (vertex) normals, found by position.
    co = np.array([v.co for v in ob.data.vertices]) + np.array([1.0, 0, 0])
    vn = np.array([v.normal for v in ob.data.vertices])
    nearest = np.argmin(np.linalg.norm(m.positions[:, None] - co[None], axis=2), axis=1)
    assert np.allclose(m.normals, vn[nearest], atol=1e-5)
    assert np.allclose(np.linalg.norm(m.normals, axis=1), 1, atol=1e-5)
    # Mixed smooth/flat: flat faces are flagged, smooth ones interpolate.
    for i, poly in enumerate(ob.data.polygons):
        poly.use_smooth = i % 2 == 0
    ob.data.update()
    m = h.export().description.mesh
    assert 0 < m.smooth.sum() < m.n_triangles


def test_multi_material_slots():
    h.camera()
    red, green = h.diffuse("Red", (1, 0, 0)), h.diffuse("Green", (0, 1, 0))
    ob = h.box("Cube", material=red)
    ob.data.materials.append(green)
    for i, poly in enumerate(ob.data.polygons):
        poly.material_index = i % 2
    desc = h.export().description
    names = desc.materials.names
    got = [names[i] for i in desc.mesh.material_ids]
    assert got.count("Red") == 6 and got.count("Green") == 6


def test_material_override_and_default_surface():
    h.camera()
    h.plane("NoMaterial")
    h.plane("Red", material=h.diffuse("Red", (1, 0, 0)), location=(0, 0, 1))
    desc = h.export().description
    rows = {desc.materials.names[i] for i in desc.mesh.material_ids}
    assert rows == {"<default surface>", "Red"}
    default = desc.materials.names.index("<default surface>")
    assert np.allclose(desc.materials.base_color[default], 0.8)
    bpy.context.view_layer.material_override = h.diffuse("Clay", (0.5, 0.5, 0.5))
    desc = h.export().description
    assert {desc.materials.names[i] for i in desc.mesh.material_ids} == {"Clay"}


# --------------------------------------------------------------------------- materials

def _single_material(mat):
    h.camera()
    h.plane(material=mat)
    exported = h.export()
    desc = exported.description
    row = int(desc.mesh.material_ids[0])
    t = desc.materials
    return dict(base=t.base_color[row], rough=t.roughness[row], metal=t.metallic[row],
                spec=t.specular[row], emit=t.emission[row]), exported.warnings


def test_principled_sockets():
    mat = h.node_material("P", "ShaderNodeBsdfPrincipled", base_color=(0.2, 0.4, 0.6),
                          roughness=0.3, metallic=0.7, emission_color=(1.0, 0.5, 0.25),
                          emission_strength=4.0)
    if V >= (4, 0, 0):  # the 4.x/5.x socket names, spelled out
        node = mat.node_tree.nodes["Principled BSDF"]
        assert node.inputs["Emission Color"].default_value[1] == pytest.approx(0.5)
        assert node.inputs["Specular IOR Level"].default_value == pytest.approx(0.5)
    row, warnings = _single_material(mat)
    assert warnings == []
    assert np.allclose(row["base"], (0.2, 0.4, 0.6), atol=1e-6)
    assert row["rough"] == pytest.approx(0.3) and row["metal"] == pytest.approx(0.7)
    assert row["spec"] == pytest.approx(0.5, abs=1e-3)  # default IOR/level ↔ F0 = 0.04
    assert np.allclose(row["emit"], (4.0, 2.0, 1.0), atol=1e-5)


def test_principled_defaults_have_no_emission():
    row, warnings = _single_material(h.node_material("P", "ShaderNodeBsdfPrincipled"))
    assert warnings == [] and np.allclose(row["emit"], 0)
    assert np.allclose(row["base"], 0.8, atol=1e-6)


def test_diffuse_and_emission_nodes():
    row, warnings = _single_material(h.diffuse("D", (0.1, 0.2, 0.3)))
    assert warnings == []
    assert np.allclose(row["base"], (0.1, 0.2, 0.3)) and row["spec"] == 0 and row["metal"] == 0
    bpy.ops.wm.read_factory_settings(use_empty=True)
    row, warnings = _single_material(h.emission("E", (1.0, 0.5, 0.0), 3.0))
    assert warnings == []
    assert np.allclose(row["emit"], (3.0, 1.5, 0.0)) and np.allclose(row["base"], 0)


def test_rgb_node_through_reroute_is_read():
    mat = h.diffuse("D", (0, 0, 0))
    nt = mat.node_tree
    rgb = nt.nodes.new("ShaderNodeRGB")
    rgb.outputs[0].default_value = (0.25, 0.5, 0.75, 1.0)
    reroute = nt.nodes.new("NodeReroute")
    diffuse = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeBsdfDiffuse")
    nt.links.new(rgb.outputs[0], reroute.inputs[0])
    nt.links.new(reroute.outputs[0], diffuse.inputs["Color"])
    row, warnings = _single_material(mat)
    assert warnings == [] and np.allclose(row["base"], (0.25, 0.5, 0.75))


def test_unsupported_shader_warns_once_and_falls_back_to_grey():
    mat = h.node_material("Shiny", "ShaderNodeBsdfToon")
    h.plane("Second", material=mat, location=(0, 0, 1))  # used twice → still one warning
    row, warnings = _single_material(mat)
    assert len(warnings) == 1 and "'Shiny'" in warnings[0] and "Toon BSDF" in warnings[0]
    assert np.allclose(row["base"], 0.8) and np.allclose(row["emit"], 0)


def test_linked_texture_warns_and_uses_socket_value():
    mat = h.node_material("Textured", "ShaderNodeBsdfPrincipled", base_color=(0.3, 0.3, 0.9))
    nt = mat.node_tree
    tex = nt.nodes.new("ShaderNodeTexNoise")
    nt.links.new(tex.outputs["Color"], nt.nodes["Principled BSDF"].inputs["Base Color"])
    row, warnings = _single_material(mat)
    assert len(warnings) == 1 and "'Textured'" in warnings[0] and "Base Color" in warnings[0]
    assert np.allclose(row["base"], (0.3, 0.3, 0.9))


def test_material_without_nodes_uses_viewport_colour():
    mat = bpy.data.materials.new("Plain")
    mat.diffuse_color = (0.1, 0.6, 0.3, 1.0)
    if compat.USE_NODES_DEPRECATED:  # 5.x: every material has nodes; use the tree's Principled
        pytest.skip("materials without node trees do not exist in Blender 5")
    row, warnings = _single_material(mat)
    assert np.allclose(row["base"], (0.1, 0.6, 0.3)) and warnings == []


# --------------------------------------------------------------------------- lights

def _lights():
    h.camera()
    return h.export()


def test_point_light_units():
    h.light("POINT", location=(1, 2, 3), energy=100.0, color=(1.0, 0.5, 0.25), shadow_soft_size=0.2)
    exported = _lights()
    pl = exported.description.point_lights
    assert len(pl) == 1
    assert np.allclose(pl.intensity[0], np.array([1.0, 0.5, 0.25]) * 100 / (4 * math.pi), rtol=1e-6)
    assert np.allclose(pl.position[0], (1, 2, 3))
    assert pl.cos_half_angle[0] == -1 and pl.radius[0] == pytest.approx(0.2)
    assert exported.has_emitters


def test_spot_light_units_cone_and_direction():
    ob = h.light("SPOT", location=(0, 0, 4), energy=250.0, spot_size=math.radians(60), spot_blend=0.3)
    ob.rotation_euler = (math.radians(90), 0, 0)  # local −Z → world +Y
    exported = _lights()
    pl = exported.description.point_lights
    assert np.allclose(pl.intensity[0], 250 / (4 * math.pi))  # power not concentrated into the cone
    assert len(exported.warnings) == (1 if V < (4, 0, 0) else 0)  # 3.x cos θ falloff not modelled
    assert pl.cos_half_angle[0] == pytest.approx(math.cos(math.radians(30)))
    assert pl.blend[0] == pytest.approx(0.3)
    assert np.allclose(pl.direction[0], (0, 1, 0), atol=1e-6)


def test_sun_light_units_and_direction():
    ob = h.light("SUN", energy=3.0, color=(1, 1, 0.5), angle=math.radians(2))
    ob.rotation_euler = (0, math.radians(90), 0)  # local −Z → world −X
    sl = _lights().description.sun_lights
    assert np.allclose(sl.irradiance[0], (3.0, 3.0, 1.5))
    assert np.allclose(sl.direction[0], (-1, 0, 0), atol=1e-6)
    assert sl.angle[0] == pytest.approx(math.radians(2))


def _area_factor(area):
    return 1 / (math.pi * area) if V >= (4, 0, 0) else 1 / (4 * area)


@pytest.mark.parametrize("shape,size,size_y,scale,area,expect_shape", [
    ("SQUARE", 2.0, None, (1, 2, 1), 8.0, 0),
    ("RECTANGLE", 1.0, 3.0, (1, 1, 1), 3.0, 0),
    ("DISK", 2.0, None, (1, 1, 1), math.pi, 1),
    ("ELLIPSE", 2.0, 4.0, (0.5, 1, 1), 2.0 * math.pi / 4 * 4 / 4 * 1.0, 1),
])
def test_area_light_units_and_shapes(shape, size, size_y, scale, area, expect_shape):
    data = dict(shape=shape, size=size)
    if size_y is not None:
        data["size_y"] = size_y
    ob = h.light("AREA", location=(0, 0, 3), energy=100.0, color=(1, 0.5, 0.5), **data)
    ob.scale = scale
    al = _lights().description.area_lights
    hu = size * scale[0] / 2
    hv = (size_y if size_y is not None and shape in {"RECTANGLE", "ELLIPSE"} else size) * scale[1] / 2
    if shape == "ELLIPSE":
        area = math.pi * hu * hv
    assert np.allclose(al.axis_u[0], (hu, 0, 0)) and np.allclose(al.axis_v[0], (0, hv, 0))
    assert np.allclose(al.normal[0], (0, 0, -1))
    assert np.allclose(al.center[0], (0, 0, 3))
    assert al.shape[0] == expect_shape
    assert np.allclose(al.radiance[0], np.array([1, 0.5, 0.5]) * 100 * _area_factor(area), rtol=1e-5)


@pytest.mark.skipif(V < (4, 0, 0), reason="light exposure/normalize exist from Blender 4.0 on")
def test_area_light_exposure_and_normalize():
    ob = h.light("AREA", energy=10.0, size=2.0, exposure=1.0)
    al = _lights().description.area_lights
    assert np.allclose(al.radiance[0], 2 * 10 / (math.pi * 4.0))
    ob.data.normalize = False
    al = h.export().description.area_lights
    assert np.allclose(al.radiance[0], 2 * 10 / math.pi)


def test_soft_light_shapes_follow_soft_falloff_and_spread_is_exported():
    """Radius > 0: a sphere when Soft Falloff is off (Blender ≥ 4.0), else (the default, and
    every 3.x) the disk facing the receiver; area spread and sun angle as set."""
    soft = h.light("POINT", name="Soft", energy=10.0, shadow_soft_size=0.3)
    hard = h.light("SPOT", name="Hard", energy=10.0, shadow_soft_size=0.3)
    if V >= (4, 0, 0):
        assert hard.data.use_soft_falloff                          # Blender's default
        hard.data.use_soft_falloff = False
    h.light("AREA", energy=10.0, size=1.0, spread=math.radians(40))
    exported = _lights()
    pl = exported.description.point_lights
    names = [exported.description.object_name(int(i)) for i in pl.object_ids]
    sphere = dict(zip(names, pl.sphere.tolist()))
    assert sphere == {"Soft": False, "Hard": V >= (4, 0, 0)}
    assert np.allclose(pl.radius, 0.3)
    assert exported.description.area_lights.spread[0] == pytest.approx(math.radians(40))
    assert not any("spread" in w for w in exported.warnings)


@pytest.mark.skipif(V < (4, 0, 0), reason="light normalize exists from Blender 4.0 on")
def test_point_and_sun_without_normalize():
    """Cycles without normalisation: a point light's radiance is P/π (I = P·r², or P/π at
    r = 0); a sun's strength is the radiance of its disk (E = P·π·sin²(angle/2))."""
    pt = h.light("POINT", energy=10.0, shadow_soft_size=0.2)
    sun = h.light("SUN", energy=2.0, angle=math.radians(10))
    pt.data.normalize = sun.data.normalize = False
    d = _lights().description
    assert np.allclose(d.point_lights.intensity[0], 10 * 0.2**2, rtol=1e-5)
    assert np.allclose(d.sun_lights.irradiance[0], 2 * math.pi * math.sin(math.radians(5)) ** 2, rtol=1e-5)
    pt.data.shadow_soft_size = 0.0
    assert np.allclose(h.export().description.point_lights.intensity[0], 10 / math.pi, rtol=1e-5)


def test_light_node_strength_multiplies():
    ob = h.light("POINT", energy=10.0)
    ob.data.use_nodes = True
    em = next(n for n in ob.data.node_tree.nodes if n.bl_idname == "ShaderNodeEmission")
    em.inputs["Strength"].default_value = 2.0
    pl = _lights().description.point_lights
    assert np.allclose(pl.intensity[0], 20 / (4 * math.pi))


def test_emissive_mesh_counts_as_emitter_and_no_lights_does_not():
    h.camera()
    h.plane(material=h.diffuse())
    exported = h.export()
    assert not exported.has_emitters
    h.plane("Lamp", material=h.emission(strength=2.0), location=(0, 0, 1))
    assert h.export().has_emitters


# --------------------------------------------------------------------------- world

def test_world_background_color_times_strength():
    h.world((0.2, 0.3, 0.4), 2.0)
    exported = _lights()
    assert np.allclose(exported.description.world_radiance, (0.4, 0.6, 0.8))
    assert exported.warnings == [] and exported.has_emitters


def test_world_none_is_black_and_unsupported_warns():
    assert np.allclose(_lights().description.world_radiance, 0)
    w = h.world((0.1, 0.2, 0.3), 1.0)
    sky = w.node_tree.nodes.new("ShaderNodeTexSky")
    bg = next(n for n in w.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")
    w.node_tree.links.new(sky.outputs[0], bg.inputs["Color"])
    exported = h.export()
    assert np.allclose(exported.description.world_radiance, (0.1, 0.2, 0.3))
    assert len(exported.warnings) == 1 and "World" in exported.warnings[0]


def test_world_without_nodes_uses_world_color():
    if compat.USE_NODES_DEPRECATED:
        pytest.skip("worlds always use nodes in Blender 5")
    w = bpy.data.worlds.new("Plain")
    w.color = (0.3, 0.2, 0.1)
    bpy.context.scene.world = w
    assert np.allclose(_lights().description.world_radiance, (0.3, 0.2, 0.1))


# --------------------------------------------------------------------------- camera

def test_no_camera_is_an_export_error():
    h.plane()
    with pytest.raises(ExportError, match="camera"):
        h.export()
    assert h.export(require_camera=False).description.camera is None


def test_camera_desc_fields():
    s = bpy.context.scene
    s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = 333, 201, 50
    s.render.pixel_aspect_x = 2.0
    s.render.use_border = True
    s.render.border_min_x, s.render.border_max_x = 0.25, 0.75
    cam = h.camera(location=(1, 2, 3), lens=35.0, sensor_width=30.0, sensor_height=20.0,
                   sensor_fit="VERTICAL", shift_x=0.1, shift_y=-0.2)
    cam.scale = (2, 2, 2)
    c = h.export().description.camera
    assert (c.width, c.height) == (166, 100)
    assert (c.lens, c.sensor_width, c.sensor_height, c.sensor_fit) == (35.0, 30.0, 20.0, "VERTICAL")
    assert c.shift_x == pytest.approx(0.1) and c.shift_y == pytest.approx(-0.2)
    assert c.pixel_aspect_x == 2.0 and c.use_border and c.border == (0.25, 0.0, 0.75, 1.0)
    r = c.world_from_camera[:3, :3]
    assert np.allclose(r.T @ r, np.eye(3), atol=1e-6)  # scale removed
    assert np.allclose(c.world_from_camera[:3, 3], (1, 2, 3))
    assert c.projection == "PERSP"


def test_depth_of_field_fields_as_cycles():
    """Aperture radius lens·10⁻³/(2·f-stop); focus distance, or the focus object's distance
    along the view axis; blades, rotation, ratio; no DOF → a pinhole; ortho DOF warns."""
    cam = h.camera(location=(0, -4, 1), target=(0, 0, 1), lens=50.0)
    dof = cam.data.dof
    assert h.export().description.camera.aperture_radius == 0.0
    dof.use_dof, dof.aperture_fstop, dof.focus_distance = True, 2.0, 3.5
    dof.aperture_blades, dof.aperture_rotation, dof.aperture_ratio = 6, 0.25, 1.5
    c = h.export().description.camera
    assert c.aperture_radius == pytest.approx(0.05 / 4.0)
    assert c.focus_distance == pytest.approx(3.5)
    assert (c.aperture_blades, c.aperture_rotation, c.aperture_ratio) == (6, pytest.approx(0.25), 1.5)
    target = h.plane("Target", location=(1.0, 2.0, 0.0))      # 6 m ahead, 1 m aside and down
    dof.focus_object = target
    assert h.export().description.camera.focus_distance == pytest.approx(6.0, abs=1e-5)
    cam.data.type = "ORTHO"
    exported = h.export()
    assert exported.description.camera.aperture_radius == 0.0
    assert any("depth of field" in w for w in exported.warnings)


CAMERA_CASES = [
    dict(res=(64, 32), fit="AUTO"),
    dict(res=(32, 64), fit="AUTO"),
    dict(res=(64, 32), fit="AUTO", shift=(0.1, 0.05)),
    dict(res=(64, 32), fit="HORIZONTAL", shift=(-0.2, 0.1)),
    dict(res=(48, 64), fit="VERTICAL", shift=(0.0, 0.3)),
    dict(res=(64, 48), fit="VERTICAL", aspect=(2.0, 1.0)),
    dict(res=(64, 48), fit="AUTO", aspect=(1.0, 3.0), shift=(0.05, 0.0)),
    dict(res=(64, 48), fit="AUTO", ortho=4.0, shift=(0.1, 0.0)),
    dict(res=(40, 80), fit="HORIZONTAL", ortho=3.0),
]


def camera_case(case):
    """The scene's resolution, pixel aspect and a camera as a CAMERA_CASES row describes."""
    s = bpy.context.scene
    s.render.resolution_x, s.render.resolution_y = case["res"]
    s.render.pixel_aspect_x, s.render.pixel_aspect_y = case.get("aspect", (1.0, 1.0))
    ob = h.camera(location=(1, -2, 3), target=(0, 0, 0), lens=42.0, sensor_width=36.0,
                  sensor_height=24.0, sensor_fit=case["fit"])
    ob.data.shift_x, ob.data.shift_y = case.get("shift", (0.0, 0.0))
    if "ortho" in case:
        ob.data.type = "ORTHO"
        ob.data.ortho_scale = case["ortho"]
    bpy.context.view_layer.update()
    return ob


@pytest.mark.parametrize("case", CAMERA_CASES, ids=[str(i) for i in range(len(CAMERA_CASES))])
def test_core_camera_corners_match_view_frame(case):
    """Rays of ercuts_core.camera at the 4 frame corners hit Blender's view_frame corners."""
    from ercuts_core.camera import Camera

    s = bpy.context.scene
    ob = camera_case(case)
    desc = h.export().description.camera
    cam = Camera(desc)
    W, H = desc.width, desc.height
    # view_frame order: top-right, bottom-right, bottom-left, top-left (camera space).
    frame = [np.array(v) for v in ob.data.view_frame(scene=s)]
    raster = np.array([[W, 0], [W, H], [0, H], [0, 0]], np.float64)
    origins, dirs = cam.generate_rays(raster)
    m = np.array(ob.matrix_world)
    rot = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0)
    for k, corner in enumerate(frame):
        if "ortho" in case:
            # Ortho: same origin offset in the camera's XY plane, direction = view axis.
            local = (origins[k] - m[:3, 3]) @ rot
            assert np.allclose(local[:2], corner[:2], atol=1e-5), (k, local, corner)
            assert np.allclose(dirs[k], -rot[:, 2], atol=1e-6)
        else:
            want = rot @ corner
            want /= np.linalg.norm(want)
            assert np.allclose(dirs[k], want, atol=1e-6), (k, dirs[k], want)
            assert np.allclose(origins[k], m[:3, 3])


def test_camera_override_and_panoramic_error():
    a = h.camera(location=(0, 0, 5), name="A")
    b = h.camera(location=(0, 0, 9), name="B")
    bpy.context.scene.camera = a
    desc = h.export(camera_override=b).description
    assert desc.camera.world_from_camera[2, 3] == pytest.approx(9)
    b.data.type = "PANO"
    with pytest.raises(ExportError, match="not supported"):
        h.export(camera_override=b)


def test_matrix_copy_is_world_space():
    """Parenting: world transform (not local) is applied."""
    h.camera()
    parent = h.link(bpy.data.objects.new("Parent", None))
    parent.location = (0, 0, 10)
    child = h.plane("Child")
    child.parent = parent
    child.matrix_parent_inverse = Matrix.Identity(4)
    desc = h.export().description
    assert np.allclose(desc.mesh.positions[:, 2], 10)


def test_lights_shown_to_the_camera_warn():
    """Cycles shows a light with a size to camera rays when its Camera visibility is on (off by
    default for lights); Ercuts never does, and says so."""
    ob = h.light("AREA", energy=10.0, size=1.0)
    assert not ob.visible_camera                                   # Blender's default
    assert _lights().warnings == []
    ob.visible_camera = True
    assert any("visible to the camera" in w for w in h.export().warnings)


def test_ray_visibility_that_ercuts_ignores_warns_naming_the_object():
    """Cycles hides objects from single ray types, makes holdouts and shadow catchers, and
    switches lights' shadows off; Ercuts renders all of them as visible to every ray and says
    so once per object (bad-input policy: a warning with the fallback, not a silent
    difference). Defaults give no warning."""
    h.camera()
    cube = h.box("Cube", location=(0, 0, 0))
    lamp = h.light("POINT", name="Lamp", energy=10.0)
    assert h.export().warnings == []
    cube.visible_shadow = False
    cube.visible_glossy = False
    cube.is_holdout = True
    lamp.visible_diffuse = False
    lamp.data.use_shadow = False
    warnings = h.export().warnings
    obj = [w for w in warnings if w.startswith("Object 'Cube'")]
    light = [w for w in warnings if w.startswith("Light 'Lamp'")]
    assert len(obj) == 1 and "glossy, shadow rays" in obj[0] and "holdout" in obj[0]
    assert len(light) == 1 and "diffuse rays" in light[0] and "Cast Shadow off" in light[0]
