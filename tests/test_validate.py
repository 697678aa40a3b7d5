"""One test per row of the bad-input table (style-and-testing.md §2.6)."""
from __future__ import annotations

import numpy as np
import pytest

from ercuts_core import (AreaLights, MaterialTable, MeshTable, PointLights, RenderSettings,
                         SceneError, render)
from ercuts_core.scenes import _camera
from ercuts_core.description import SceneDescription
from ercuts_core.validate import sanitize


def scene(positions=None, triangles=None, material_ids=None, lights=True, camera=True, **kw):
    pos = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1], [0, 0, 0], [0, 1, 0]], float) \
        if positions is None else positions
    tris = np.array([[0, 2, 1], [0, 3, 2]]) if triangles is None else triangles
    mats = MaterialTable.diffuse(["Grey"], [[0.5, 0.5, 0.5]])
    mid = np.zeros(len(tris)) if material_ids is None else material_ids
    mesh = MeshTable(pos, tris, mid, np.arange(len(tris)) % 2)
    pl = PointLights([[0, 1, 0]], [[1, 1, 1]], [[0, -1, 0]], [-1], [0], [0], [2]) if lights else \
        PointLights(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), [], [], [], [])
    cam = _camera((0, 1, 2), (0, 0, 0), 8, 6) if camera else None
    return SceneDescription(mesh, mats, cam, point_lights=pl,
                            object_names=("Floor", "FloorB", "Lamp"), **kw)


def codes(v):
    return [i.code for i in v.issues]


def test_clean_scene_has_no_issues():
    v = sanitize(scene())
    assert v.issues == [] and v.stats["triangles"] == 2


def test_nan_vertices_drop_triangles_and_warn_with_object_name():
    pos = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1], [np.nan, 0, 0], [0, np.inf, 0]])
    tris = np.array([[0, 2, 1], [0, 3, 2], [0, 4, 1], [1, 5, 2]])
    v = sanitize(scene(pos, tris))
    assert codes(v).count("nonfinite_vertices") == 2
    assert v.desc.mesh.n_triangles == 2
    assert any("'Floor'" in i.message for i in v.issues)


def test_degenerate_triangles_are_dropped_silently_and_counted():
    tris = np.array([[0, 2, 1], [0, 3, 2], [0, 0, 1], [0, 4, 2]])  # repeated index; collinear
    v = sanitize(scene(triangles=tris))
    assert v.issues == [] and v.stats["degenerate_triangles"] == 2 and v.desc.mesh.n_triangles == 2


def test_indices_out_of_range_warn():
    tris = np.array([[0, 2, 1], [0, 3, 99], [-1, 1, 2]])
    v = sanitize(scene(triangles=tris))
    assert "index_out_of_range" in codes(v) and v.desc.mesh.n_triangles == 1


def test_material_index_out_of_range_falls_back_to_grey():
    v = sanitize(scene(material_ids=np.array([0, 5])))
    assert "material_out_of_range" in codes(v)
    fallback = v.desc.mesh.material_ids[1]
    np.testing.assert_allclose(v.desc.materials.base_color[fallback], [0.8, 0.8, 0.8])


def test_no_camera_is_an_error():
    with pytest.raises(SceneError, match="no active camera"):
        sanitize(scene(camera=False))
    with pytest.raises(SceneError, match="no active camera"):
        render(scene(camera=False), RenderSettings(rough_samples=1))


@pytest.mark.parametrize("w,h", [(0, 6), (8, 0)])
def test_zero_resolution_is_an_error(w, h):
    d = scene()
    d = d.replace(camera=d.camera.__class__(**{**vars(d.camera), "width": w, "height": h}))
    with pytest.raises(SceneError, match="empty"):
        sanitize(d)


def test_empty_border_is_an_error():
    d = scene()
    d = d.replace(camera=d.camera.__class__(**{**vars(d.camera), "use_border": True,
                                               "border": (0.5, 0.5, 0.52, 0.9)}))
    with pytest.raises(SceneError, match="border"):
        sanitize(d)


def test_no_lights_gives_black_image_and_warning():
    r = render(scene(lights=False), RenderSettings(samples=2, integrator="PATH"))
    assert [i.code for i in r.issues] == ["no_lights"]
    assert r.image.shape == (6, 8, 4)
    assert np.all(r.image[..., :3] == 0) and np.all(r.image[..., 3] == 1)


def test_zero_power_lights_are_dropped_silently():
    d = scene(lights=False)
    pl = PointLights([[0, 1, 0], [0, 1, 0]], [[0, 0, 0], [1, 1, 1]], [[0, -1, 0]] * 2, [-1, -1],
                     [0, 0], [0, 0], [2, 2])
    al = AreaLights([[0, 1, 0]], [[0, 0, 0]], [[0, 0, 0.1]], [[0, -1, 0]], [[5, 5, 5]], [0], [2])
    v = sanitize(d.replace(point_lights=pl, area_lights=al))
    assert v.issues == [] and v.stats["dropped_zero_lights"] == 2 and len(v.desc.point_lights) == 1


def test_zero_cone_spot_is_dropped_silently():
    """A spot whose cone is closed (cos of the half-angle 1) emits nothing: dropped like a
    zero-power light. Kept, it was the scene's only light, picked with probability 0 and
    divided by 2π(1 − cos) = 0 (the fuzz test's 'divide by zero' warnings in lights.py)."""
    d = scene(lights=False)
    pl = PointLights([[0, 1, 0]] * 2, [[1, 1, 1]] * 2, [[0, -1, 0]] * 2, [1.0, 0.9], [0, 0], [0, 0], [2, 2])
    v = sanitize(d.replace(point_lights=pl))
    assert v.issues == [] and v.stats["dropped_zero_lights"] == 1
    assert list(v.desc.point_lights.cos_half_angle) == [pytest.approx(0.9)]


