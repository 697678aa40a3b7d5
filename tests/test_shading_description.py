"""Textured-material fields of the description (issue 14): defaults, .npz round trip, validation."""
from __future__ import annotations

import numpy as np

from ercuts_core import MaterialTable, MeshTable, load_npz, save_npz
from ercuts_core.scenes import cornell_box
from ercuts_core.shading.textures import TextureTable
from ercuts_core.validate import sanitize


def _textured(d, uvs=True, tangents=True, programs=None, images=None):
    m = d.mesh
    t = m.n_triangles
    rng = np.random.default_rng(1)
    mesh = MeshTable(m.positions, m.triangles, m.material_ids, m.object_ids, m.normals, m.smooth,
                     rng.random((t, 3, 2)) if uvs else None,
                     np.tile([1, 0, 0, -1], (t, 3, 1)) if tangents else None)
    mats = d.materials
    progs = programs if programs is not None else \
        ('{"version": 1, "nodes": [], "outputs": {}}',) + ("",) * (mats.n_materials - 1)
    mats = MaterialTable(mats.names, mats.base_color, mats.roughness, mats.metallic, mats.specular,
                         mats.emission, progs)
    images = images if images is not None else (rng.random((4, 3, 4)), np.ones((2, 5, 4)))
    tex = TextureTable(tuple(f"img{i}" for i in range(len(images))), images, (True,))
    return d.replace(mesh=mesh, materials=mats, textures=tex)


def test_defaults_keep_existing_constructors_working():
    d = cornell_box()
    assert d.mesh.uvs is None and d.mesh.tangents is None
    assert d.materials.programs == ("",) * d.materials.n_materials
    assert not d.materials.has_programs
    assert len(d.textures) == 0
    mats = MaterialTable.diffuse(["a", "b"], [[0.5] * 3] * 2)
    assert mats.programs == ("", "")


def test_npz_round_trip_with_uvs_tangents_programs_textures(tmp_path):
    d = _textured(cornell_box())
    save_npz(d, tmp_path / "t.npz")
    e = load_npz(tmp_path / "t.npz")
    np.testing.assert_array_equal(d.mesh.uvs, e.mesh.uvs)
    assert e.mesh.uvs.dtype == np.float32 and e.mesh.uvs.shape == (d.mesh.n_triangles, 3, 2)
    np.testing.assert_array_equal(d.mesh.tangents, e.mesh.tangents)
    assert e.materials.programs == d.materials.programs
    assert e.textures.names == d.textures.names
    assert e.textures.srgb == d.textures.srgb == (True, False)
    assert sanitize(e).desc.textures.srgb == (True, False)
    for a, b in zip(d.textures.images, e.textures.images):
        assert b.dtype == np.float32
        np.testing.assert_array_equal(a, b)


def test_npz_round_trip_without_textures(tmp_path):
    d = cornell_box()
    save_npz(d, tmp_path / "c.npz")
    e = load_npz(tmp_path / "c.npz")
    assert e.mesh.uvs is None and len(e.textures) == 0 and e.materials.programs == d.materials.programs


def test_validation_keeps_good_fields_and_appends_an_empty_program():
    d = _textured(cornell_box())
    v = sanitize(d)
    assert not [i for i in v.issues if i.severity == "warning"]
    assert v.desc.materials.programs == d.materials.programs + ("",)
    np.testing.assert_array_equal(v.desc.mesh.uvs, d.mesh.uvs)
    assert len(v.desc.textures) == 2


def test_bad_uv_shape_and_nan_uvs_warn():
    d = _textured(cornell_box())
    bad = d.replace(mesh=MeshTable(d.mesh.positions, d.mesh.triangles, d.mesh.material_ids,
                                   d.mesh.object_ids, uvs=np.zeros((3, 3, 2))))
    v = sanitize(bad)
    assert "uvs_shape" in [i.code for i in v.issues] and v.desc.mesh.uvs is None
    uvs = d.mesh.uvs.copy()
    uvs[0, 1, 0] = np.nan
    bad = d.replace(mesh=MeshTable(d.mesh.positions, d.mesh.triangles, d.mesh.material_ids,
                                   d.mesh.object_ids, uvs=uvs))
    v = sanitize(bad)
    assert "nonfinite_uvs" in [i.code for i in v.issues]
    assert np.isfinite(v.desc.mesh.uvs).all() and v.desc.mesh.uvs[0, 1, 0] == 0