def test_nonfinite_light_warns_and_is_skipped():
    d = scene(lights=False)
    pl = PointLights([[0, np.nan, 0]], [[1, 1, 1]], [[0, -1, 0]], [-1], [0], [0], [2])
    v = sanitize(d.replace(point_lights=pl))
    assert "nonfinite_light" in codes(v) and "no_lights" in codes(v)
    assert "'Lamp'" in v.issues[0].message


def test_nan_material_values_are_replaced():
    d = scene()
    m = d.materials
    bad = MaterialTable(m.names, [[np.nan, 0.5, 2.0]], [np.nan], [0], [0], [[-1, np.inf, 0]])
    v = sanitize(d.replace(materials=bad))
    assert np.isfinite(v.desc.materials.base_color).all()
    assert (v.desc.materials.base_color <= 1).all() and (v.desc.materials.emission >= 0).all()


def test_triangles_without_vertices_are_dropped_not_a_crash():
    v = sanitize(scene(positions=np.zeros((0, 3)), triangles=np.array([[0, 1, 2]])))
    assert "index_out_of_range" in codes(v) and v.desc.mesh.n_triangles == 0


def test_normal_count_mismatch_warns_and_shades_flat():
    d = scene()
    m = d.mesh
    d = d.replace(mesh=MeshTable(m.positions, m.triangles, m.material_ids, m.object_ids, np.ones((2, 3))))
    v = sanitize(d)
    assert "normal_count_mismatch" in codes(v) and v.desc.mesh.normals is None


def test_nonfinite_material_values_warn_and_never_emit():
    d = scene()
    mats = MaterialTable(("Hot",), [[np.nan, 0.5, 0.5]], [0.5], [0.0], [0.5], [[np.inf, 1.0, 0.0]])
    v = sanitize(d.replace(materials=mats))
    assert codes(v) == ["nonfinite_material"] and "'Hot'" in v.issues[0].message
    assert np.isfinite(v.desc.materials.emission).all() and v.desc.materials.emission[0, 0] == 0


def test_nonfinite_world_warns_and_renders_black_background():
    v = sanitize(scene(world_radiance=[np.inf, 0.0, np.nan]))
    assert "nonfinite_world" in codes(v) and (v.desc.world_radiance == 0).all()


def test_bad_light_sizes_warn_and_fall_back():
    """NaN or negative radius / sun angle → 0 (sharp), one warning naming the light; a NaN or
    negative spread → 180°, a spread below 1° → 1° (Cycles 3.x's minimum)."""
    from ercuts_core import SunLights

    d = scene(lights=False)
    pl = PointLights([[0, 1, 0]] * 3, [[1, 1, 1]] * 3, [[0, -1, 0]] * 3, [-1] * 3, [0] * 3,
                     [np.nan, -0.2, 0.3], [2, 2, 2])
    sl = SunLights([[0, -1, 0]] * 2, [[1, 1, 1]] * 2, [np.inf, 0.02], [2, 2])
    al = AreaLights([[0, 1, 0]] * 3, [[0.1, 0, 0]] * 3, [[0, 0, 0.1]] * 3, [[0, -1, 0]] * 3, [[5, 5, 5]] * 3,
                    [0] * 3, [2, 2, 2], [np.nan, 0.001, 1.0])
    v = sanitize(d.replace(point_lights=pl, sun_lights=sl, area_lights=al))
    assert codes(v).count("bad_light_size") == 2             # one per light object (all 'Lamp')
    assert "bad_light_spread" in codes(v) and "small_light_spread" in codes(v)
    assert all("'Lamp'" in i.message for i in v.issues)
    np.testing.assert_allclose(v.desc.point_lights.radius, [0, 0, 0.3], rtol=1e-6)
    np.testing.assert_allclose(v.desc.sun_lights.angle, [0, 0.02], rtol=1e-6)
    np.testing.assert_allclose(v.desc.area_lights.spread, [np.pi, np.radians(1), 1.0], rtol=1e-6)


@pytest.mark.parametrize("field, value, code", [
    ("aperture_radius", np.nan, "bad_aperture"), ("aperture_radius", -1.0, "bad_aperture"),
    ("focus_distance", np.nan, "bad_focus"), ("aperture_ratio", 0.0, "bad_aperture_ratio"),
])
def test_bad_lens_values_warn_and_fall_back(field, value, code):
    import dataclasses

    d = scene()
    cam = dataclasses.replace(d.camera, **{"aperture_radius": 0.05, field: value})
    v = sanitize(d.replace(camera=cam))
    assert code in codes(v)
    c = v.desc.camera
    if code == "bad_aperture_ratio":
        assert c.aperture_ratio == 1.0 and c.aperture_radius == 0.05
    else:
        assert c.aperture_radius == 0.0                      # a pinhole
    assert np.isfinite(render(v.desc, RenderSettings(integrator="PATH", samples=1)).image).all()


def test_orthographic_depth_of_field_warns_and_renders_sharp():
    import dataclasses

    d = scene()
    v = sanitize(d.replace(camera=dataclasses.replace(d.camera, projection="ORTHO", aperture_radius=0.1)))
    assert "ortho_dof" in codes(v) and v.desc.camera.aperture_radius == 0.0