def test_program_count_mismatch_warns():
    d = _textured(cornell_box(), programs=("", ""))
    v = sanitize(d)
    assert "program_count_mismatch" in [i.code for i in v.issues]
    assert v.desc.materials.programs == ("",) * v.desc.materials.n_materials


def test_nan_texels_and_empty_images_warn_and_fall_back():
    nan_img = np.ones((2, 2, 4), np.float32)
    nan_img[0, 1, 2] = np.nan
    nan_img[1, 1, 0] = np.inf
    d = _textured(cornell_box(), images=(nan_img, np.zeros((0, 4, 4)), np.full((3, 2, 3), 0.5)))
    v = sanitize(d)
    msgs = {i.code: i.message for i in v.issues}
    assert "img0" in msgs["nonfinite_image"] and "img1" in msgs["empty_image"]
    a, b, c = v.desc.textures.images
    assert a[0, 1, 2] == 0 and a[1, 1, 0] == 0 and np.isfinite(a).all()
    np.testing.assert_array_equal(b, [[[1, 0, 1, 1]]])
    assert c.shape == (3, 2, 4) and (c[..., 3] == 1).all()


def test_textures_count_in_the_memory_plan():
    from ercuts_core import RenderSettings
    from ercuts_core.memory import plan_for
    d = cornell_box(24, 18)
    big = _textured(d, images=(np.zeros((512, 512, 4), np.float32),))
    plain, textured = plan_for(d, RenderSettings()), plan_for(big, RenderSettings())
    assert "textures" not in plain.parts
    assert textured.parts["textures"] >= 512 * 512 * 16
    assert textured.total - plain.total == textured.parts["textures"]


def test_bad_programs_warn_naming_material_and_node_and_fall_back_to_constants():
    good = '{"version": 1, "nodes": [{"type": "VALUE", "params": {"value": 0.2}}], ' \
           '"outputs": {"roughness": {"node": 0, "socket": "Value"}}}'
    bad = '{"version": 1, "nodes": [{"type": "TEX_NOISE"}], "outputs": {}}'
    d = _textured(cornell_box(), programs=(good, bad, "{oops", ""))
    v = sanitize(d)
    msgs = [i.message for i in v.issues if i.code == "shading_program"]
    assert len(msgs) == 2
    assert "Material 'Red'" in msgs[0] and "node 0 (TEX_NOISE)" in msgs[0]
    assert "Material 'Green'" in msgs[1]
    assert v.desc.materials.programs == (good, "", "", "", "")


def test_a_render_with_a_bad_program_reports_and_does_not_raise():
    from ercuts_core import RenderSettings, render
    bad = '{"version": 1, "nodes": [{"type": "MATH", "inputs": {"Value": {"node": 7, "socket": "Value"}}}]}'
    d = _textured(cornell_box(16, 12), programs=("", bad, "", ""))
    r = render(d, RenderSettings(integrator="PATH", samples=2))
    assert np.isfinite(r.image).all()
    assert any("Material 'Red'" in str(i) for i in r.issues)


def test_an_emission_program_counts_as_a_light():
    prog = '{"version": 1, "nodes": [], "outputs": {"emission": [2.0, 2.0, 2.0]}}'
    d = cornell_box(16, 12, "area").replace(
        area_lights=cornell_box(16, 12, "mesh").area_lights)          # no area light, no emission
    d = _textured(d, programs=(prog, "", "", ""), images=())
    v = sanitize(d)
    assert "no_lights" not in [i.code for i in v.issues]
    assert "no_lights" in [i.code for i in sanitize(_textured(d, programs=("",) * 4, images=())).issues]
